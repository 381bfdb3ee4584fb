"""Displacement deeper than the base's local thickness is detected (issue 12.3)."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import trimesh

from mi_displace.core import surfaces, tessellate
from mi_displace.core.thickness import crossing_check, crossing_warning

WALL = 0.015


def shell_mesh(wall: float = WALL):
    """A thin spherical shell: outer radius 1 (normals out), inner radius 1 - wall (normals
    into the cavity, faces wound to match), spherical UVs; (pos, nrm, uvs, faces)."""
    ico = trimesh.creation.icosphere(3)
    v = ico.vertices / np.linalg.norm(ico.vertices, axis=1)[:, None]
    uv = np.stack([np.arctan2(v[:, 1], v[:, 0]) / (2 * np.pi) + 0.5,
                   np.arccos(np.clip(v[:, 2], -1, 1)) / np.pi], 1)
    n = len(v)
    pos = np.concatenate([v, (1 - wall) * v])
    nrm = np.concatenate([v, -v])
    faces = np.concatenate([ico.faces, ico.faces[:, ::-1] + n])
    return pos, nrm, np.concatenate([uv, uv]), faces


def constant(value):
    return lambda uv: (dr.full(mi.Float, value, dr.width(uv)), dr.zeros(mi.Vector2f, dr.width(uv)))


@pytest.mark.parametrize("depth,crosses", [(0.03, True), (0.01, False)])
def test_inward_displacement_through_a_thin_shell(variant, depth, crosses):
    pos, nrm, uvs, faces = shell_mesh()
    t = tessellate.displace_mesh(pos, nrm, uvs, faces, constant(0.0), depth, 1.0, 2)
    check = crossing_check(t, base_mesh=(pos, faces))
    assert check["vertices"] == t.vertex_count
    if crosses:  # every vertex of both walls passes through the other wall (rays that
        # meet the other wall exactly at one of its vertices or edges may slip through)
        assert check["crossing_vertices"] > 0.95 * t.vertex_count
        assert check["max_depth_ratio"] == pytest.approx(depth / WALL, rel=0.05)
        message = crossing_warning("displaced 'shell'", check)
        assert "'shell'" in message and "thickness" in message
    else:
        assert check["crossing_vertices"] == 0
        assert crossing_warning("displaced 'shell'", check) is None


def test_outward_displacement_does_not_count(variant):
    pos, nrm, uvs, faces = shell_mesh()
    t = tessellate.displace_mesh(pos, nrm, uvs, faces, constant(1.0), 0.05, 0.0, 2)
    assert crossing_check(t, base_mesh=(pos, faces))["crossing_vertices"] == 0


def test_parametric_bases_use_their_analytic_thickness(variant):
    torus = surfaces.Torus(1.0, 0.1)
    assert torus.thickness() == pytest.approx(0.2) and surfaces.Plane().thickness() == np.inf
    t = tessellate.displace_parametric(torus, constant(0.0), 0.3, 1.0, 32, 16)
    assert crossing_check(t, thickness=torus.thickness())["crossing_vertices"] == t.vertex_count
    t = tessellate.displace_parametric(torus, constant(0.0), 0.1, 1.0, 32, 16)
    assert crossing_check(t, thickness=torus.thickness())["crossing_vertices"] == 0


def test_both_walls_moving_towards_each_other_cross(variant):
    """Each wall moves 0.01 inwards (less than the 0.015 wall): alone harmless, together they
    meet; counted once the other side's displacement is known."""
    pos, nrm, uvs, faces = shell_mesh()
    t = tessellate.displace_mesh(pos, nrm, uvs, faces, constant(0.0), 0.01, 1.0, 2)
    alone = crossing_check(t, base_mesh=(pos, faces))
    both = crossing_check(t, base_mesh=(pos, faces, uvs),
                          other_side=lambda uv: dr.full(mi.Float, -0.01, dr.width(uv)))
    assert alone["crossing_vertices"] == 0
    assert both["crossing_vertices"] > 0.95 * t.vertex_count
    assert both["max_depth_ratio"] == pytest.approx(0.02 / WALL, rel=0.1)


def _full_depth_check(pos, nrm, uvs, faces, base, scale):
    """Both walls of Spot moved ``scale`` inwards everywhere (h = 0, midlevel 1)."""
    t = tessellate.displace_mesh(pos, nrm, uvs, faces, constant(0.0), scale, 1.0, 2)
    return crossing_check(t, base_mesh=base,
                          other_side=lambda uv: dr.full(mi.Float, -scale, dr.width(uv)))


def test_spot_is_flagged_at_its_tail_only(variant):
    """vdm_spot's reference warns: Spot's tail (the nub at the rear, z > 0.95) is 0.035-0.039
    thick, less than both walls moving 0.02 inwards.  No false positives elsewhere (ears,
    horns, a vertex's own neighbourhood): up to 0.0175 per wall nothing is flagged, and the
    rest of the cow, cast against the whole base, is clean at 0.02 and 0.025."""
    from pathlib import Path

    from mi_displace.core.mesh_io import load_uv_mesh

    spot = Path(__file__).resolve().parents[2] / "data" / "spot" / "spot_triangulated.obj"
    pos, nrm, uvs, faces = load_uv_mesh(str(spot))
    base = (pos, faces, uvs)
    assert _full_depth_check(pos, nrm, uvs, faces, base, 0.0175)["crossing_vertices"] == 0
    assert _full_depth_check(pos, nrm, uvs, faces, base, 0.02)["crossing_vertices"] > 0
    x, y, z = pos[:, 0], pos[:, 1], pos[:, 2]
    tail = (z > 0.95) & (np.abs(x) < 0.1) & (y > -0.2) & (y < 0.05)   # the nub at the rear
    body = faces[~np.any(tail[faces], axis=1)]                       # the rest of the cow
    used, body = np.unique(body, return_inverse=True)
    body = body.reshape(-1, 3)
    assert 0.9 * len(faces) < len(body) < len(faces)
    for scale in (0.02, 0.025):
        check = _full_depth_check(pos[used], nrm[used], uvs[used], body, base, scale)
        assert check["crossing_vertices"] == 0, (scale, check)


def test_crossing_check_without_displacement_or_vertices(variant):
    """No displacement (zero height) and an empty tessellation: nothing crosses, exactly."""
    flat = tessellate.Tessellation(mi.Point3f([0, 1, 0], [0, 0, 1], [0, 0, 0]),
                                   mi.Vector3f([0, 0, 0], [0, 0, 0], [1, 1, 1]),
                                   mi.Point2f([0, 1, 0], [0, 0, 1]), mi.Vector3u([0], [1], [2]))
    assert crossing_check(flat, thickness=0.1) == {
        "crossing_vertices": 0, "vertices": 3, "max_depth_ratio": 0.0}
    empty = tessellate.Tessellation(mi.Point3f(), mi.Vector3f(), mi.Point2f(), mi.Vector3u(),
                                    displacement=mi.Float())
    assert crossing_check(empty, thickness=0.1) == {
        "crossing_vertices": 0, "vertices": 0, "max_depth_ratio": 0.0}


def test_displacement_of_exactly_the_thickness_reaches_but_does_not_cross(variant):
    """A parametric base of thickness 0.25 (torus tube radius 0.125): an inward displacement
    of exactly 0.25 (d = 0.25 (0 - 1), exact in float32) touches the other side; a crossing
    is a displacement *deeper* than the thickness (ratio > 1)."""
    torus = surfaces.Torus(1.0, 0.125)
    assert torus.thickness() == 0.25
    t = tessellate.displace_parametric(torus, constant(0.0), 0.25, 1.0, 16, 8)
    assert np.all(np.asarray(t.displacement) == -0.25)
    assert crossing_check(t, thickness=0.25)["crossing_vertices"] == 0
    t = tessellate.displace_parametric(torus, constant(0.0), 0.2501, 1.0, 16, 8)
    check = crossing_check(t, thickness=0.25)
    assert check["crossing_vertices"] == t.vertex_count
    assert check["max_depth_ratio"] == pytest.approx(0.2501 / 0.25, rel=1e-6)


def test_outward_rays_use_their_own_facing(variant):
    """A vertex at the origin (n = +z) displaced +0.5: the +n ray meets a steep roof 0.3
    above at a grazing angle (cos 0.087 < GRAZING_COS: a crease, not a crossing), the -n ray
    a floor head-on.  The outward vertex is judged by its own (+n) ray: no crossing; moved
    -0.5 instead it passes through the floor 0.4 below (ratio 0.5 / 0.4)."""
    from mi_displace.core.thickness import crossing_warning

    a = np.radians(5.0)
    up = np.array([np.sin(a), 0, np.cos(a)])          # the roof rises 5 degrees off vertical
    mid = np.array([[0, 1, 0.3], [0, -1, 0.3]])       # the roof's middle line, over the origin
    roof = [*(mid - up), *(mid[::-1] + up)]
    floor = [[-1, -1, -0.4], [1, -1, -0.4], [1, 1, -0.4], [-1, 1, -0.4]]
    pos = np.array(roof + floor, np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])

    def vertex(d):
        p = mi.Point3f([0.0], [0.0], [0.0])
        return tessellate.Tessellation(p, mi.Vector3f([0], [0], [1]), mi.Point2f([0], [0]),
                                       mi.Vector3u([0], [0], [0]), p, mi.Vector3f([0], [0], [1]),
                                       mi.Float([d]))

    from mi_displace.core.thickness import cast_crossing_rays

    rays = cast_crossing_rays(vertex(0.5), (pos, faces))
    assert np.asarray(rays.gap[0])[0] == pytest.approx(0.3, abs=1e-4)      # the roof is met
    assert abs(np.asarray(rays.facing[0])[0]) == pytest.approx(np.sin(a), abs=1e-4)
    assert abs(np.asarray(rays.facing[1])[0]) == pytest.approx(1.0, abs=1e-6)   # the floor
    assert crossing_check(vertex(0.5), base_mesh=(pos, faces))["crossing_vertices"] == 0
    down = crossing_check(vertex(-0.5), base_mesh=(pos, faces))
    assert down["crossing_vertices"] == 1
    assert down["max_depth_ratio"] == pytest.approx(0.5 / 0.4, rel=1e-3)
    assert crossing_warning("displaced 'x'", down) == (
        "displaced 'x': displacement deeper than the local thickness of the base at 1 of 1 "
        "vertices (up to 1.25x the distance to the base's other side): the displaced surface "
        "passes through the base and the reference is wrong there; lower 'scale' or raise "
        "'midlevel'")


def test_crossing_rays_report_the_uv_of_what_they_hit(variant):
    """With base UVs the rays carry the texture coordinates of the hit: from the outer wall
    of a thin spherical shell (both walls with the same spherical UVs) the -n ray meets the
    inner wall at (nearly) the vertex's own (u, v)."""
    import trimesh

    from mi_displace.core.thickness import cast_crossing_rays

    ico = trimesh.creation.icosphere(3)
    v = ico.vertices / np.linalg.norm(ico.vertices, axis=1, keepdims=True)
    uv = np.stack([np.arctan2(v[:, 1], v[:, 0]) / (2 * np.pi) + 0.5,
                   np.arccos(np.clip(v[:, 2], -1, 1)) / np.pi], 1)
    n = len(v)
    pos = np.concatenate([v, 0.985 * v])
    faces = np.concatenate([ico.faces, ico.faces[:, ::-1] + n])
    t = tessellate.displace_mesh(v, v, uv, ico.faces, None, 0.0, 0.0, 1)
    rays = cast_crossing_rays(t, (pos, faces, np.concatenate([uv, uv])))
    hit = np.asarray(rays.uv[1]).T
    own = np.asarray(t.texcoords).T
    away = (np.abs(own[:, 0] - 0.5) < 0.4) & (np.abs(own[:, 1] - 0.5) < 0.35)   # seam, poles
    assert away.sum() > 100
    err = np.abs(hit[away] - own[away]).max(1)
    assert np.mean(err < 2e-3) > 0.95       # (a few hit a face spanning the u seam)
