"""`raster`'s ``freeze``: the frame's kernels recorded once and replayed
(:class:`mi_displace.render.raster.FrozenFrames`).  A frozen frame must be the plain frame bit
for bit, after a camera move and after edits of Dr.Jit values and of C++ scalars alike;
scenes Dr.Jit cannot record are drawn unfrozen, once warned about, never black or stale."""
import warnings

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core.resources import scene_path
from mi_displace.render.scene import load

VDM_QUICK = {"vdm_res": 16, "vdm_phi": 8, "vdm_theta": 4, "vdm_curvatures": 4}


def pair(**options):
    """The same ``raster`` twice: plain and frozen."""
    return (mi.load_dict({"type": "raster", **options}),
            mi.load_dict({"type": "raster", "freeze": True, **options}))


def image(scene, integrator):
    img = np.array(mi.render(scene, integrator=integrator))
    assert np.isfinite(img).all() and img.max() > 0
    return img


def same(scene, plain, frozen):
    """The frozen frame (twice: recorded, then replayed) against the plain one, bit for bit."""
    want = image(scene, plain)
    for _ in range(2):
        np.testing.assert_array_equal(image(scene, frozen), want)
    return want


def recorded(scene, plain, frozen):
    """The scene's first frozen frame: recorded (a refusal's warning raises), the plain frame."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        first = image(scene, frozen)
    np.testing.assert_array_equal(first, image(scene, plain))
    return first


def orbit(scene, degrees):
    params = mi.traverse(scene.sensors()[0])
    params["to_world"] = mi.Transform4f().rotate([0, 0, 1], degrees) @ params["to_world"]
    params.update()


@pytest.mark.parametrize("mode, scalar", [("bump", "bsdf.scale"), ("horizon", None),
                                          ("approximation", None)])
def test_frozen_frames_are_the_plain_frames_through_moves_and_edits(variant, mode, scalar):
    """The VDM torus in the modes with different holders of their tables (the bump map's
    C++ ``scale``, horizon's and VDM's textures in dataclasses): recorded, replayed, after a
    camera move (a Dr.Jit input), a colour edit (a Dr.Jit input) and, for bump, an edit of a
    C++ scalar that a recording would hold as a constant (recorded again)."""
    scene, _ = load(scene_path("vdm_torus.xml"), mode=mode, integrator="raster", res=48,
                    **(VDM_QUICK if mode == "approximation" else {}))
    plain, frozen = pair()
    first = same(scene, plain, frozen)
    orbit(scene, 9.0)
    moved = same(scene, plain, frozen)
    assert np.abs(moved - first).max() > 0.01
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith(scalar or "vdm_material.reflectance.value"))
    params[key] = type(params[key])(params[key] * 0.5)
    params.update()
    edited = same(scene, plain, frozen)
    assert np.abs(edited - moved).max() > 0.01
    assert frozen.frozen.refused == {}


def test_area_lights_environment_and_aa_frozen(variant):
    """Light data (area-light points, an environment's SH) prepared outside the recording
    and passed in; a 2 x 2 pattern's box filter inside it; a light moved between frames."""
    scene = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 35, "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, -5, 2], target=[0, 0, 0], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": 40, "height": 32}},
        "ball": {"type": "sphere", "bsdf": {"type": "diffuse"}},
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, -1])
                  @ mi.ScalarTransform4f().scale(4)},
        "lamp": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([1, -1, 3])
                 @ mi.ScalarTransform4f().scale(0.5) @ mi.ScalarTransform4f().rotate([1, 0, 0], 180),
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 8}}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.2}},
    })
    plain, frozen = pair(aa=2, area_samples=4)
    first = same(scene, plain, frozen)
    params = mi.traverse(scene)
    params["lamp.to_world"] = mi.Transform4f().translate([0.6, 0, 0]) @ params["lamp.to_world"]
    params.update()
    assert np.abs(same(scene, plain, frozen) - first).max() > 0.01


def test_the_depth_object_frozen_through_moves_and_edits(variant):
    """The depth object's model (a dataclass of its images' textures) and its BSDF's
    per-interaction cache (a plain object, not traversed): recorded as the scene's first
    frame, the plain frame bit for bit after a camera move and an edit of the sun."""
    scene, _ = load(scene_path("slicing_cup_depth.xml"), mode="approximation",
                    integrator="raster", res=32, slices=16)
    plain, frozen = pair()
    first = recorded(scene, plain, frozen)
    orbit(scene, 7.0)
    moved = same(scene, plain, frozen)
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("irradiance.value"))
    params[key] = params[key] * 0.5
    params.update()
    assert np.abs(same(scene, plain, frozen) - moved).max() > 0.01
    assert frozen.frozen.refused == {}


def diffuse_sphere(bsdf_type: str):
    return mi.load_dict({"type": "scene", "ball": {"type": "sphere", "bsdf": {"type": bsdf_type}},
                         "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 16, "height": 16},
                                    "to_world": mi.ScalarTransform4f().translate([0, 0, -4])},
                         "sun": {"type": "directional", "direction": [0, 0, 1]}})


def lambert():
    """A diffuse BSDF class of 0.25 albedo read from an array (``albedo_array()``); made
    once a variant is set."""
    import drjit as dr

    class Lambert(mi.BSDF):
        def __init__(self, props):
            super().__init__(props)
            self.albedo = mi.Float(0.25, 0.25)
            self.m_components = [mi.BSDFFlags.DiffuseReflection]
            self.m_flags = mi.BSDFFlags.DiffuseReflection

        def eval(self, ctx, si, wo, active=True):
            value = dr.gather(mi.Float, self.albedo_array(), dr.zeros(mi.UInt32, dr.width(si.t)), active)
            return mi.Color3f(value * dr.maximum(mi.Frame3f.cos_theta(wo), 0.0) / dr.pi)

        def albedo_array(self):
            return self.albedo

        def eval_null_transmission(self, si, active=True):
            return mi.Color3f(0.0)

        def eval_diffuse_reflectance(self, si, active=True):
            return mi.Color3f(0.25)

    return Lambert


def test_a_bsdf_declared_unrecordable_is_drawn_unfrozen_with_one_warning(variant):
    """``FREEZABLE = False`` on a BSDF's class: refused before recording (a recording over
    state Dr.Jit cannot traverse may abort the process), drawn plain, warned once."""
    class Declared(lambert()):
        FREEZABLE = False

    mi.register_bsdf("test_declared_unrecordable", Declared)
    scene = diffuse_sphere("test_declared_unrecordable")
    plain, frozen = pair()
    with pytest.warns(UserWarning, match="raster: freeze: this scene's frames are drawn unfrozen "
                                         r"\(BSDF .* is not recordable \(FREEZABLE = False\)"):
        first = image(scene, frozen)
    np.testing.assert_array_equal(first, image(scene, plain))
    with warnings.catch_warnings():
        warnings.simplefilter("error")   # once per scene
        np.testing.assert_array_equal(image(scene, frozen), first)


def test_a_recording_dr_jit_refuses_is_drawn_unfrozen(variant):
    """A BSDF whose array sits in a plain Python object (not traversed): Dr.Jit refuses the
    recording with an exception (the array was made before it and is no input); the frame
    is drawn plain, the reason warned."""
    class Holder:   # not a PyTree: a recording does not see its array
        def __init__(self):
            self.albedo = mi.Float(0.25, 0.25)

    class Hidden(lambert()):
        def __init__(self, props):
            super().__init__(props)
            self.holder = Holder()
            del self.albedo

        def albedo_array(self):
            return self.holder.albedo

    mi.register_bsdf("test_hidden_array", Hidden)
    scene = diffuse_sphere("test_hidden_array")
    plain, frozen = pair()
    with pytest.warns(UserWarning, match=r"\(Dr.Jit refused to record it: "):
        np.testing.assert_array_equal(image(scene, frozen), image(scene, plain))


@pytest.mark.parametrize("direction", ["a", "best", "screen"])
def test_the_sliced_donut_frozen_through_moves_and_rebuilds(variant, direction):
    """The slicing shape rasterises its slices before the frame (``raster_begin``, outside
    the recording) and the recorded frame reads what it drew (the volume and its frame
    buffer as dataclasses): recorded, not refused, and the plain frame bit for bit after a
    camera move and after ``scale`` and ``slices`` edits (a new volume: new slice scenes
    and counts)."""
    scene, _ = load(scene_path("slicing_donut.xml"), mode="approximation", integrator="raster",
                    res=32, coarse=16, slices=12, direction=direction)
    plain, frozen = pair()
    first = recorded(scene, plain, frozen)
    orbit(scene, 11.0)
    moved = same(scene, plain, frozen)
    assert np.abs(moved - first).max() > 0.01
    params = mi.traverse(scene)
    shape = next(k.rsplit(".", 1)[0] for k in params.keys() if k.endswith(".slices"))
    last = moved
    for key, value in (("scale", 0.07), ("slices", 5)):
        params[f"{shape}.{key}"] = mi.Float(value)
        params.update()
        edited = same(scene, plain, frozen)
        assert np.abs(edited - last).max() > 0.01, key
        last = edited
    assert frozen.frozen.refused == {}


@pytest.mark.parametrize("option", [{"visibility": "zbuffer"}, {"shadows": "map"}])
def test_freeze_refuses_passes_sized_by_what_a_frame_finds(variant, option):
    """The z-buffer and shadow maps read back sizes during a frame: refused at load,
    naming the parameter, before any kernel runs."""
    with pytest.raises(Exception, match="raster: 'freeze' needs visibility='raytrace' and "
                                        "shadows='ray' or 'none'"):
        mi.load_dict({"type": "raster", "freeze": True, **option})


@pytest.mark.parametrize("direction", ["a", "best", "screen"])
def test_slicing_on_a_placed_mesh_under_area_light_and_sky_frozen(variant, direction):
    """A user's slicing shape, not the packaged donut: Spot (a mesh base with UV seams; the
    screen-space slices' mesh coordinates), rotated, scaled and moved, lit by an area light
    and a constant environment, 2 x 2 samples a pixel: recorded, and the plain frame bit for
    bit over a camera move."""
    from mi_displace.core.resources import data_path

    T = mi.ScalarTransform4f
    scene = mi.load_dict({
        "type": "scene",
        "cam": {"type": "perspective", "fov": 40,
                "to_world": T().look_at(origin=[2.4, 1.6, 3.6], target=[0.3, 0.8, 0], up=[0, 1, 0]),
                "film": {"type": "hdrfilm", "width": 40, "height": 32}},
        "spot": {"type": "slicing", "base": "mesh", "scale": 0.02, "slices": 6, "direction": direction,
                 "filename": str(data_path("spot/spot_triangulated.obj")), "height": {"type": "bricks"},
                 "to_world": T().translate([0.3, 0.9, 0]) @ T().rotate([0, 1, 0], 35) @ T().scale(1.3)},
        "lamp": {"type": "rectangle", "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 12}},
                 "to_world": T().look_at(origin=[2, 3, 2], target=[0, 0.8, 0], up=[0, 1, 0]) @ T().scale(0.6)},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.15}},
    })
    plain, frozen = pair(aa=2, area_samples=4)
    first = recorded(scene, plain, frozen)
    orbit(scene, 6.0)
    assert np.abs(same(scene, plain, frozen) - first).max() > 0.01
    assert frozen.frozen.refused == {}
