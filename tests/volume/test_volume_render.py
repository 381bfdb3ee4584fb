"""Slicing renderer against volpath, extremes, bad input, animation through mi.traverse."""
import mitsuba as mi
import numpy as np
import pytest

from test_volume_normals import _ball_volume
from volume_helpers import points as _points, to_numpy as _np


def _volume(mode="approximation", maps=None, **kw):
    d = {"type": "displaced_volume", "procedural": "piggy_bank", "resolution": 32, "mode": mode,
         "tf_low": 0.0, "tf_high": 1.0, "density_scale": 15.0, **kw}
    for i, (kind, params) in enumerate(maps or []):
        d[f"map{i}_type"] = kind
        d.update({f"map{i}_{k}": v for k, v in params.items()})
    return mi.load_dict(d)


def _scene(integrator, volume, res=24, origin=(0.9, -2.3, 1.3), fov=30.0, **integrator_props):
    d = {"type": "scene",
         "sun": {"type": "directional", "direction": [-0.5, 0.6, -1], "irradiance": {"type": "rgb", "value": 6.0}},
         "sensor": {"type": "perspective", "fov": fov,
                    "to_world": mi.ScalarTransform4f().look_at(origin=list(origin), target=[0, 0, 0], up=[0, 0, 1]),
                    "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}}}
    if integrator == "volpath":
        d["integrator"] = {"type": "volpath", "max_depth": 2}
        d["proxy"] = {"type": "volume_proxy", "volume": volume, "bsdf": {"type": "null"},
                      "interior": {"type": "heterogeneous", "sigma_t": volume, "albedo": 0.8}}
    else:
        d["integrator"] = {"type": "volume_slicer", "volume": volume, "albedo": 0.8, **integrator_props}
    return mi.load_dict(d)


def _render(scene, **kw):
    img = np.array(mi.render(scene, **kw))
    assert np.isfinite(img).all()
    return img


def test_slicer_agrees_with_volpath(variant):
    """Consistency (no displacement): single scattering by slices vs Mitsuba's volpath.

    Per-pixel z-test of the difference against the reference's own standard error (16
    independent 64-spp renders), with a Bonferroni-corrected threshold."""
    vol = _volume()
    approx = _render(_scene("volume_slicer", vol, res=20, spacing=0.5, aa=4))[..., 0]  # box filter as the film
    ref = np.stack([_render(_scene("volpath", vol, res=20), spp=64, seed=s)[..., 0] for s in range(10)])
    mean, se = ref.mean(0), ref.std(0, ddof=1) / np.sqrt(len(ref))
    lit = mean > 0.02 * mean.max()
    assert abs(approx[lit].mean() / mean[lit].mean() - 1) < 0.04
    z = np.abs(approx - mean)[lit] / np.maximum(se[lit], 1e-3 * mean.max())
    from scipy.stats import norm
    threshold = norm.isf(0.01 / (2 * lit.sum()))
    assert (z > threshold).mean() < 0.05     # discretisation: a few edge pixels may exceed it


def test_zero_displacement_renders_bit_identically(variant):
    plain = _volume()
    zero = _volume(maps=[("gaussian", {"amount": 0.0}), ("peel", {"angle": 0.0}), ("wave", {"amount": 0.0})])
    for props in ({"model": "scatter"}, {"model": "surface", "normals": "jacobian"},
                  {"model": "surface", "normals": "blend"}):
        a = _render(_scene("volume_slicer", plain, **props))
        b = _render(_scene("volume_slicer", zero, **props))
        assert a.max() > 0 and np.array_equal(a, b)
        assert np.array_equal(a, _render(_scene("volume_slicer", plain, **props)))   # deterministic


def test_extremes_stay_finite(variant):
    vol = _volume(maps=[("gaussian", {"amount": 0.95})], bits=8)       # 8-bit map, large pull
    assert _render(_scene("volume_slicer", vol)).max() > 0
    inside = _render(_scene("volume_slicer", _volume(), origin=(0.05, -0.1, 0.02)))   # camera inside
    assert inside.max() > 0
    # close up with a 150-degree view: edge rays meet the view-aligned slices at ~75 degrees
    grazing = _render(_scene("volume_slicer", _volume(), origin=(0.25, -0.6, 0.25), fov=150.0, model="surface"))
    assert grazing.max() > 0


def test_majorant_bounds_the_displaced_density(variant):
    vol = _volume(maps=[("slabs", {"count": 3, "gap": 0.3}), ("gaussian", {"amount": 0.9})], bits=8)
    for mode in ("reference", "approximation"):
        vol.volume.mode = mode
        lo, hi = vol.volume.proxy_box()
        p = np.random.default_rng(0).uniform(lo - 0.5, hi + 0.5, (200000, 3))
        sigma = np.array(vol.volume.sigma_t(mi.Point3f(*(mi.Float(p[:, i]) for i in range(3)))))
        assert sigma.max() <= vol.max() and sigma.max() > 0.5 * vol.max()
        outside = ((p < lo) | (p > hi)).any(1)
        assert sigma[outside].max() == 0.0            # the proxy holds all displaced matter


def test_bad_input(variant):
    vol = _volume()
    for props, match in (({"spacing": 0.0}, "spacing"), ({"model": "xray"}, "model"),
                         ({"normals": "sobel"}, "normals"), ({"spacing": 1e-5}, "slices")):
        with pytest.raises(Exception, match=match):
            _render(_scene("volume_slicer", vol, **props))
    with pytest.raises(RuntimeError, match="exactly one of"):
        mi.load_dict({"type": "displaced_volume"})
    with pytest.raises(RuntimeError, match="displaced_volume: parameter 'to_world' is not supported"):
        mi.load_dict({"type": "displaced_volume", "procedural": "piggy_bank", "resolution": 16,
                      "to_world": mi.ScalarTransform4f().translate([1, 0, 0])})
    with pytest.raises(RuntimeError, match="singular"):
        mi.load_dict({"type": "displaced_volume", "procedural": "piggy_bank", "resolution": 16,
                      "map0_type": "wave", "map0_to_world": mi.ScalarTransform4f().scale([1, 0, 1])})


@pytest.mark.parametrize("light", ["area", "envmap"])
def test_lights_the_slicer_cannot_draw_are_refused(variant, light, tmp_path):
    """An area light or an environment map would leave the slices unlit: refused, naming
    the emitter and the integrator, before anything renders."""
    if light == "area":
        emitter = {"type": "rectangle", "emitter": {"type": "area", "radiance": 5.0}}
    else:
        mi.Bitmap(np.full((8, 16, 3), 0.5, dtype=np.float32)).write(str(tmp_path / "env.exr"))
        emitter = {"type": "envmap", "filename": str(tmp_path / "env.exr")}
    sc = _scene("volume_slicer", _volume())
    d = {"type": "scene", "integrator": {"type": "volume_slicer", "volume": _volume(),
                                         "albedo": 0.8},
         "sensor": sc.sensors()[0], "odd_light": emitter}
    sc = mi.load_dict(d)
    problem = sc.integrator().setup_problem(sc)
    assert problem.startswith("volume_slicer: cannot draw emitter") and "\n" not in problem
    with pytest.raises(ValueError, match="volume_slicer: cannot draw emitter"):
        sc.integrator().render(sc, sc.sensors()[0])


def test_traverse_edits_maps_without_rebuilding_the_object(variant):
    vol = _volume(maps=[("peel", {"angle": 10.0, "hinge": 1.0, "height": 0.5})])
    scene = _scene("volume_slicer", vol)
    before = _render(scene)
    textures = vol.volume.obj.textures()
    params = mi.traverse(vol)
    assert "map0_angle" in params and "map0_to_world" in params
    params["map0_angle"] = 60.0
    params.update()
    after = _render(scene)
    assert vol.volume.obj.textures() is textures
    assert np.abs(after - before).max() > 0.1 * before.max()
    assert vol.volume.chain.maps[0].params["angle"] == 60.0


def test_medium_volume_refuses_to_outgrow_its_box(variant):
    """Under volpath the medium box is fixed at load time: an edit that displaces matter past
    it is an error (naming 'bounds'), not a silently clipped reference."""
    vol = _volume(maps=[("peel", {"angle": 10.0, "hinge": 1.0, "height": 0.5})])
    _scene("volpath", vol)                                  # volume_proxy: the medium's container
    params = mi.traverse(vol)
    params["map0_angle"] = 80.0
    with pytest.raises(Exception, match="bounds"):
        params.update()
    roomy = _volume(maps=[("peel", {"angle": 10.0, "hinge": 1.0, "height": 0.5})], bounds=3.0)
    _scene("volpath", roomy)
    params = mi.traverse(roomy)
    params["map0_angle"] = 80.0
    params.update()
    assert roomy.volume.chain.maps[0].params["angle"] == 80.0


@pytest.mark.parametrize("tilt", [20.0, 0.0])
def test_fast_paths_agree_with_the_slow_ones(variant, monkeypatch, tilt):
    """A Gaussian pull over one quadrant of the piggy bank (the map region is partial): the
    symbolic branches that skip D_k reads outside the box of its non-zero nodes and (for a
    tilted map, whose D has two world components) in its all-zero cells, the occupancy
    skipping, the shading branch and the shading's reuse of the density step's lookup change
    no bit against reading the D_k everywhere, twice per visible sample, and marching every
    slice."""
    from mi_displace.volume import slicer

    m = mi.ScalarTransform4f().translate([0.0, -0.5, 0.0]).rotate([1, 0, 0], tilt).scale([0.5, 0.5, 0.5])
    vol = _volume(maps=[("gaussian", {"amount": 0.6})], map0_to_world=m)
    dk = vol.volume.chain.sampled_maps()[0]
    assert (dk.nonzero is not None) == (tilt != 0)      # the flag grid only for the wider D read
    if tilt:
        assert 0 < np.array(dk.nonzero).mean() < 1
    p = np.random.default_rng(3).uniform(-0.6, 0.6, (20000, 3))
    fast = vol.volume.chain.approximate(_points(p), True)
    u = np.array(dk._coords(_points(p)))
    box = ((u >= dk.read_box[0][:, None]) & (u < dk.read_box[1][:, None])).all(axis=0)
    assert 0.1 < box.mean() < 0.9                                      # lanes both sides of the box
    d = np.array(fast.p) - np.array(_points(p))
    assert 0 < (box & (np.abs(d).max(axis=0) == 0)).sum() < box.sum()  # zero D inside it too
    assert (np.abs(d).max(axis=0)[~box] == 0).all()
    colour = mi.load_dict({"type": "displaced_volume", "output": "albedo", "source": vol,
                           "albedo_low": [0.9, 0.2, 0.1], "albedo_high": [0.1, 0.3, 0.9]})
    props = ({"model": "scatter"}, {"model": "surface", "normals": "jacobian"}, {"model": "surface", "normals": "blend"},
             {"model": "surface", "normals": "gradient"}, {"model": "scatter", "albedo": colour})
    images = [_render(_scene("volume_slicer", vol, **kw)) for kw in props]
    monkeypatch.setattr(dk, "nonzero", None)                           # read the D_k everywhere
    monkeypatch.setattr(dk, "read_box", None)
    slow = vol.volume.chain.approximate(_points(p), True)
    for a, b in ((fast.p, slow.p), (fast.B, slow.B), (fast.galpha, slow.galpha)):
        assert np.array_equal(np.array(a), np.array(b))
    assert np.array_equal(np.array(fast.alpha), np.array(slow.alpha))
    everywhere = lambda v, s, lo, hi: (np.array([1, 1, 1]), mi.Float([0.0]))   # one occupied cell
    monkeypatch.setattr(slicer, "occupancy", everywhere)
    for kw, img in zip(props, images):                                  # shading reads the D_k again
        again = _render(_scene("volume_slicer", vol, reuse_lookup=False, **kw))
        assert img.max() > 0 and np.array_equal(img, again), kw


def test_volume_methods_in_a_trace_run_with_the_collector_paused(variant, monkeypatch):
    """volpath's medium calls are vectorised: Dr.Jit traces every live medium, holding plain
    pointers, and the heterogeneous medium calls the Python volume (sigma_t and albedo) inside
    that trace.  Python's collector, started by an allocation there, could free a dropped
    scene's medium before its turn (plugins/_guard.py); the volume's methods see it off, and
    it is on again after the render."""
    import gc

    vol = _volume(maps=[("gaussian", {"amount": 0.3})])
    colour = mi.load_dict({"type": "displaced_volume", "output": "albedo", "source": vol,
                           "albedo_low": [0.9, 0.2, 0.1], "albedo_high": [0.1, 0.3, 0.9]})
    seen = {"sigma_t": [], "albedo": []}

    def probe(name, method):
        def noted(*args, **kwargs):
            seen[name].append(gc.isenabled())
            return method(*args, **kwargs)
        return noted

    monkeypatch.setattr(vol.volume, "sigma_t", probe("sigma_t", vol.volume.sigma_t))
    monkeypatch.setattr(colour.albedo, "albedo", probe("albedo", colour.albedo.albedo))
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "volpath", "max_depth": 2},
        "sun": {"type": "directional", "direction": [-0.5, 0.6, -1], "irradiance": {"type": "rgb", "value": 6.0}},
        "sensor": {"type": "perspective", "fov": 30.0, "film": {"type": "hdrfilm", "width": 8, "height": 8},
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0.9, -2.3, 1.3], target=[0, 0, 0], up=[0, 0, 1])},
        "proxy": {"type": "volume_proxy", "volume": vol, "bsdf": {"type": "null"},
                  "interior": {"type": "heterogeneous", "sigma_t": vol, "albedo": colour}}})
    assert gc.isenabled()
    img = _render(scene, spp=4)
    assert img.max() > 0
    for name, calls in seen.items():
        assert calls and not any(calls), (name, calls)
    assert gc.isenabled()


def test_a_camera_move_compiles_no_new_kernel(variant):
    """The view enters the slicer's kernels as parameters: after two views, the first one
    turned by a hair more launches only kernels Dr.Jit has compiled."""
    from mi_displace.bench import frames
    from mi_displace.core.resources import scene_path
    from mi_displace.render.scene import load

    scene, _ = load(scene_path("volume_nucleon_pull.xml"), mode="approximation",
                    integrator="volume_slicer", res=24)
    # degrees; the hair is new to each run: a view traced as constants would otherwise find
    # an earlier run's kernels in Dr.Jit's on-disk cache
    angles = np.array([5.0, 6.0, 5.0 + np.random.default_rng().uniform(1e-3, 2e-3)])
    profile, moved, images = frames.camera_move_profile(scene, angles, lambda: _render(scene, spp=1))
    assert moved                      # other float32 numbers in the camera's transform
    assert all(np.isfinite(img).all() for img in images)
    assert profile["kernels"] > 3
    assert profile["cache_misses"] == 0, profile


def test_majorant_is_the_tight_bound_of_sigma_t(variant):
    # density_scale * tau(largest voxel), raised by only 1e-5 relative (field docstring)
    v = _ball_volume(tf_low=0.2, tf_high=0.8, density_scale=7.0)
    pts = _points(np.random.default_rng(4).uniform(-0.3, 0.3, (20000, 3)))
    top = np.array(v.sigma_t(pts)).max()
    assert top == pytest.approx(7.0, rel=1e-5)          # the core reaches tau = 1
    assert top <= v.majorant() <= 7.0 * (1 + 1.5e-5)
    assert v.nbytes() == {"object": v.obj.nbytes(), "maps": 0}


def test_parameter_edges_and_messages(variant):
    from mi_displace.volume import maps
    from mi_displace.volume.displacement import PlacedMap
    from mi_displace.volume.field import AlbedoField

    q = maps.check_params("gaussian", {"amount": 0.0})          # |amount| < 1 includes 0
    d, a = maps.evaluate("gaussian", q, _points([[0.5, 0.5, 0.5]]))
    assert np.abs(_np(d)).max() == 0
    assert maps.check_params("wave", {"amount": 0.9})["amount"] == 0.9   # the seam's bound is the seam's
    with pytest.raises(ValueError) as e:
        PlacedMap("wave", resolution=(1, 8, 8))
    assert str(e.value).startswith("wave resolution: ")
    v = _ball_volume()
    for bad in ([1.5, 0, 0], [-0.1, 0.5, 0.5], [np.nan, 0, 0]):
        with pytest.raises(ValueError) as e:
            AlbedoField(v, bad, [1, 1, 1])
        assert str(e.value) == f"albedo_low: an RGB albedo needs three values in [0, 1], got {np.asarray(bad, float)}"
    from mi_displace.volume.field import DisplacedVolume

    with pytest.raises(ValueError) as e:
        DisplacedVolume(v.obj, v.chain, tf_low=0.5, tf_high=0.5)
    assert str(e.value) == "tf_low/tf_high: need finite tf_low < tf_high, got 0.5, 0.5"
