"""Screen-space slices (§3.3) on mesh bases: a point's (u, v, h) from the prism map
inverted by ray queries against the base (:class:`mi_displace.slicing.geometry.MeshCoordinates`),
checked against the parametric bases' closed-form coordinates under the same camera."""
import numpy as np
import mitsuba as mi

from tests.plugins.test_displaced_seams import uv_sphere_obj
from tests.slicing.test_slicing_memory import grid_obj, sensor


def render(cam, shape):
    scene = mi.load_dict({"type": "scene", "sensor": cam, "integrator": {"type": "raster"}, "obj": shape,
                          "sun": {"type": "directional", "direction": [-0.4, 0.5, -0.75], "irradiance": 2.0},
                          "amb": {"type": "constant", "radiance": 0.1}})
    img = np.array(mi.render(scene, spp=1, seed=0))[..., :3]
    assert np.all(np.isfinite(img))
    return img


def differ(a, b):
    """Fraction of pixels whose channels differ by more than 0.05."""
    return float((np.abs(a - b).max(-1) > 0.05).mean())


def test_screen_on_a_flat_mesh_matches_the_parametric_plane(variant, tmp_path):
    """Screen-space slices on a mesh base: its (u, v, h) come from the prism map inverted
    by ray queries; on a flat grid that inversion is exact, so the image is that of the
    parametric plane (closed-form coordinates) under the same camera."""
    path = grid_obj(tmp_path / "grid.obj")
    common = {"direction": "screen", "slices": 8, "scale": 0.2, "draw_base": True,
              "height": {"type": "bricks", "rows": 4, "columns": 2}}
    cam = sensor()
    cam["to_world"] = mi.ScalarTransform4f().look_at(origin=[0.6, -2.2, 2.0], target=[0, 0, 0], up=[0, 0, 1])
    mesh, plane = (render(cam, {"type": "slicing", **base, **common})
                   for base in ({"base": "mesh", "filename": path}, {"base": "plane"}))
    assert (plane.sum(-1) > 0.05).mean() > 0.2
    assert differ(mesh, plane) < 0.01


def test_screen_on_a_sphere_mesh_matches_the_parametric_sphere(variant, tmp_path, monkeypatch):
    """A 64 x 32 lat-long sphere mesh (the parametric sphere's uv): its extrusion directions
    spread by ~6 degrees over a triangle, so the foot is found by iterating; the image is
    the parametric sphere's up to the facets (measured: 0.65 % of 48^2 pixels differ, 2.9 %
    for `best` on the same mesh, 3.9 % with a single step from the entry's extrusion)."""
    from mi_displace.slicing import geometry as geo

    path = uv_sphere_obj(tmp_path / "sphere.obj", nu=64, nv=32)
    cam = sensor()
    cam["film"].update(width=48, height=48)
    cam["to_world"] = mi.ScalarTransform4f().look_at(origin=[1.5, -3.6, 2.0], target=[0, 0, 0], up=[0, 0, 1])
    common = {"slices": 8, "scale": 0.15, "height": {"type": "bricks", "rows": 8, "columns": 8}}
    exact = render(cam, {"type": "slicing", "base": "sphere", "direction": "screen", **common})
    mesh = {"type": "slicing", "base": "mesh", "filename": path, **common}
    screen = render(cam, {**mesh, "direction": "screen"})
    best = render(cam, {**mesh, "direction": "best"})
    assert differ(screen, exact) < 0.015
    assert differ(screen, exact) < differ(best, exact)
    monkeypatch.setattr(geo.MeshCoordinates, "ITERATIONS", 1)
    assert differ(render(cam, {**mesh, "direction": "screen"}), exact) > differ(screen, exact)


def test_screen_on_a_mesh_follows_to_world(variant, tmp_path):
    """The planes are made in object space and the mesh's coordinates found in world
    space: under a rotated, translated and non-uniformly scaled ``to_world`` the flat mesh
    still gives the parametric plane's image."""
    path = grid_obj(tmp_path / "grid.obj")
    T = mi.ScalarTransform4f
    to_world = T().translate([0.3, 0.2, 0]) @ T().rotate([0, 0, 1], 25) @ T().scale([1.3, 0.8, 1.0])
    common = {"direction": "screen", "slices": 8, "scale": 0.2, "draw_base": True, "to_world": to_world,
              "height": {"type": "bricks", "rows": 4, "columns": 2}}
    cam = sensor()
    cam["to_world"] = T().look_at(origin=[1.0, -3.2, 3.0], target=[0.3, 0.2, 0], up=[0, 0, 1])
    mesh, plane = (render(cam, {"type": "slicing", **base, **common})
                   for base in ({"base": "mesh", "filename": path}, {"base": "plane"}))
    assert differ(mesh, plane) < 0.01


def test_mesh_coordinates_queried_as_coherent_rays_in_a_raster_frame(variant, tmp_path, monkeypatch):
    """During a raster frame the foot queries of screen slicing on a mesh base use Embree's
    coherent flag (the frame's samples are neighbouring points): the same feet, so the same
    image bit for bit as incoherent queries."""
    from mi_displace.slicing import geometry as geo

    path = uv_sphere_obj(tmp_path / "sphere.obj", nu=32, nv=16)
    cam = sensor()
    cam["film"].update(width=32, height=32)
    cam["to_world"] = mi.ScalarTransform4f().look_at(origin=[1.5, -3.6, 2.0], target=[0, 0, 0], up=[0, 0, 1])
    shape = {"type": "slicing", "base": "mesh", "filename": path, "slices": 8, "scale": 0.15,
             "direction": "screen", "height": {"type": "bricks", "rows": 8, "columns": 8}}
    flags, call = [], geo.MeshCoordinates.__call__

    def recorded(self, p, e, active, coherent=False):
        flags.append(coherent)
        return call(self, p, e, active, coherent)

    monkeypatch.setattr(geo.MeshCoordinates, "__call__", recorded)
    coherent = render(cam, shape)
    assert flags and all(flags)
    flags.clear()
    from mi_displace.plugins.slicing import Slicing
    begin = Slicing.raster_begin

    def incoherent(self, sensor, aa):
        begin(self, sensor, aa)
        self.volume.coherent = False

    monkeypatch.setattr(Slicing, "raster_begin", incoherent)
    plain = render(cam, shape)
    assert flags and not any(flags)
    assert (plain.sum(-1) > 0.05).mean() > 0.2 and np.array_equal(coherent, plain)
