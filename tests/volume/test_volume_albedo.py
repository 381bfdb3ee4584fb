"""The albedo of a displaced volume (``output="albedo"``): a colour field read at the same
pre-image as the density, under volpath and the slicer."""
import mitsuba as mi
import numpy as np
import pytest

from test_volume_render import _render, _scene, _volume
from volume_helpers import points as _p, to_numpy as _np

RED, BLUE = (0.9, 0.1, 0.1), (0.1, 0.2, 0.9)


def _albedo(source, low, high, **kw):
    return mi.load_dict({"type": "displaced_volume", "output": "albedo", "source": source,
                         "albedo_low": mi.ScalarColor3f(low), "albedo_high": mi.ScalarColor3f(high), **kw})


def _medium_scene(vol, albedo, res=16):
    d = {"type": "scene",
         "sun": {"type": "directional", "direction": [-0.5, 0.6, -1], "irradiance": {"type": "rgb", "value": 6.0}},
         "sensor": {"type": "perspective", "fov": 30.0,
                    "to_world": mi.ScalarTransform4f().look_at(origin=[0.9, -2.3, 1.3], target=[0, 0, 0], up=[0, 0, 1]),
                    "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
         "integrator": {"type": "volpath", "max_depth": 2},
         "proxy": {"type": "volume_proxy", "volume": vol, "bsdf": {"type": "null"},
                   "interior": {"type": "heterogeneous", "sigma_t": vol, "albedo": albedo}}}
    return mi.load_dict(d)


def test_constant_albedo_field_renders_as_the_constant_albedo(variant):
    """low == high: the field is that constant everywhere, so volpath (same seed) and the
    slicer give the constant-albedo images exactly."""
    vol = _volume(maps=[("seam", {"amount": 0.2})])
    field = _albedo(vol, (0.7, 0.7, 0.7), (0.7, 0.7, 0.7))
    a = _render(_medium_scene(vol, 0.7), spp=16, seed=3)
    b = _render(_medium_scene(vol, field), spp=16, seed=3)
    assert a.max() > 0 and np.array_equal(a, b)
    plain = _render(_scene("volume_slicer", vol, albedo=0.7))
    coloured = _render(_scene("volume_slicer", vol, albedo=field))
    assert plain.max() > 0 and np.array_equal(plain, coloured)


@pytest.mark.parametrize("mode", ["reference", "approximation"])
def test_colour_moves_with_the_displacement(variant, mode):
    """A two-colour field (red below z = 0.7, blue above) under slabs that lift the upper half
    of the unit cube by 0.3 (closed-form forward map f_z = z + [z >= 1/2] 0.3): an object
    point keeps its colour at its displaced position, where the undisplaced field has the
    other colour."""
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap
    from mi_displace.volume.field import AlbedoField, DisplacedVolume
    from mi_displace.volume.objects import ObjectVolume

    n = 64
    z = (np.arange(n) + 0.5) / n
    label = np.broadcast_to((z > 0.7)[:, None, None], (n, n, n)).astype(np.float32)
    field = ObjectVolume(label, [0, 0, 0], [1, 1, 1], value_range=(0, 1))
    obj = ObjectVolume(np.ones((8, 8, 8)), [0, 0, 0], [1, 1, 1], value_range=(0, 1))
    chain = DisplacementChain([PlacedMap("slabs", {"count": 2, "gap": 0.3})], bits=32)
    vol = DisplacedVolume(obj, chain, mode=mode, tf_low=0.0, tf_high=1.0)
    colour = AlbedoField(vol, RED, BLUE, (0.25, 0.75), field)
    rng = np.random.default_rng(1)
    l = rng.uniform(0.15, 0.85, (3000, 3))
    l[:, 2] = np.concatenate([rng.uniform(0.1, 0.4, 1000), rng.uniform(0.55, 0.65, 1000), rng.uniform(0.75, 0.95, 1000)])
    moved = l.copy()
    moved[:, 2] += np.where(l[:, 2] >= 0.5, 0.3, 0.0)
    expected = np.where((l[:, 2] > 0.7)[:, None], BLUE, RED)
    got = _np(colour.albedo(_p(moved)))
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, expected, atol=1e-5)
    # the middle band now sits where the undisplaced field is blue: the colour moved
    undisplaced = _np(AlbedoField(DisplacedVolume(obj, DisplacementChain([]), tf_low=0, tf_high=1),
                                  RED, BLUE, (0.25, 0.75), field).albedo(_p(moved)))
    assert np.allclose(undisplaced[1000:2000], BLUE) and np.allclose(got[1000:2000], RED)


def test_slicer_colours_like_volpath(variant):
    """The piggy bank's coins (density 1) and shell (0.6) coloured by a transfer on density,
    cut open by a seam: the slicer's scatter model with the albedo volume has the same mean
    colour as volpath's medium with it (per channel, 5 %), and the colour is not grey."""
    vol = _volume(maps=[("seam", {"amount": 0.25})])
    field = _albedo(vol, (0.9, 0.35, 0.35), (0.95, 0.8, 0.15), albedo_range_low=0.6, albedo_range_high=1.0)
    approx = _render(_scene("volume_slicer", vol, res=16, spacing=0.5, aa=4, albedo=field))
    ref = np.mean([_render(_medium_scene(vol, field), spp=64, seed=s) for s in range(4)], axis=0)
    m_ref, m_approx = ref.reshape(-1, 3).mean(0), approx.reshape(-1, 3).mean(0)
    assert m_ref[0] > 1.5 * m_ref[2]                    # red/gold, not grey
    np.testing.assert_allclose(m_approx / m_ref, 1.0, atol=0.05)


def test_albedo_bad_input(variant):
    vol = _volume()
    with pytest.raises(RuntimeError, match="output"):
        mi.load_dict({"type": "displaced_volume", "procedural": "piggy_bank", "resolution": 16, "output": "colour"})
    with pytest.raises(RuntimeError, match="albedo_low"):
        _albedo(vol, (1.5, 0.2, 0.2), (0.5, 0.5, 0.5))
    with pytest.raises(RuntimeError, match="albedo_range"):
        _albedo(vol, RED, BLUE, albedo_range_low=0.6, albedo_range_high=0.6)
    colour = _albedo(vol, RED, BLUE)
    with pytest.raises(RuntimeError, match="source"):
        _albedo(colour, RED, BLUE)                       # an albedo volume is no density source
    with pytest.raises(RuntimeError, match="albedo"):
        _scene("volume_slicer", vol, albedo=mi.load_dict({"type": "constvolume"}))


def test_albedo_follows_an_edit_of_its_source(variant):
    """The albedo volume shares its source's chain: a mi.traverse edit of the source's map
    (slabs over [-0.5, 0.5]^3: the upper half lifts by the gap) moves the colour too, and the
    albedo volume itself exposes no map parameters."""
    m = mi.ScalarTransform4f().translate([-0.5, -0.5, -0.5])
    vol = _volume(maps=[("slabs", {"count": 2, "gap": 0.0})], mode="reference", map0_to_world=m)
    colour = _albedo(vol, RED, BLUE, albedo_range_low=0.0, albedo_range_high=0.6)
    assert len(mi.traverse(colour)) == 0
    it = mi.Interaction3f()
    it.p = _p([[0.0, 0.0, 0.57]])                   # above the shell: no matter, low colour
    np.testing.assert_allclose(np.array(colour.eval(it))[:, 0], RED, atol=1e-6)
    params = mi.traverse(vol)
    params["map0_gap"] = 0.3
    params.update()
    # now it shows the shell's top at z = 0.27 (piggy bank density 0.6 there)
    shell = float(vol.volume.obj.density(_p([[0.0, 0.0, 0.27]]))[0])
    assert shell > 0.3
    t = min(shell / 0.6, 1.0)
    expected = np.array(RED) + t * (np.array(BLUE) - np.array(RED))
    np.testing.assert_allclose(np.array(colour.eval(it))[:, 0], expected, atol=1e-5)
