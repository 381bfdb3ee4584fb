"""Parameters of the VDM-family plugins (issue 15): misspelt names are Mitsuba errors."""
import mitsuba as mi
import pytest

TABLE = {"res": 8, "theta": 4, "phi": 4, "curvatures": 1, "svd_terms": 2, "mvm_terms": 2}


def _bsdf(plugin, **extra):
    d = {"type": plugin, "height": {"type": "cells"}, "depth": 0.05}
    if plugin == "vdm":
        d.update(TABLE)
    d.update(extra)
    return d


@pytest.mark.parametrize("plugin,typo", [("vdm", "svd_term"), ("vdm", "dpeth"),
                                         ("vdm", "shadow_veriffy"), ("horizon", "azimuth"),
                                         ("relief", "shadow_step"), ("relief", "tilling")])
def test_misspelt_bsdf_parameter_is_refused(variant, plugin, typo):
    with pytest.raises(Exception, match=f"(?s)unreferenced property.*{typo}"):
        mi.load_dict({"type": "vdm_mesh", "base": "plane", "resolution": 2,
                      "bsdf": _bsdf(plugin, **{typo: 3})})
    # spelt right, the same scene loads
    mi.load_dict({"type": "vdm_mesh", "base": "plane", "resolution": 2, "bsdf": _bsdf(plugin)})


def test_misspelt_vdm_mesh_parameter_is_refused(variant):
    with pytest.raises(Exception, match="(?s)unreferenced property.*resolutoin"):
        mi.load_dict({"type": "vdm_mesh", "base": "plane", "resolutoin": 2,
                      "bsdf": _bsdf("relief")})
