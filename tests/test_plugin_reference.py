"""The typed property declarations: one source for reading and for docs/plugins.md."""
import re

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.bake.mitsuba_frames import prepare_scene
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
    scene = mi.load_string(xml)
    prepare_scene(scene)          # what our loader does after mi.load_* (mikk_normalmap)
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


def test_every_registered_plugin_is_declared(variant, monkeypatch):
    """Each plugin module declares its plugins (``SPEC``, or ``SPECS`` for several) and
    registers nothing that its declarations do not describe."""
    import importlib

    from mi_displace.core.properties import PluginSpec
    from mi_displace.plugins import PLUGIN_MODULES

    _specs()
    for name in PLUGIN_MODULES:
        module = importlib.import_module(name)
        specs = getattr(module, "SPECS", None) or (getattr(module, "SPEC", None),)
        assert all(isinstance(s, PluginSpec) for s in specs), f"{name} declares no SPEC"
        registered = []
        for kind in ("shape", "bsdf", "texture", "integrator"):
            monkeypatch.setattr(mi, f"register_{kind}", lambda plugin, make: registered.append(plugin))
        module.register()
        assert registered and set(registered) <= {s.plugin for s in specs}, (name, registered)
    assert len({s.plugin for s in _specs()}) == len(_specs())


def test_a_parameter_family_is_read_by_index(variant):
    from mi_displace.core.properties import Param, PluginSpec

    spec = PluginSpec("p", "volume", "", (Param("map<i>_type", "string", None, "", choices=("a", "b")),
                                          Param("map<i>_<name>", "float", None, "", low=0)))
    props = mi.Properties("p")
    props["map0_type"], props["map1_type"], props["map1_size"] = "a", "b", 2
    assert spec.read(props) == {"map<i>_type": {0: "a", 1: "b"}, "map<i>_<name>": {(1, "size"): 2.0}}
    props["map0_size"] = -1.0
    with pytest.raises(ValueError, match=r"^p: parameter 'map0_size' must lie in \[0, inf\), got -1.0$"):
        spec.read(props)


PIGGY = {"type": "displaced_volume", "procedural": "piggy_bank", "resolution": 16, "map0_type": "peel"}


@pytest.mark.parametrize("scene, message", [
    ({**PIGGY, "map0_bogus": 1.0}, "displaced_volume: parameter 'map0_bogus' is not one of peel's"),
    ({**PIGGY, "map2_type": "wave"}, "displaced_volume: parameter 'map1_type' is missing"),
    ({**PIGGY, "map1_amount": 0.1}, "displaced_volume: parameter 'map1_amount' needs 'map1_type'"),
    ({"type": "displaced", "base": "torus", "radius": 2.0},
     "displaced: parameter 'radius' does not apply to base 'torus'"),
    ({"type": "ddm", "base": "plane", "filename": "tile.obj"},
     "ddm: parameter 'filename' applies to base 'mesh' or 'teapot' only"),
])
def test_family_and_base_parameters_are_named(variant, scene, message):
    """A parameter declared through a family or the shared base declaration, given where it
    does not belong, is one line naming it (not Mitsuba's "unreferenced property")."""
    with pytest.raises(Exception, match=re.escape(message)):
        mi.load_dict(scene)
