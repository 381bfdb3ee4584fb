"""``<volume type="displaced_volume">``: an object volume seen through discontinuous
displacement maps (:mod:`mi_displace.volume`), for ``sigma_t`` of a ``heterogeneous`` medium
under ``volpath`` and for the ``volume_slicer`` integrator.

(:data:`SPEC` declares its parameters.)

``output="albedo"`` makes it the ``albedo`` of a ``heterogeneous`` medium (and of the
``volume_slicer``): :class:`~mi_displace.volume.field.AlbedoField`.  With ``source`` it shares
the object, maps and mode of a sigma_t volume (edit the maps there); without, it takes its
own object and maps like a sigma_t volume.

The plugin is an ``mi.Volume``: Mitsuba 3.9.1 has no ``register_volume``, so it is registered
through ``mi.register_texture`` (the plugin manager checks the type of the object the
constructor returns, so ``<volume type=...>`` works).  It is not called ``displaced``: plugin
names share one registry, and that name is our displacement *shape*.

Editable through ``mi.traverse`` (the object textures are not rebuilt, only the edited map's
D_k): ``map{i}_{parameter}`` and ``map{i}_to_world``, named as in the XML (no dots: Mitsuba's
``SceneParameters.update`` reads a dot as a child object and would not notify the volume).
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np

from mi_displace.volume import EXAMPLE_XML, maps as primitives
from mi_displace.volume.displacement import BITS, DisplacementChain, PlacedMap
from mi_displace.volume.field import MODES, AlbedoField, DisplacedVolume
from mi_displace.volume.objects import load_raw, load_vol, piggy_bank
from mi_displace.core.collector import collector_paused
from mi_displace.core.properties import Param, PluginSpec
from mi_displace.plugins._guard import constructor

MAX_MAPS = 32
OUTPUTS = ("sigma_t", "albedo")
PROCEDURAL = ("piggy_bank",)
_GREY = (0.8, 0.8, 0.8)


def _object_params(prefix: str, what: str) -> tuple[Param, ...]:
    """The parameters of an object volume (``{prefix}filename`` etc.), ``what`` it is."""
    return (
        Param(f"{prefix}filename", "string", None, f"{what}: a .raw with its .json sidecar, or a "
              "Mitsuba .vol"),
        Param(f"{prefix}procedural", "string", None, f"{what}: a procedural object instead",
              choices=PROCEDURAL),
        Param(f"{prefix}resolution", "int", 96, f"{what}, procedural: voxels per side", low=8, high=512),
    )


SPEC = PluginSpec(
    "displaced_volume", "volume",
    "An object volume seen through discontinuous displacement maps (§6), for `sigma_t` (or, "
    "with `output=\"albedo\"`, the `albedo`) of a `heterogeneous` medium under `volpath`, and "
    "for the `volume_slicer` integrator.  The maps apply in forward order `map0`, `map1`, …; "
    "each sample reads the object at its pre-image, exactly (`reference`) or through the "
    "sampled inverse maps D_k (`approximation`).  Registered through `mi.register_texture` "
    "(Mitsuba has no `register_volume`); `<volume type=...>` works.",
    (
        Param("output", "string", "sigma_t", "what the volume evaluates", choices=OUTPUTS),
        Param("source", "volume", None, "output=albedo: a `displaced_volume` (sigma_t) whose "
              "object, maps and mode this one shares (`<ref>`)"),
        *_object_params("", "the object"),
        Param("mode", "string", "reference", "exact pre-images or the sampled D_k", choices=MODES),
        Param("tf_low", "float", 0.1, "transfer ramp start on the normalised density (< tf_high; "
              "tau(0) = 0 keeps empty space empty)", low=0, high=1, open_high=True),
        Param("tf_high", "float", 0.6, "transfer ramp end on the normalised density"),
        Param("density_scale", "float", 20.0, "sigma_t at tau = 1", unit="1/world", low=0,
              open_low=True),
        Param("bits", "int", 16, "D_k storage: 8, 16 or 32 (float)", low=min(BITS), high=max(BITS)),
        Param("smoothing", "float", 1.5, "alpha smoothing", unit="D_k voxels", low=0),
        Param("composition", "string", DisplacementChain.COMPOSITIONS[0], "compose the maps per "
              "lookup or once into one table", choices=DisplacementChain.COMPOSITIONS),
        Param("composite_resolution", "int", 64, "precomputed: composite table voxels per side",
              low=1, high=1024),
        Param("bounds", "float", None, "medium box at least [-bounds, bounds]³ (room for edits "
              "that grow the object)", unit="world", low=0, open_low=True),
        Param("albedo_low", "rgb", _GREY, "output=albedo: albedo where F <= albedo_range_low"),
        Param("albedo_high", "rgb", _GREY, "output=albedo: albedo where F >= albedo_range_high"),
        Param("albedo_range_low", "float", None, "output=albedo: F at albedo_low (default tf_low)"),
        Param("albedo_range_high", "float", None, "output=albedo: F at albedo_high (default tf_high)"),
        *_object_params("albedo_", "output=albedo: a second field F (default: the object)"),
        Param("map<i>_type", "string", None, "map i's primitive (i = 0, 1, … in forward order, "
              f"at most {MAX_MAPS})", choices=tuple(primitives.PRIMITIVES)),
        Param("map<i>_resolution", "int", None, "map i's D_k voxels per side (default: the "
              "primitive's)", low=1, high=4096),
        *(Param(f"map<i>_res_{axis}", "int", None, f"map i's D_k voxels along {axis}", low=1,
                high=4096) for axis in "xyz"),
        Param("map<i>_to_world", "transform", None, "map i's placement M (§6)", editable=True),
        Param("map<i>_<parameter>", "float", None, "a parameter of map i's primitive: "
              + "; ".join(f"{k}: {', '.join(v)}" for k, v in primitives.PRIMITIVES.items())
              + " (angles in degrees)", editable=True),
    ),
    example=EXAMPLE_XML,
    nested="`source`: a `<ref>` to a sigma_t `displaced_volume`",
    stats="texture_bytes, maps",
    limits="`to_world` is refused: the object fills its own box (raw: centred, longest side 1 "
           "world unit; .vol: its header's box); "
           "edits that grow the object past the medium box fixed at load are refused (give "
           "`bounds`).  Map parameters are editable, not differentiable.",
)


def _object(values: dict, prefix=""):
    """The object volume from ``{prefix}filename`` or ``{prefix}procedural`` (+ ``resolution``)."""
    filename, procedural = values[f"{prefix}filename"], values[f"{prefix}procedural"]
    if (filename is None) == (procedural is None):
        raise ValueError(f"displaced_volume: give exactly one of '{prefix}filename' (.raw + .json sidecar, "
                         f"or Mitsuba .vol) and '{prefix}procedural' ('piggy_bank')")
    if procedural is not None:
        return piggy_bank(values[f"{prefix}resolution"])
    path = str(mi.file_resolver().resolve(filename))
    return load_vol(path) if path.endswith(".vol") else load_raw(path)


def _volume(values: dict) -> DisplacedVolume:
    """The object and its displacement chain from the read values (module docstring)."""
    chain = DisplacementChain(
        _maps(values), bits=values["bits"], smoothing=values["smoothing"],
        composition=values["composition"],
        composite_resolution=[values["composite_resolution"]] * 3)
    return DisplacedVolume(
        _object(values), chain, mode=values["mode"], tf_low=values["tf_low"],
        tf_high=values["tf_high"], density_scale=values["density_scale"])


def _medium_box(values: dict, volume: DisplacedVolume) -> tuple[np.ndarray, np.ndarray]:
    """The proxy box, grown to [-bounds, bounds]^3 when ``bounds`` is given."""
    lo, hi = volume.proxy_box()
    bounds = values["bounds"]
    if bounds is not None:
        lo, hi = np.minimum(lo, -bounds), np.maximum(hi, bounds)
    return lo, hi


def _maps(values: dict) -> list[PlacedMap]:
    """The maps ``map0``, ``map1``, … of the read values, checked to be consecutive, each with
    a type, and with parameters of that type only."""
    kinds = values["map<i>_type"]
    count = len(kinds)
    if count > MAX_MAPS:
        raise ValueError(f"displaced_volume: at most {MAX_MAPS} maps, got {count}")
    if sorted(kinds) != list(range(count)):
        missing = min(set(range(count + 1)) - set(kinds))
        raise ValueError(f"displaced_volume: parameter 'map{missing}_type' is missing (maps are "
                         f"numbered 0, 1, … without gaps; given: {sorted(kinds)})")
    params = values["map<i>_<parameter>"]
    for family in (name for name in values if name.startswith("map<i>_") and name != "map<i>_type"):
        for index in values[family]:
            i, rest = index if isinstance(index, tuple) else (index, family.removeprefix("map<i>_"))
            if i not in kinds:
                raise ValueError(f"displaced_volume: parameter 'map{i}_{rest}' needs 'map{i}_type'")
            if isinstance(index, tuple) and rest not in primitives.PRIMITIVES[kinds[i]]:
                raise ValueError(f"displaced_volume: parameter 'map{i}_{rest}' is not one of "
                                 f"{kinds[i]}'s ({', '.join(primitives.PRIMITIVES[kinds[i]])})")
    out = []
    for i in range(count):
        kind = kinds[i]
        res = list(primitives.DEFAULT_RESOLUTION[kind])
        if i in values["map<i>_resolution"]:
            res = [values["map<i>_resolution"][i]] * 3
        for a, axis in enumerate("xyz"):
            res[a] = values[f"map<i>_res_{axis}"].get(i, res[a])
        to_world = values["map<i>_to_world"].get(i)
        if to_world is not None:
            to_world = np.array(to_world.matrix, dtype=float).reshape(4, 4)
        out.append(PlacedMap(kind, {name: v for (j, name), v in params.items() if j == i},
                             to_world, res))
    return out


def _albedo(values: dict, volume: DisplacedVolume) -> AlbedoField:
    """The colour transfer of ``output="albedo"`` (see :class:`AlbedoField`)."""
    field = None
    if values["albedo_filename"] is not None or values["albedo_procedural"] is not None:
        field = _object(values, prefix="albedo_")
    value_range = None
    low, high = values["albedo_range_low"], values["albedo_range_high"]
    if low is not None or high is not None:
        value_range = (volume.tf_low if low is None else low, volume.tf_high if high is None else high)
    return AlbedoField(volume, np.array(values["albedo_low"]), np.array(values["albedo_high"]),
                       value_range, field)


class DisplacedVolumePlugin(mi.Volume):
    """sigma_t (or the albedo) of the displaced object (see the module docstring)."""

    def __init__(self, props: mi.Properties, values: dict):
        if "to_world" in props:   # it would be overwritten below by the medium box: refuse it
            raise ValueError("displaced_volume: parameter 'to_world' is not supported: the object "
                             "fills its own box (raw: centred, longest side 1 world unit; .vol: its "
                             "header's box; docs/volume.md, Conventions); place the maps with "
                             "map<i>_to_world and move the camera, not the object")
        self.output = values["output"]
        source = values["source"]
        if source is not None:
            if getattr(source, "output", None) != "sigma_t":
                raise ValueError("displaced_volume: 'source' must reference a displaced_volume with "
                                 "output=\"sigma_t\" (whose object, maps and mode this one shares)")
            if self.output != "albedo":
                raise ValueError("displaced_volume: 'source' is for output=\"albedo\" only")
            volume, (lo, hi) = source.volume, source._box
        else:
            volume = _volume(values)
            lo, hi = _medium_box(values, volume)
        self.albedo = _albedo(values, volume) if self.output == "albedo" else None
        # Mitsuba's media clip sampling to the C++ bbox of the volume (its to_world applied to
        # the unit cube), not to a Python bbox() override: set it to the proxy box
        props["to_world"] = mi.ScalarTransform4f().translate(mi.ScalarPoint3f(lo)).scale(
            mi.ScalarVector3f(hi - lo))
        super().__init__(props)
        self.volume, self.source = volume, source
        self._box = (lo, hi)
        self._refresh()

    def _refresh(self):
        self.volume.prepare()
        if self.albedo is not None:
            self.albedo.prepare()
        lo, hi = self.volume.proxy_box()
        grown = (lo < self._box[0] - 1e-6).any() or (hi > self._box[1] + 1e-6).any()
        if grown and getattr(self, "in_medium", False):  # set by volume_proxy; slicing needs no box
            raise ValueError(f"displaced_volume: the displaced object now reaches {lo}..{hi}, outside "
                             f"the medium box {self._box[0]}..{self._box[1]} fixed at load time; "
                             "give a larger 'bounds'")
        self._bbox = mi.ScalarBoundingBox3f(mi.ScalarPoint3f(lo), mi.ScalarPoint3f(hi))
        self._max = self.volume.majorant()
        self.build_stats = {"texture_bytes": self.volume.nbytes(), "maps": len(self.volume.chain.maps)}

    def medium_box(self) -> tuple[np.ndarray, np.ndarray]:
        """The box Mitsuba clips this volume to (fixed at load time; see ``bounds``).  Asking
        for it (``volume_proxy`` does) marks the volume as a medium's, so that an edit that
        grows the displaced object past the box is refused."""
        self.in_medium = True
        return self._box

    # eval / eval_1 run inside the trace of volpath's vectorised medium calls, which holds
    # every live medium through plain pointers: the collector stays off (plugins/_guard.py)
    @collector_paused
    def eval(self, it, active=True):
        if self.albedo is not None:
            return self.albedo.albedo(it.p)
        return mi.Color3f(self.volume.sigma_t(it.p))

    @collector_paused
    def eval_1(self, it, active=True):
        """sigma_t, or the mean of the albedo's channels."""
        if self.albedo is not None:
            c = self.albedo.albedo(it.p)
            return (c[0] + c[1] + c[2]) / 3.0
        return self.volume.sigma_t(it.p)

    def max(self):
        return self.albedo.max() if self.albedo is not None else self._max

    def bbox(self):
        return self._bbox

    def traverse(self, callback):
        """The maps' parameters (none when they belong to a ``source`` volume: edit them there)."""
        self._editable = {}
        for i, m in enumerate([] if self.source is not None else self.volume.chain.maps):
            for name, value in m.params.items():
                self._editable[f"map{i}_{name}"] = mi.Float(value)
            self._editable[f"map{i}_to_world"] = mi.Transform4f(m.placement.matrix)
        for key, value in self._editable.items():
            callback.put(key, value, mi.ParamFlags.NonDifferentiable)

    def parameters_changed(self, keys=[]):
        """Re-sample only the D_k of the edited maps (the object textures stay)."""
        for i, m in enumerate(self.volume.chain.maps):
            prefix = f"map{i}_"
            mine = [k for k in keys if k.startswith(prefix)]
            if not mine:
                continue
            params = {k[len(prefix):]: float(self._editable[k][0]) for k in mine
                      if k != f"{prefix}to_world"}
            to_world = None
            if f"{prefix}to_world" in mine:
                to_world = np.array(self._editable[f"{prefix}to_world"].matrix, dtype=float).reshape(4, 4)
            m.set(params, to_world)
        self.volume.chain.changed()
        self._refresh()

    def to_string(self):
        c = self.volume.chain
        return (f"DisplacedVolume[{self.volume.obj.name}, output={self.output}, mode={self.volume.mode}, "
                f"maps={[m.kind for m in c.maps]}, bits={c.bits}, composition={c.composition}]")


def register():
    mi.register_texture("displaced_volume", constructor(SPEC, DisplacedVolumePlugin))
