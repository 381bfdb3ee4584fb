"""The `displaced` shape plugin: XML loading, editing, stats, and bad input."""
import mitsuba as mi
import numpy as np
import pytest
import trimesh


def displaced(**kw):
    d = {"type": "displaced"}
    d.update(kw)
    return mi.load_dict(d)


def buffers(shape):
    p = mi.traverse(shape)
    return (np.asarray(p["vertex_positions"]).reshape(-1, 3),
            np.asarray(p["faces"]).reshape(-1, 3), np.asarray(p["vertex_normals"]).reshape(-1, 3))


def test_xml_with_bitmap_height_and_edit_scale(variant, tmp_path):
    h = np.linspace(0, 1, 32 * 16, dtype=np.float32).reshape(16, 32, 1)
    mi.Bitmap(h).write(str(tmp_path / "h.exr"))
    xml = f"""<scene version="3.0.0"><shape type="displaced" id="d">
        <string name="base" value="torus"/><float name="major_radius" value="1"/>
        <float name="minor_radius" value="0.25"/><integer name="resolution" value="48"/>
        <float name="scale" value="0.1"/>
        <texture type="bitmap" name="height"><string name="filename" value="{tmp_path / 'h.exr'}"/>
            <boolean name="raw" value="true"/></texture></shape></scene>"""
    scene = mi.load_string(xml)
    shape = scene.shapes()[0]
    stats = shape.build_stats
    assert stats["faces"] == shape.face_count() and stats["vertices"] == shape.vertex_count()
    pos, faces, nrm = buffers(shape)
    assert np.all(np.isfinite(pos)) and np.all(np.isfinite(nrm))
    m = trimesh.Trimesh(pos, faces)
    assert m.is_watertight
    params = mi.traverse(scene)
    params["d.scale"] = 0.0
    params.update()
    pos0, faces0, _ = buffers(shape)
    assert np.array_equal(faces0, faces)
    # scale 0 gives the plain torus: distance to the tube circle == minor radius
    ring = np.linalg.norm(pos0[:, :2], axis=1)
    assert np.allclose(np.hypot(ring - 1.0, pos0[:, 2]), 0.25, atol=1e-6)
    assert scene.bbox().max.z < 0.25 + 1e-5


def test_mesh_base(variant, tmp_path):
    ico = trimesh.creation.icosphere(2)
    uv = np.stack([np.arctan2(ico.vertices[:, 1], ico.vertices[:, 0]) / (2 * np.pi) + 0.5,
                   np.arccos(np.clip(ico.vertices[:, 2], -1, 1)) / np.pi], 1)
    ico.visual = trimesh.visual.TextureVisuals(uv=uv)
    ico.export(tmp_path / "ico.ply")
    s = displaced(base="mesh", filename=str(tmp_path / "ico.ply"), subdivision=3, scale=0.05,
                  height={"type": "checkerboard"})
    pos, faces, nrm = buffers(s)
    assert len(faces) == len(ico.faces) * 9
    assert np.all(np.isfinite(pos)) and np.allclose(np.linalg.norm(nrm, axis=1), 1, atol=1e-5)
    r = np.linalg.norm(pos, axis=1)
    assert r.max() > 1.0 + 0.01  # checkerboard (0.4 / 0.2) pushes vertices out
    with pytest.raises(Exception, match="triangles, more than the limit"):
        displaced(base="mesh", filename=str(tmp_path / "ico.ply"), subdivision=4000)


@pytest.mark.parametrize("props,match", [
    ({"base": "cube"}, "parameter 'base' must be one of .*, got 'cube'"),
    ({"base": "sphere", "resolution": 0}, "resolution"),
    ({"base": "sphere", "resolution": -4}, "resolution"),
    ({"base": "sphere", "radius": -1.0}, "radius"),
    ({"base": "mesh", "filename": "/no/such/file.ply"}, "not found: /no/such/file.ply"),
    ({"base": "sphere", "scale": float("nan")}, "scale"),
    ({"base": "mesh"}, "needs a 'filename'"),
])
def test_bad_input_is_named(variant, props, match):
    with pytest.raises(Exception, match=match):
        displaced(**props)


def test_mesh_without_uvs_is_refused(variant, tmp_path):
    trimesh.creation.icosphere(1).export(tmp_path / "plain.ply")
    with pytest.raises(Exception, match="has no UVs"):
        displaced(base="mesh", filename=str(tmp_path / "plain.ply"))


def test_nan_in_height_bitmap_is_refused(variant, tmp_path):
    h = np.ones((8, 8, 1), np.float32)
    h[3, 4] = np.nan
    mi.Bitmap(h).write(str(tmp_path / "nan.exr"))
    with pytest.raises(Exception, match="NaN/Inf texel"):
        displaced(height={"type": "bitmap", "filename": str(tmp_path / "nan.exr"), "raw": True})


@pytest.mark.parametrize("size", [1e-3, 1.0, 1e3])
def test_extreme_scales_and_far_offsets(variant, size):
    """Radius and displacement from 1e-3 to 1e3, 1e4 radii away from the origin: finite,
    watertight, displaced by the requested relative amount."""
    offset = 1e4 * size
    s = displaced(base="sphere", radius=size, resolution=64, scale=0.1 * size, midlevel=0.0,
                  height={"type": "ripples", "frequency": 4.0},
                  to_world=mi.ScalarTransform4f().translate([offset, 0, 0]))
    pos, faces, nrm = buffers(s)
    assert np.all(np.isfinite(pos)) and np.all(np.isfinite(nrm))
    assert trimesh.Trimesh(pos, faces).is_watertight
    r = np.linalg.norm(pos - [offset, 0, 0], axis=1) / size
    # float32 at 1e4 radii from the origin keeps ~1e-3 relative precision of the radius
    assert r.min() > 1 - 2e-3 and r.max() < 1.1 + 2e-3
    assert r.max() - r.min() > 0.09  # the ripples are there


def write_obj(path, pos, nrm, uvs, faces):
    """An OBJ with positions, UVs and vertex normals (one index per corner for all three)."""
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in pos]
    lines += [f"vt {u:.9g} {v:.9g}" for u, v in uvs]
    lines += [f"vn {x:.9g} {y:.9g} {z:.9g}" for x, y, z in nrm]
    lines += ["f " + " ".join(f"{i + 1}/{i + 1}/{i + 1}" for i in f) for f in faces]
    path.write_text("\n".join(lines) + "\n")


def test_mesh_reference_at_zero_height_renders_like_the_smooth_base(variant, tmp_path):
    """Issue 12.1: the `displaced` reference on a 12-gon cylinder at zero height matches the
    smooth-shaded base mesh (Mitsuba's own vertex-normal interpolation), not the facets."""
    from tests.core.test_tessellate import cylinder_mesh

    write_obj(tmp_path / "cyl.obj", *cylinder_mesh(12, 2))

    def render(shape):
        scene = mi.load_dict({
            "type": "scene", "integrator": {"type": "direct"},
            "sensor": {"type": "perspective", "fov": 40, "to_world": mi.ScalarTransform4f().look_at(
                origin=[0, -4.5, 1.5], target=[0, 0, 1], up=[0, 0, 1]),
                "film": {"type": "hdrfilm", "width": 64, "height": 64, "rfilter": {"type": "box"}},
                "sampler": {"type": "independent", "sample_count": 4}},
            "light": {"type": "point", "position": [2, -3, 2], "intensity": {"type": "rgb", "value": 20}},
            "shape": shape})
        img = np.asarray(mi.render(scene, seed=1))
        assert np.all(np.isfinite(img))
        return img

    smooth = render({"type": "obj", "filename": str(tmp_path / "cyl.obj")})
    faceted = render({"type": "obj", "filename": str(tmp_path / "cyl.obj"), "face_normals": True})
    ours = render({"type": "displaced", "filename": str(tmp_path / "cyl.obj"), "subdivision": 4,
                   "scale": 0.0, "height": {"type": "ripples"}})
    lit = smooth.mean()
    assert lit > 0.05
    facet_error = np.abs(faceted - smooth).mean() / lit
    error = np.abs(ours - smooth).mean() / lit
    assert facet_error > 0.05           # the test sees faceting
    assert error < 0.05 * facet_error, (error, facet_error)


def test_edits_reuse_the_crossing_rays_and_still_warn(variant, tmp_path, monkeypatch):
    """The thin-shell check casts its rays once per load: an edit within the checked depth
    casts none and stays silent; an edit deepening the displacement through the 0.015 wall
    casts none either and warns with the count a fresh load gives; the edited buffers are
    a fresh load's."""
    import warnings

    from mi_displace.core import thickness
    from tests.core.test_thickness import shell_mesh

    write_obj(tmp_path / "shell.obj", *shell_mesh())
    casts, cast = [], thickness.cast_crossing_rays
    monkeypatch.setattr(thickness, "cast_crossing_rays",
                        lambda *a: casts.append(1) or cast(*a))
    common = {"filename": str(tmp_path / "shell.obj"), "subdivision": 2, "midlevel": 1.0,
              "height": {"type": "ripples"}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        shape = displaced(id="thin", scale=0.006, **common)
        params = mi.traverse(shape)
        params["scale"] = 0.003
        params.update()
    assert len(casts) == 1 and shape.build_stats["crossing_vertices"] == 0
    with pytest.warns(UserWarning, match="displaced 'thin'.*thickness"):
        params["scale"] = 0.03
        params.update()
    assert len(casts) == 1
    with pytest.warns(UserWarning, match="thickness"):
        fresh = displaced(id="thin", scale=0.03, **common)
    assert shape.build_stats["crossing_vertices"] == fresh.build_stats["crossing_vertices"] > 0
    edited, loaded = buffers(shape), buffers(fresh)
    for a, b in zip(edited, loaded):
        assert np.all(np.isfinite(a)) and np.allclose(a, b, atol=1e-6)


def test_thin_shell_warning_reaches_compare_metrics(variant, tmp_path):
    """Issue 12.3: inward displacement of 0.03 through a 0.015 shell warns, naming the shape,
    and `compare` lists the warning in metrics.json; 0.01 stays silent."""
    import json

    from mi_displace.evaluate.compare import compare
    from tests.core.test_thickness import shell_mesh

    write_obj(tmp_path / "shell.obj", *shell_mesh())
    common = {"filename": str(tmp_path / "shell.obj"), "subdivision": 2, "midlevel": 1.0,
              "height": {"type": "ripples"}}
    with pytest.warns(UserWarning, match="displaced 'thin'.*thickness"):
        deep = mi.load_dict({"type": "displaced", "id": "thin", "scale": 0.03, **common})
    assert deep.build_stats["crossing_vertices"] > 0 and deep.build_stats["warnings"]
    shallow = displaced(scale=0.004, **common)
    assert shallow.build_stats["crossing_vertices"] == 0 and not shallow.build_stats["warnings"]

    (tmp_path / "parts").mkdir()
    for mode, depth in (("reference", 0.03), ("approximation", 0.0)):
        (tmp_path / "parts" / f"shell_{mode}.xml").write_text(
            f'<scene version="3.0.0"><shape type="displaced" id="thin">'
            f'<string name="filename" value="shell.obj"/><integer name="subdivision" value="1"/>'
            f'<float name="scale" value="{depth}"/><float name="midlevel" value="1"/>'
            f'<texture type="ripples" name="height"/></shape></scene>')
    (tmp_path / "shell.xml").write_text("""<scene version="3.0.0">
        <default name="mode" value="reference"/><default name="integrator" value="path"/>
        <default name="approximation_integrator" value="path"/>
        <integrator type="$integrator"><integer name="max_depth" value="2"/></integrator>
        <sensor type="perspective"><transform name="to_world">
            <lookat origin="0, -4, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
            <sampler type="independent"><integer name="sample_count" value="2"/></sampler>
            <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
        </sensor><emitter type="constant"/>
        <include filename="parts/shell_$mode.xml"/></scene>""")
    compare(tmp_path / "shell.xml", tmp_path / "out", max_spp=8)
    saved = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert len(saved["warnings"]) == 1
    assert saved["warnings"][0].startswith("reference: displaced 'thin'")


def test_render_explain_prints_build_stats_per_shape(variant, tmp_path, capsys):
    """`mi-displace render --explain`: every shape with build_stats, the dicing rate and faces;
    a shape diced for the scene's sensor without a <ref> is diced by the loader."""
    from mi_displace import cli

    (tmp_path / "s.xml").write_text("""<scene version="3.0.0"><integrator type="direct"/>
        <sensor type="perspective" id="cam"><float name="fov" value="40"/>
            <transform name="to_world"><lookat origin="0, -4, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
            <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/></film>
        </sensor>
        <shape type="displaced" id="ball"><float name="dicing_rate" value="2"/>
            <texture type="ripples" name="height"/><ref id="cam"/></shape>
        <shape type="displaced" id="loose"><float name="dicing_rate" value="2"/>
            <transform name="to_world"><translate x="3"/></transform></shape>
        <shape type="sphere" id="plain"/></scene>""")
    out = tmp_path / "img.exr"
    with pytest.warns(UserWarning, match="'loose'.*needs a sensor"):
        assert cli.main(["render", str(tmp_path / "s.xml"), "--explain", "--spp", "1",
                         "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "shape 'ball' (Displaced):" in text and "shape 'loose' (Displaced):" in text
    assert "'plain'" not in text
    assert text.count("dicing_rate: 2") == 2 and "faces:" in text and "sensors: 1" in text
    assert out.is_file()
    assert cli.main(["render", str(tmp_path / "s.xml"), "--explain"]) == 0  # explain only


def test_seam_twins_of_a_folded_offset_keep_a_finite_normal(variant):
    """Displacing the bunny's low-poly (UV seams) by a uniform 0.002 folds the offset surface
    where two seam twins' normals cancel: their shared normal falls back to the base's n
    instead of NaN (a fresh load and an edit both refused the shape before)."""
    from mi_displace.inverse import bunny

    scale = bunny.baked_map(64)[2]   # 2 max_distance: 0.0500 (the recovery's model)
    shape = mi.load_dict(bunny._model(np.full((64, 64), 0.54, np.float32), scale))
    for a in buffers(shape):
        assert np.all(np.isfinite(a))
    normals = buffers(shape)[2]
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-4)
