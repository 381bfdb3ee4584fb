"""``<volume type="displaced_volume">``: an object volume seen through discontinuous
displacement maps (:mod:`mi_displace.volume`), for ``sigma_t`` of a ``heterogeneous`` medium
under ``volpath`` and for the ``volume_slicer`` integrator.

.. code-block:: xml

    <volume type="displaced_volume" id="walnut">
        <string name="filename" value="../data/volumes/walnut_128x96x114_uint16.raw"/>  <!-- raw + .json, or .vol -->
        <!-- or <string name="procedural" value="piggy_bank"/> <integer name="resolution" value="96"/> -->
        <string name="mode" value="reference"/>          <!-- reference: exact maps | approximation: D_k -->
        <float name="tf_low" value="0.1"/> <float name="tf_high" value="0.6"/>
        <float name="density_scale" value="20"/>          <!-- sigma_t at tau = 1, 1/world unit -->
        <integer name="bits" value="16"/>                  <!-- D_k storage: 8, 16, 32 (float) -->
        <float name="smoothing" value="1.5"/>              <!-- alpha smoothing, D_k voxels -->
        <string name="composition" value="on_the_fly"/>    <!-- or precomputed -->
        <integer name="composite_resolution" value="64"/>
        <float name="bounds" value="1.0"/>                  <!-- optional: medium box >= [-b, b]^3 (animation) -->
        <string name="map0_type" value="peel"/>            <!-- maps in forward order: map0, map1, ... -->
        <float name="map0_angle" value="60"/>              <!-- any parameter of the primitive -->
        <integer name="map0_resolution" value="64"/>       <!-- or map0_res_x/_y/_z -->
        <transform name="map0_to_world"> ... </transform>  <!-- placement M of §6 -->
    </volume>

    <!-- the albedo of the same displaced object: a colour transfer read at the same pre-image -->
    <volume type="displaced_volume" id="walnut_albedo">
        <string name="output" value="albedo"/>            <!-- sigma_t (default) | albedo -->
        <ref name="source" id="walnut"/>                   <!-- share its object, maps, mode -->
        <rgb name="albedo_low" value="0.8, 0.5, 0.3"/>     <!-- albedo where F <= albedo_range_low -->
        <rgb name="albedo_high" value="0.9, 0.85, 0.7"/>   <!-- ... where F >= albedo_range_high -->
        <float name="albedo_range_low" value="0.1"/> <float name="albedo_range_high" value="0.6"/>
        <!-- F: the object itself, or a second field: albedo_filename / albedo_procedural -->
    </volume>

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

from mi_displace.volume import maps as primitives
from mi_displace.volume.displacement import DisplacementChain, PlacedMap
from mi_displace.volume.field import AlbedoField, DisplacedVolume
from mi_displace.volume.objects import load_raw, load_vol, piggy_bank
from mi_displace.core.collector import collector_paused
from mi_displace.plugins._guard import constructor

MAX_MAPS = 32
OUTPUTS = ("sigma_t", "albedo")


def _object(props, prefix=""):
    """The object volume from ``{prefix}filename`` or ``{prefix}procedural`` (+ ``resolution``)."""
    filename = props.get(f"{prefix}filename", None)
    procedural = props.get(f"{prefix}procedural", None)
    if (filename is None) == (procedural is None):
        raise ValueError(f"displaced_volume: give exactly one of '{prefix}filename' (.raw + .json sidecar, "
                         f"or Mitsuba .vol) and '{prefix}procedural' ('piggy_bank')")
    if procedural is not None:
        if procedural != "piggy_bank":
            raise ValueError(f"displaced_volume: {prefix}procedural {procedural!r} is unknown (piggy_bank)")
        return piggy_bank(int(props.get(f"{prefix}resolution", 96)))
    path = str(mi.file_resolver().resolve(filename))
    return load_vol(path) if path.endswith(".vol") else load_raw(path)


def _volume(props) -> DisplacedVolume:
    """The object and its displacement chain from the properties (module docstring)."""
    chain = DisplacementChain(
        _maps(props), bits=int(props.get("bits", 16)), smoothing=float(props.get("smoothing", 1.5)),
        composition=props.get("composition", "on_the_fly"),
        composite_resolution=[int(props.get("composite_resolution", 64))] * 3)
    return DisplacedVolume(
        _object(props), chain, mode=props.get("mode", "reference"), tf_low=float(props.get("tf_low", 0.1)),
        tf_high=float(props.get("tf_high", 0.6)), density_scale=float(props.get("density_scale", 20.0)))


def _medium_box(props, volume: DisplacedVolume) -> tuple[np.ndarray, np.ndarray]:
    """The proxy box, grown to [-bounds, bounds]^3 when ``bounds`` is given."""
    lo, hi = volume.proxy_box()
    bounds = props.get("bounds", None)
    if bounds is not None:
        if not float(bounds) > 0:
            raise ValueError(f"displaced_volume: 'bounds' must be > 0, got {bounds}")
        lo, hi = np.minimum(lo, -float(bounds)), np.maximum(hi, float(bounds))
    return lo, hi


def _maps(props) -> list[PlacedMap]:
    out = []
    for i in range(MAX_MAPS + 1):
        key = f"map{i}_type"
        if not (key in props):
            break
        if i == MAX_MAPS:
            raise ValueError(f"displaced_volume: at most {MAX_MAPS} maps")
        kind = props.get(key)
        if kind not in primitives.PRIMITIVES:
            raise ValueError(f"displaced_volume: {key} {kind!r} is not one of {', '.join(primitives.PRIMITIVES)}")
        params = {name: props.get(f"map{i}_{name}") for name in primitives.PRIMITIVES[kind]
                  if (f"map{i}_{name}" in props)}
        res = list(primitives.DEFAULT_RESOLUTION[kind])
        if (f"map{i}_resolution" in props):
            res = [int(props.get(f"map{i}_resolution"))] * 3
        for a, axis in enumerate("xyz"):
            if (f"map{i}_res_{axis}" in props):
                res[a] = int(props.get(f"map{i}_res_{axis}"))
        to_world = None
        if (f"map{i}_to_world" in props):
            to_world = np.array(props.get(f"map{i}_to_world").matrix, dtype=float).reshape(4, 4)
        out.append(PlacedMap(kind, params, to_world, res))
    return out


def _rgb(props, key, default):
    """An RGB property (``<rgb>`` or a grey ``<float>``) as a (3,) array."""
    if not (key in props):
        return np.asarray(default, float)
    value = props.get(key)
    if isinstance(value, (int, float)):
        return np.full(3, float(value))
    return np.array(tuple(mi.ScalarColor3f(value)), float)


def _albedo(props, volume: DisplacedVolume) -> AlbedoField:
    """The colour transfer of ``output="albedo"`` (see :class:`AlbedoField`)."""
    field = None
    if ("albedo_filename" in props) or ("albedo_procedural" in props):
        field = _object(props, prefix="albedo_")
    value_range = None
    if ("albedo_range_low" in props) or ("albedo_range_high" in props):
        value_range = (float(props.get("albedo_range_low", volume.tf_low)),
                       float(props.get("albedo_range_high", volume.tf_high)))
    return AlbedoField(volume, _rgb(props, "albedo_low", (0.8, 0.8, 0.8)), _rgb(props, "albedo_high", (0.8, 0.8, 0.8)),
                       value_range, field)


class DisplacedVolumePlugin(mi.Volume):
    """sigma_t (or the albedo) of the displaced object (see the module docstring)."""

    def __init__(self, props: mi.Properties):
        if "to_world" in props:   # it would be overwritten below by the medium box: refuse it
            raise ValueError("displaced_volume: parameter 'to_world' is not supported: the object "
                             "fills its own box (raw: centred, longest side 1 world unit; .vol: its "
                             "header's box; docs/volume.md, Conventions); place the maps with "
                             "map<i>_to_world and move the camera, not the object")
        self.output = props.get("output", "sigma_t")
        if self.output not in OUTPUTS:
            raise ValueError(f"displaced_volume: output must be one of {OUTPUTS}, got {self.output!r}")
        source = props.get("source", None)
        if source is not None:
            if getattr(source, "output", None) != "sigma_t":
                raise ValueError("displaced_volume: 'source' must reference a displaced_volume with "
                                 "output=\"sigma_t\" (whose object, maps and mode this one shares)")
            if self.output != "albedo":
                raise ValueError("displaced_volume: 'source' is for output=\"albedo\" only")
            volume, (lo, hi) = source.volume, source._box
        else:
            volume = _volume(props)
            lo, hi = _medium_box(props, volume)
        self.albedo = _albedo(props, volume) if self.output == "albedo" else None
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
    mi.register_texture("displaced_volume", constructor("displaced_volume", DisplacedVolumePlugin))
