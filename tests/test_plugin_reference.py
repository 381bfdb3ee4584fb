"""The typed property declarations: one source for reading and for docs/plugins.md."""
import mitsuba as mi
import pytest

from mi_displace.core import reference
from mi_displace.core.properties import REQUIRED


def _specs():
    import mi_displace

    mi_displace.init("llvm_ad_rgb")
    return reference.declared_specs()


def test_reference_page_matches_the_declarations(variant):
    on_disk = reference.reference_path().read_text()
    assert on_disk == reference.markdown(_specs()), (
        "docs/plugins.md is stale: run python -m mi_displace.core.reference")


@pytest.mark.parametrize("spec", _specs(), ids=lambda s: s.plugin)
def test_each_example_loads_and_renders(variant, spec):
    scene = mi.load_string(f"""<scene version="3.0.0">
  <integrator type="path"/>
  <emitter type="constant"/>
  <sensor type="perspective"><transform name="to_world"><lookat origin="0, -4, 2" target="0, 0, 0"
    up="0, 0, 1"/></transform><film type="hdrfilm"><integer name="width" value="8"/>
    <integer name="height" value="8"/></film></sensor>
  {spec.example}
</scene>""")
    import numpy as np
    img = np.asarray(mi.render(scene, spp=1))
    assert np.isfinite(img).all() and img.mean() > 0


def _bad_values(param):
    """Values the declaration must refuse, each with the words of the error."""
    if param.type in ("float", "int"):
        out = [("big", "must be a number")]
        if param.low is not None:
            out.append((param.low - 1, "must lie in"))
        if param.high is not None:
            out.append((param.high + 1, "must lie in"))
        if param.type == "int":
            out.append((1.5 if param.low is None or param.low < 1.5 else param.low + 0.5, "integer"))
        return out
    if param.type == "bool":
        return [("maybe", "must be a boolean")]
    if param.type == "texture":
        return [(0.5, "must be a nested texture")]
    return []


@pytest.mark.parametrize("spec", _specs(), ids=lambda s: s.plugin)
def test_every_declared_number_is_checked_by_name(variant, spec):
    """Each declared parameter refuses a wrong type or range with a one-line error naming
    the plugin and the parameter, before the plugin builds anything."""
    base = {"type": spec.plugin, "height": {"type": "cells"}, "tile_size": 0.5}
    checked = 0
    for param in spec.all_params():
        for value, words in _bad_values(param):
            with pytest.raises(Exception) as caught:
                mi.load_dict(dict(base, **{param.name: value}))
            message = str(caught.value).splitlines()[-1]
            assert f"{spec.plugin}: parameter '{param.name}'" in message and words in message, message
            checked += 1
    assert checked >= len([p for p in spec.all_params() if p.type in ("float", "int")])


@pytest.mark.parametrize("spec", _specs(), ids=lambda s: s.plugin)
def test_a_misspelt_parameter_is_still_refused_by_mitsuba(variant, spec):
    with pytest.raises(Exception, match="depht"):
        mi.load_dict({"type": spec.plugin, "height": {"type": "cells"}, "tile_size": 0.5, "depht": 0.1})


def test_required_parameters_are_named(variant):
    for spec in _specs():
        for param in spec.all_params():
            if param.default is REQUIRED:
                with pytest.raises(Exception, match=f"{spec.plugin}: parameter '{param.name}' is required"):
                    mi.load_dict({"type": spec.plugin, "tile_size": 0.5})
