"""No exactly black pixel where the true geometry is lit: the surface a slicing walk finds is
shaded from the side the ray arrives on (its gradient normal can face away from the viewer
where the slices show a fragment the true surface would hide, or where the ray reaches the
far side of the volume through a groove).

Sky-lit (a constant emitter) ``path`` renders at 32 spp: an exactly black pixel is one whose
32 paths all found no light.  The bound is the true geometry's own count at the same spp
(``displaced``): a pixel it lights sees enough sky that 32 misses in a row are not expected
there either (screen slicing on a bricks torus: 0 here against 11 pixels of 48^2 with the
gradient normal used as it is)."""
import mitsuba as mi
import numpy as np

from slicing_scenes import bricks_torus

SPP = 32


def render(shape, res=48):
    """Max over channels of a 32 spp sky-lit ``path`` render, (res, res)."""
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 8}, "obj": shape,
        "sky": {"type": "constant", "radiance": 1.0},
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0.3, -3.0, 2.4],
                                                              target=[0, 0, 0], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": res, "height": res,
                            "rfilter": {"type": "box"}}}})
    img = np.array(mi.render(scene, spp=SPP))[..., :3]
    assert np.all(np.isfinite(img)), "non-finite pixels"
    return img.max(-1)


def test_screen_slicing_has_no_black_pixel_where_the_true_geometry_is_lit(variant):
    torus = bricks_torus()
    ref = render({"type": "displaced", **torus, "resolution": 256})
    img = render({"type": "slicing", **torus, "resolution": 16, "slices": 8,
                  "direction": "screen", "draw_base": True})
    covered = np.abs(img - 1.0) > 1e-4
    assert covered.mean() > 0.2, "the object is in view"
    black = ((img == 0) & (ref > 0)).sum()
    ref_black = ((ref == 0) & covered).sum()
    assert black <= ref_black, (black, ref_black)
