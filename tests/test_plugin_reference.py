"""The typed property declarations: one source for reading and for docs/plugins.md."""
import re

import mitsuba as mi
import numpy as np
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
    """The reference's example, in a scene with a camera and sky light (an integrator's
    example replaces the default one)."""
    xml = _scene_xml(spec.example)
    if spec.kind == "integrator":
        xml = xml.replace('<integrator type="path"/>', "", 1)
    img = np.asarray(mi.render(mi.load_string(xml), spp=1))
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


def _scene_xml(body: str) -> str:
    return f"""<scene version="3.0.0">
  <integrator type="path"/>
  <emitter type="constant"/>
  <sensor type="perspective" id="camera"><transform name="to_world"><lookat origin="0, -4, 2"
    target="0, 0, 0" up="0, 0, 1"/></transform><film type="hdrfilm"><integer name="width" value="8"/>
    <integer name="height" value="8"/></film></sensor>
  {body}
</scene>"""


def _with_property(spec, xml: str) -> str:
    """The example with ``xml`` (a property) added to the plugin's own element."""
    pattern = re.compile(rf'<(\w+)( type="{spec.plugin}"[^>]*?)(/?)>')
    assert pattern.search(spec.example), spec.plugin

    def add(m):   # <tag type=...> gets xml first; a self-closing one is opened and closed
        return f"<{m.group(1)}{m.group(2)}>{xml}" + (f"</{m.group(1)}>" if m.group(3) else "")
    return pattern.sub(add, spec.example, count=1)


@pytest.mark.parametrize("spec", _specs(), ids=lambda s: s.plugin)
def test_every_declared_parameter_is_checked_by_name(variant, spec):
    """Each declared parameter refuses a wrong type or range with a one-line error naming
    the plugin and the parameter; through the plugin itself, before it builds anything."""
    checked = 0
    for param in spec.all_params():
        for value, words in _bad_values(param):
            with pytest.raises(ValueError) as caught:
                param.convert(spec.plugin, value)
            assert str(caught.value).startswith(f"{spec.plugin}: parameter '{param.name}'")
            assert words in str(caught.value) and "\n" not in str(caught.value)
            checked += 1
    assert checked >= len([p for p in spec.all_params() if p.type in ("float", "int")])
    # end to end: the plugin reads through its declaration (an out-of-range number not in
    # the example, added to the plugin's element)
    absent = [p for p in spec.all_params() if p.type in ("float", "int") and p.low is not None
              and f'name="{p.name}"' not in spec.example]
    for param in absent[:2]:
        tag = "integer" if param.type == "int" else "float"
        xml = _with_property(spec, f'<{tag} name="{param.name}" value="{int(param.low) - 1}"/>')
        with pytest.raises(Exception, match=f"{spec.plugin}: parameter '{param.name}' must lie in"):
            mi.load_string(_scene_xml(xml))


@pytest.mark.parametrize("spec", _specs(), ids=lambda s: s.plugin)
def test_a_misspelt_parameter_is_still_refused_by_mitsuba(variant, spec):
    xml = _with_property(spec, '<float name="depht" value="0.1"/>')
    with pytest.raises(Exception, match="depht"):
        mi.load_string(_scene_xml(xml))


def test_required_parameters_are_named(variant):
    for spec in _specs():
        for param in spec.all_params():
            if param.default is REQUIRED:
                with pytest.raises(ValueError, match=f"{spec.plugin}: parameter '{param.name}' is required"):
                    spec.read(mi.Properties(spec.plugin))
                break
