"""mi_displace.render.scene: load with timings and build stats, render in passes."""
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.render import scene as scenes

CONSTANT_SCENE = """<scene version="3.0.0">
    <default name="spp" value="4"/>
    <integrator type="path"/>
    <sensor type="perspective">
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="8"/><integer name="height" value="6"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <emitter type="constant"><rgb name="radiance" value="0.25, 0.5, 0.75"/></emitter>
    {shape}
</scene>"""


# a lit sphere in front of the camera: every pass of a few spp gives a different noisy image
NOISY_SHAPE = """<shape type="sphere"><point name="center" x="0" y="0" z="3"/>
        <float name="radius" value="0.8"/></shape>
    <emitter type="point"><point name="position" x="1" y="1" z="0"/><rgb name="intensity" value="5"/></emitter>"""


def _write(tmp_path, shape="", name="scene.xml"):
    path = tmp_path / name
    path.write_text(CONSTANT_SCENE.format(shape=shape))
    return path


def test_render_in_uneven_passes_weights_them_by_spp(variant, tmp_path, monkeypatch):
    scene, timings = scenes.load(_write(tmp_path), spp=3)
    assert timings["spp"] == 3 and timings["build_s"] > 0 and timings["shapes"] == []
    # 8 x 6 pixels, 2 spp per pass: 7 spp render as passes of 2, 2, 2, 1
    monkeypatch.setattr(scenes, "MAX_SAMPLES_PER_PASS", 8 * 6 * 2)
    image, seconds = scenes.render(scene, spp=7, seed=5)
    assert image.shape == (6, 8, 3) and image.dtype == np.float32 and seconds > 0
    np.testing.assert_allclose(image, np.broadcast_to([0.25, 0.5, 0.75], image.shape), rtol=1e-6)


def test_uneven_passes_of_a_noisy_image_are_weighted_by_their_spp(variant, tmp_path, monkeypatch):
    """Passes of 2, 2, 2 and 1 spp: the result is sum_k (spp_k / 7) image_k, each image_k
    rendered directly with its pass seed.  The passes differ (pixel noise), so an unweighted
    mean of the passes (or one dropped pass) fails."""
    scene, _ = scenes.load(_write(tmp_path, NOISY_SHAPE), spp=7)
    monkeypatch.setattr(scenes, "MAX_SAMPLES_PER_PASS", 8 * 6 * 2)
    image, _ = scenes.render(scene, spp=7, seed=5)
    passes = [np.asarray(mi.render(scene, spp=count, seed=scenes._pass_seed(5, k)))[..., :3]
              for k, count in enumerate((2, 2, 2, 1))]
    weighted = sum(p * (count / 7) for p, count in zip(passes, (2, 2, 2, 1)))
    np.testing.assert_allclose(image, weighted, rtol=1e-5, atol=1e-6)
    unweighted = sum(passes) / 4
    assert np.abs(unweighted - weighted).max() > 100 * np.abs(image - weighted).max() + 1e-3


def test_pass_seeds_are_distinct():
    seeds = {scenes._pass_seed(s, k) for s in range(50) for k in range(50)}
    assert len(seeds) == 2500
    assert scenes._pass_seed(7, 0) == 7


def test_build_stats_of_python_shapes_are_collected(variant, tmp_path):
    class Tri(mi.Mesh):
        def __init__(self, props):
            super().__init__("tri", 3, 1, props)
            params = mi.traverse(self)
            params["vertex_positions"] = mi.Float([0, 0, 1, 1, 0, 1, 0, 1, 1])
            params["faces"] = mi.UInt32([0, 1, 2])
            params.update()
            self.build_stats = {"vertices": 3, "faces": 1}

    mi.register_shape("test_stats_tri", lambda props: Tri(props))
    _, timings = scenes.load(_write(tmp_path, '<shape type="test_stats_tri" id="t"/>'
                                              '<shape type="sphere"/>'))
    assert timings["shapes"] == [{"id": "t", "type": "Tri", "vertices": 3, "faces": 1}]


def test_bad_input_is_reported_with_the_file(variant, tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.xml"):
        scenes.load(tmp_path / "nope.xml")
    path = _write(tmp_path)
    with pytest.raises(ValueError, match=r"scene.xml.*unused parameters.*\$foo=1"):
        scenes.load(path, foo=1)
    with pytest.raises(ValueError, match=r'could not parse integer value "x"'):
        scenes.load(path, spp="x")
    with pytest.raises(ValueError, match="parameter name"):
        scenes.load(path, **{"1bad": 2})

    def refuse(props):
        raise ValueError("refuse: parameter 'scale' must be finite")

    mi.register_shape("test_refuse", refuse)
    with pytest.raises(ValueError, match="refuse: parameter 'scale' must be finite"):
        scenes.load(_write(tmp_path, '<shape type="test_refuse"/>', "refuse.xml"))
    scene, _ = scenes.load(path)
    with pytest.raises(ValueError, match="spp"):
        scenes.render(scene, spp=0)


def test_compare_can_switch_raster_to_zbuffer_visibility(variant):
    """``-D approximation_integrator=raster_zbuffer`` picks scenes/integrators/raster_zbuffer.xml:
    the comparison's approximation side rasterises (the same image as ray-traced visibility,
    docs/raster.md), and the reference side keeps ``path``."""
    from pathlib import Path

    from mi_displace.evaluate.compare import protocol_settings

    path = Path(__file__).resolve().parents[2] / "scenes" / "ddm_thorns_sphere.xml"
    settings = protocol_settings(path, {"approximation_integrator": "raster_zbuffer"})
    assert settings["approximation_integrator"] == "raster_zbuffer"
    assert settings["reference_integrator"] == "path" and settings["xml_params"] == {}
    images = {}
    for integrator in ("raster", "raster_zbuffer"):
        scene, _ = scenes.load(path, mode="approximation", integrator=integrator, res=48)
        images[integrator] = np.asarray(mi.render(scene))
        assert np.all(np.isfinite(images[integrator]))
        assert scene.integrator().options.visibility == ("zbuffer" if integrator.endswith("zbuffer")
                                                         else "raytrace")
    assert images["raster"].mean() > 0.02
    differ = np.abs(images["raster_zbuffer"] - images["raster"]).max(axis=2) > 1e-3
    assert differ.mean() < 0.01, differ.mean()
