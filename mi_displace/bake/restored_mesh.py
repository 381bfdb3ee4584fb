"""The mesh behind ``<shape type="restored">``: a low-poly restored with its baked map (§5).

:class:`RestoredSurface` is a plain Python object: it resolves and reads the map and the
low-poly, chooses the subdivision levels (given, or ``levels="auto"`` from the map
resolution and the projected size through the sensors, :mod:`mi_displace.bake.levels`),
restores the mesh (:func:`mi_displace.bake.restore.restore`) and re-displaces it when the
map's texels are edited (:class:`~mi_displace.bake.restore.DisplaceState`, keeping the AD
graph).  Every build comes back as :class:`~mi_displace.core.mesh_buffers.MeshBuffers` in
world space for the plugin (``mi_displace.plugins.restored``) to upload.
"""
from __future__ import annotations

import time

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake import formats
from mi_displace.bake.levels import auto_levels
from mi_displace.bake.meshdata import load_mesh
from mi_displace.bake.restore import edge_splits, low_for_map, restore
from mi_displace.core.mesh_buffers import MeshBuffers


class RestoredSurface:
    """Builds the restored mesh of one ``restored`` shape (object units of the low-poly
    inside, world units in the :class:`MeshBuffers`).

    Args:
        values: the plugin's declared values (``SPEC.read``): map, low, levels, split,
            dicing_rate, keep_holes.
        sensors: the sensors referenced in the shape (``levels="auto"``; may be empty).
        to_world: the shape's ``to_world`` (any Mitsuba transform).

    Raises:
        ValueError: naming ``levels`` / ``split`` (or the file) before any kernel runs.
    """

    def __init__(self, values: dict, sensors: list, to_world):
        self.sensors = list(sensors)
        resolver = mi.file_resolver()   # paths relative to the scene file
        self.map_path = str(resolver.resolve(values["map"]))
        low = (str(resolver.resolve(values["low"])) if values["low"] is not None
               else low_for_map(self.map_path))
        self.auto = values["levels"] == "auto"
        self.split = values["split"]
        self.dicing_rate = values["dicing_rate"]
        self.keep_holes = values["keep_holes"]
        self.low = load_mesh(low, "low-poly")
        metadata = formats.read_metadata(self.map_path)
        self.map_shape = (int(metadata["height"]), int(metadata["width"]))
        self.to_world = np.array(to_world.matrix, dtype=np.float64)
        if self.auto:
            self.levels, self.why = auto_levels(self.low, self.map_shape, self.sensors,
                                                self.to_world, self.dicing_rate)
        else:
            self.levels, self.why = values["levels"], {"rule": "given"}
        edge_splits(self.levels, self.split)        # ValueError naming levels/split, before any kernel
        self._start = time.perf_counter()
        self._decoded = formats.read_map(self.map_path)
        # the map's texels [object units], differentiable: edits re-displace the mesh
        self.displacement = mi.TensorXf(np.ascontiguousarray(
            self._decoded["displacement"][:, :, None], np.float32))
        self.state = None   # the DisplaceState of the last restoration
        self.stats: dict = {}   # the build_stats of the last restoration (the plugin's, shared)

    def build_mesh(self) -> MeshBuffers:
        """The first build (at load)."""
        out = restore(self.low, self._decoded, levels=self.levels, split=self.split,
                      keep_holes=self.keep_holes)
        self._decoded = None
        return self._buffers(out, self._start)

    def parameters(self) -> list[tuple[str, object, bool]]:
        """(name, value, differentiable) to traverse: the map's texels, the very tensor the
        edits re-displace from."""
        return [("displacement", self.displacement, True)]

    def owns(self, keys) -> bool:
        """Whether an edit of ``keys`` concerns the map."""
        return "displacement" in keys

    def edit(self, keys) -> MeshBuffers:
        """Re-displace from the edited texels (same topology: positions and normals only;
        with a gradient enabled on the texels they carry it), translated by ``to_world`` like
        the load."""
        if self.displacement.shape != (*self.map_shape, 1):
            raise ValueError(f"restored: 'displacement' must keep the map's shape "
                             f"{(*self.map_shape, 1)}, got {self.displacement.shape}")
        if not dr.all(dr.isfinite(dr.detach(self.displacement.array)))[0]:
            raise ValueError("restored: 'displacement' has NaN/Inf texels")
        p, n = self.state.displace(self.displacement)      # keeps the AD graph of the texels
        to_world = self._transform()
        p = mi.Point3f(p)   # displace() returns a Vector3f, which the transform would not move
        return MeshBuffers(dr.ravel(to_world @ p), dr.ravel(dr.normalize(to_world @ mi.Normal3f(n))),
                           None, None, self.stats["vertices"], self.stats["faces"], None)

    def fit_to_sensors(self, sensors) -> MeshBuffers | None:
        """``levels="auto"``: re-derive the levels for ``sensors`` (the scene's, unless the
        shape references its own); the rebuilt mesh if they changed, else ``None`` (the
        figures behind the levels still go into :attr:`stats`)."""
        if not self.auto or self.split is not None:
            return None
        levels, why = auto_levels(self.low, self.map_shape, self.sensors or list(sensors),
                                  self.to_world, self.dicing_rate)
        self.why = why
        if levels == self.levels:
            self.stats.update(why)
            return None
        self.levels = levels
        start = time.perf_counter()
        return self._buffers(restore(self.low, formats.read_map(self.map_path), levels=levels,
                                     keep_holes=self.keep_holes), start)

    def _transform(self) -> mi.Transform4f:
        return mi.Transform4f(mi.ScalarTransform4f(mi.ScalarMatrix4f(self.to_world.astype(np.float32))))

    def _buffers(self, out, start: float) -> MeshBuffers:
        """A restoration in world space, with its ``build_stats``."""
        to_world = self._transform()
        p = to_world @ mi.Point3f(*[mi.Float(np.ascontiguousarray(out.positions[:, k])) for k in range(3)])
        n = dr.normalize(to_world @ mi.Normal3f(*[mi.Float(np.ascontiguousarray(out.normals[:, k]))
                                                  for k in range(3)]))
        self.state = out.state
        V, F = len(out.positions), len(out.faces)
        self.stats = {"levels": self.levels, "split": self.split, **self.why,
                      "vertices": V, "faces": F, "bytes": V * 8 * 4 + F * 3 * 4,
                      "restore_s": out.seconds, "build_s": time.perf_counter() - start,
                      **out.report}
        return MeshBuffers(dr.ravel(p), dr.ravel(n), mi.Float(np.ascontiguousarray(out.uvs.ravel())),
                           mi.UInt32(np.ascontiguousarray(out.faces.ravel())), V, F, self.stats)
