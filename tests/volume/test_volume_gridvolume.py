"""The exact reference against Mitsuba's own ``gridvolume`` (``bench volume``'s ``gridvolume``
part): the resampled field and the two renders' means."""
import mitsuba as mi
import numpy as np

from test_volume_render import _render, _scene, _volume


def test_resample_on_the_objects_own_grid_reads_its_voxels(variant):
    """Cell centres of the object's own grid are its texel centres: sigma_t there is
    density_scale times the voxels (transfer ramp 0..1), whatever the interpolation."""
    plugin = _volume(mode="reference", density_scale=15.0)
    obj = plugin.volume.obj
    data = plugin.volume.resample(obj.bbox_min, obj.bbox_max, obj.shape)
    assert data.shape == obj.shape and np.isfinite(data).all()
    np.testing.assert_allclose(data, 15.0 * obj.data, rtol=1e-5, atol=1e-6)


def test_reference_agrees_in_mean_with_a_gridvolume_of_the_same_field(variant):
    """volpath on the displaced_volume (an all-zero map, so that the field is the object's
    voxels) and on Mitsuba's gridvolume holding them (independent truth): the per-pixel
    difference of one render each (independent seeds) has a mean within 4 standard errors
    of 0 (about 2 % of the image mean here: a grid off by a voxel or an axis, or a density
    off by that much, fails)."""
    from mi_displace.bench.volume import grid_scene

    plugin = _volume(mode="reference", maps=[("gaussian", {"amount": 0.0})])
    ours = _scene("volpath", plugin, res=32)
    grid, shape = grid_scene(ours)
    assert shape == plugin.volume.obj.shape    # zero map: the medium box is the object's box
    a = _render(ours, spp=256, seed=1)[..., 0]
    b = _render(grid, spp=256, seed=2)[..., 0]
    assert a.mean() > 0.01 and b.mean() > 0.01
    d = (a - b).ravel()
    assert abs(d.mean()) < 4 * d.std(ddof=1) / np.sqrt(d.size)
    assert not np.array_equal(a, b)             # independent samples: the test sees noise
