"""The torus scene in every mode, and the measured Table 1 (masks, FLIP per method)."""
import numpy as np
import pytest

from mi_displace.render import scene as scenes
from mi_displace.vdm import methods

SCENE = "scenes/vdm_torus.xml"
SMALL = {"res": "48", "resolution": "384", "vdm_res": "32", "coarse": "48"}


@pytest.mark.parametrize("mode", ["reference", "approximation", "bump", "horizon", "relief", "base"])
def test_every_mode_loads_and_renders(variant, mode):
    scene, timings = scenes.load(SCENE, **methods.params_for(mode, SMALL), mode=mode,
                                 integrator="raster")
    image, _ = scenes.render(scene)
    assert np.all(np.isfinite(image)) and image.mean() > 0.01


@pytest.mark.slow
def test_methods_table_masks_and_ordering(variant):
    # shadows cover few pixels: at 48 px they are too small to rank the methods
    result = methods.methods_table(SCENE, dict(SMALL, res="128", resolution="1024",
                                               vdm_res="64"), repeats=1)
    rows = {r["method"]: r for r in result["rows"]}
    for name in ("silhouette", "shadow", "occlusion"):
        assert result["mask_pixels"][name] > 0, name
    # only VDM models silhouettes: it must beat every method without them there
    for other in ("bump", "horizon", "relief"):
        assert rows["approximation"]["flip_silhouette"] < rows[other]["flip_silhouette"], other
    # methods with self-shadows and parallax beat bump mapping inside the shadow mask
    # (horizon mapping's shadows land without parallax: not reliably better at low res)
    for shadowing in ("relief", "approximation"):
        assert rows[shadowing]["flip_shadow"] < rows["bump"]["flip_shadow"], shadowing
    assert rows["approximation"]["memory_bytes"] > 0 and rows["relief"]["memory_bytes"] == 0
    assert "| VDM |" in methods.markdown(result["rows"])
