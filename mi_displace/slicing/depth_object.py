"""Image-based depth objects (§4) and visual hulls (§5).

An object is given by six orthographic images on the faces of a cube (centre c, half size
a): per face i a depth image d_i (distance from the face into the cube to the first
surface; +inf where the ray met nothing), a colour image and optionally a normal image.

Face i = (axis, sign) looks from the plane x_axis = c_axis + sign a towards -sign.  Its
image columns run along axis (axis + 1) % 3 and its rows along (axis + 2) % 3, both from
c - a to c + a, texel centres at (j + 0.5) / R (the convention of :func:`capture` and of
files, written into the JSON).

Rendering (§4.1): seen from face i the object is a displacement map over the *opposite*
face with α_i = (2a - d_i) / 2a (0 = background); a point p of the cube is inside when the
α-test passes for all six, α_i(proj_i p) - h_i(p) > 0 with h_i its normalised height
above the opposite face.  The cube is sliced by the planes perpendicular to the axis the
ray is most parallel to ("the best orthogonal direction", N slices across the cube), front
to back (:func:`mi_displace.slicing.trace.first_passing_plane`).  Texturing (§4.2): the
three faces that face the viewer, weighted by the cosine of the angle between their normal
and the view direction (the paper: "weights ... proportional to the angles"; we give the
closest image the largest weight).  A visual hull (§5) uses binary silhouettes: α_i = 1
inside, 0 outside (nearest lookup).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.io import read_exr, read_image, write_exr, write_png
from mi_displace.slicing.trace import first_passing_plane

FACES = ((0, 1), (0, -1), (1, 1), (1, -1), (2, 1), (2, -1))
FACE_NAMES = ("px", "nx", "py", "ny", "pz", "nz")
CONVENTION = ("face i = (axis, sign) looks from x_axis = c + sign*a towards -sign; columns "
              "along axis+1, rows along axis+2 (mod 3), from c-a to c+a, texel centres at "
              "(j+0.5)/R; depth = distance from the face plane, inf = background")


@dataclass
class DepthImages:
    """Six orthographic images on a cube.

    Attributes:
        center: (3,) cube centre; half: half edge length a [world units].
        depth: (6, R, R) float32, +inf where nothing was hit.
        color: (6, R, R, 3) linear RGB (albedo); normal: (6, R, R, 3) world normals or None.
    """

    center: np.ndarray
    half: float
    depth: np.ndarray
    color: np.ndarray
    normal: np.ndarray | None = None

    @property
    def resolution(self) -> int:
        return self.depth.shape[1]

    def check(self, where: str = "depth images") -> "DepthImages":
        """Validate shapes and values (ValueError naming ``where``)."""
        if not (math.isfinite(self.half) and self.half > 0):
            raise ValueError(f"{where}: the cube's half size must be a positive number, got {self.half}")
        if self.depth.ndim != 3 or self.depth.shape[0] != 6 or self.depth.shape[1] != self.depth.shape[2]:
            raise ValueError(f"{where}: expected six square depth images, got shape {self.depth.shape}")
        for name, img in (("color", self.color), ("normal", self.normal)):
            if img is not None and img.shape != self.depth.shape + (3,):
                raise ValueError(f"{where}: {name} images have shape {img.shape}, the depth "
                                 f"images {self.depth.shape}: all must have the same size")
        bad = np.isnan(self.depth) | (self.depth == -np.inf)
        if bad.any():
            raise ValueError(f"{where}: {int(bad.sum())} depth values are NaN or -inf "
                             "(background pixels must be +inf)")
        for name, img in (("color", self.color), ("normal", self.normal)):
            if img is not None and not np.all(np.isfinite(img)):
                raise ValueError(f"{where}: {name} images hold NaN/Inf values")
        return self

    def alpha(self, hull: bool = False) -> np.ndarray:
        """(6, R, R) α channels: the normalised height above the opposite face (depth
        outside the cube clamped into it), 0 for background; binary for a hull."""
        hit = np.isfinite(self.depth)
        if hull:
            return hit.astype(np.float32)
        a = (2 * self.half - np.where(hit, self.depth, 2 * self.half)) / (2 * self.half)
        return np.clip(a, 0.0, 1.0).astype(np.float32)

    def nbytes(self) -> int:
        n = self.depth.size
        return int(n * 4 * (1 + 3 + (3 if self.normal is not None else 0)))


# ---------------------------------------------------------------------------------------
# making the images

def face_sensor(center, half: float, face: int, resolution: int) -> mi.Sensor:
    """The orthographic sensor of face ``face`` (looking into the cube) from 2.5 ``half``
    off the centre; its clip planes are sized from the cube (0.5 and 5 ``half``), so a
    model in millimetres or kilometres is captured alike."""
    axis, sign = FACES[face]
    e = np.eye(3)
    origin = np.asarray(center, np.float64) + sign * 2.5 * half * e[axis]
    up = e[(axis + 2) % 3]
    to_world = mi.ScalarTransform4f().look_at(origin=origin.tolist(), target=list(map(float, center)),
                                               up=up.tolist()) @ mi.ScalarTransform4f().scale([half, half, 1.0])
    return mi.load_dict({"type": "orthographic", "to_world": to_world, "near_clip": 0.5 * half,
                         "far_clip": 5.0 * half,
                         "film": {"type": "hdrfilm", "width": resolution, "height": resolution}})


def capture(source, resolution: int = 256, center=None, half: float | None = None,
            margin: float = 1.02) -> DepthImages:
    """Six orthographic colour (albedo), depth and normal images of ``source``.

    Our own code: for each face an orthographic Mitsuba sensor, one ray at each pixel
    centre (``sensor.sample_ray``), the first intersection's distance (depth AOV), shading
    normal and its BSDF's diffuse reflectance (albedo AOV).

    Args:
        source: a ``mi.Shape`` or a ``load_dict`` dict of one shape (or of a scene).
        resolution: R, pixels along each image edge.
        center, half: the cube; default: the source's bounding box, ``margin`` x larger.
    """
    if not (isinstance(resolution, int) and 1 <= resolution <= 8192):
        raise ValueError(f"depth object: 'resolution' must be an integer in [1, 8192], got {resolution!r}")
    if isinstance(source, dict) and source.get("type") == "scene":
        scene = mi.load_dict(source)
    else:
        scene = mi.load_dict({"type": "scene", "source": source})
    bbox = scene.bbox()
    lo, hi = np.array(bbox.min, np.float64).ravel(), np.array(bbox.max, np.float64).ravel()
    if center is None:
        center = 0.5 * (lo + hi)
    if half is None:
        half = 0.5 * float(np.max(hi - lo)) * margin
    center = np.asarray(center, np.float64)
    R = resolution
    depth = np.full((6, R, R), np.inf, np.float32)
    color = np.zeros((6, R, R, 3), np.float32)
    normal = np.zeros((6, R, R, 3), np.float32)
    idx = dr.arange(mi.UInt32, R * R)
    px = (mi.Float(idx % R) + 0.5) / R
    py = (mi.Float(idx // R) + 0.5) / R
    for face, (axis, sign) in enumerate(FACES):
        sensor = face_sensor(center, half, face, R)
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(px, py), mi.Point2f(0.5))
        si = scene.ray_intersect(ray)
        hit = si.is_valid()
        albedo = si.bsdf(ray).eval_diffuse_reflectance(si, hit)
        o, p = np.array(ray.o).T, np.array(si.p).T
        ok = np.array(hit)
        # the pixel each ray belongs to in our convention (film orientation independent)
        col = np.floor((o[:, (axis + 1) % 3] - center[(axis + 1) % 3] + half) / (2 * half) * R)
        row = np.floor((o[:, (axis + 2) % 3] - center[(axis + 2) % 3] + half) / (2 * half) * R)
        col, row = np.clip(col, 0, R - 1).astype(int), np.clip(row, 0, R - 1).astype(int)
        d = half - sign * (p[:, axis] - center[axis])
        depth[face, row, col] = np.where(ok, d, np.inf)
        color[face, row, col] = np.where(ok[:, None], np.array(albedo).T, 0.0)
        n = np.array(si.sh_frame.n).T
        normal[face, row, col] = np.where(ok[:, None], n, 0.0)
    return DepthImages(center, float(half), depth, color, normal).check("captured images")


def write(images: DepthImages, folder) -> Path:
    """Write ``images`` as ``depth_<face>.exr``, ``color_<face>.png``, ``normal_<face>.exr``
    and ``cube.json`` into ``folder``; returns the JSON's path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    faces = {}
    for i, name in enumerate(FACE_NAMES):
        entry = {"depth": f"depth_{name}.exr", "color": f"color_{name}.png"}
        write_exr(folder / entry["depth"], np.repeat(images.depth[i][..., None], 3, axis=2))
        write_png(folder / entry["color"], images.color[i])
        if images.normal is not None:
            entry["normal"] = f"normal_{name}.exr"
            write_exr(folder / entry["normal"], images.normal[i])
        faces[name] = entry
    meta = {"center": [float(x) for x in images.center], "half_size": float(images.half),
            "resolution": images.resolution, "convention": CONVENTION, "faces": faces}
    path = folder / "cube.json"
    path.write_text(json.dumps(meta, indent=2))
    return path


def read(path) -> DepthImages:
    """Read a ``cube.json`` (see :func:`write`) and its images (names relative to it).

    Raises:
        FileNotFoundError: the JSON or an image is missing; ValueError: malformed JSON,
        images of inconsistent sizes, NaN / -inf depth.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"depth object: 'filename' {str(path)!r} does not exist")
    try:
        meta = json.loads(path.read_text())
        center = np.array(meta["center"], np.float64).reshape(3)
        half = float(meta["half_size"])
        faces = [meta["faces"][name] for name in FACE_NAMES]
    except (ValueError, KeyError, TypeError) as e:
        raise ValueError(f"depth object: {str(path)!r} is not a cube description "
                         f"(center, half_size, faces {'/'.join(FACE_NAMES)}): {e}") from None
    depth, color, normal = [], [], []
    for name, entry in zip(FACE_NAMES, faces):
        if "depth" not in entry or "color" not in entry:
            raise ValueError(f"depth object: face {name!r} of {str(path)!r} needs 'depth' and 'color'")
        d = read_exr(path.parent / entry["depth"])[..., 0]
        c = read_image(path.parent / entry["color"])
        if d.shape != c.shape[:2]:
            raise ValueError(f"depth object: face {name!r}: depth {entry['depth']!r} is "
                             f"{d.shape[1]}x{d.shape[0]}, colour {entry['color']!r} is "
                             f"{c.shape[1]}x{c.shape[0]}: the images must have the same size")
        depth.append(d)
        color.append(c)
        if "normal" in entry:
            normal.append(read_exr(path.parent / entry["normal"]))
    shapes = {d.shape for d in depth}
    if len(shapes) != 1:
        raise ValueError(f"depth object: the six images of {str(path)!r} differ in size "
                         f"({', '.join(f'{n}: {d.shape[1]}x{d.shape[0]}' for n, d in zip(FACE_NAMES, depth))})")
    if normal and len(normal) != 6:
        raise ValueError(f"depth object: {str(path)!r} gives normal images for some faces only")
    if normal and {n.shape[:2] for n in normal} != shapes:
        raise ValueError(f"depth object: the normal images of {str(path)!r} differ in size from the depth images")
    return DepthImages(center, half, np.stack(depth).astype(np.float32), np.stack(color).astype(np.float32),
                       np.stack(normal).astype(np.float32) if normal else None).check(str(path))


# ---------------------------------------------------------------------------------------
# rendering

#: Cells per cube edge of the empty-space grid (:func:`occupancy`).
GRID = 32


def occupancy(alpha: np.ndarray, grid: int = GRID) -> np.ndarray:
    """(grid, grid, grid) Bool (x, y, z): whether a cell of the cube may hold a point inside
    the object.  §4.1's test α_i(proj_i p) - h_i(p) > 0 for all six faces can only pass
    in a cell where, for every face, the largest α of the texels its bilinear lookups
    there read (the cell's footprint plus a texel) exceeds the cell's lowest height h_i:
    a conservative bound, exact skipping (NumPy, one-off, 2 x grid maxima per face).

    Args:
        alpha: (6, R, R) α channels (:meth:`DepthImages.alpha`).
    """
    R = alpha.shape[1]
    edges = np.arange(grid + 1) / grid
    first = np.clip(np.floor(edges[:-1] * R - 0.5).astype(int) - 1, 0, R - 1)
    last = np.clip(np.floor(edges[1:] * R - 0.5).astype(int) + 2, 0, R - 1)
    occ = np.ones((grid, grid, grid), bool)
    g = np.arange(grid)
    for face, (axis, sign) in enumerate(FACES):   # six faces
        cols = np.stack([alpha[face][:, a:b + 1].max(1) for a, b in zip(first, last)], 1)  # (R, G)
        block = np.stack([cols[a:b + 1].max(0) for a, b in zip(first, last)], 0)        # (G2, G1)
        h_low = g / grid if sign > 0 else 1 - (g + 1) / grid                            # along axis
        possible = block.T[None, :, :] > h_low[:, None, None] - 1e-6                    # (axis, a1, a2)
        a1, a2 = (axis + 1) % 3, (axis + 2) % 3
        order = np.argsort([axis, a1, a2])
        occ &= np.transpose(possible, order)
    return occ


def _texture(images: np.ndarray, nearest: bool) -> list[mi.Texture2f]:
    mode = dr.FilterMode.Nearest if nearest else dr.FilterMode.Linear
    out = []
    for img in images:
        data = img if img.ndim == 3 else img[..., None]
        out.append(mi.Texture2f(mi.TensorXf(np.ascontiguousarray(data, np.float32)),
                                filter_mode=mode, wrap_mode=dr.WrapMode.Clamp))
    return out


@dataclass(init=False, eq=False)   # the fields a PyTree: a frozen raster frame finds the textures
class DepthObject:
    """The renderer of §4.1 / §4.2 over :class:`DepthImages`.

    The images and the cube live in object space; ``to_world`` places them in the scene.
    The public methods (:meth:`find`, :meth:`normal`, :meth:`color`, :meth:`occluded`)
    take and return world points and directions; the slicing itself runs in object space
    (the ray parameter t is shared), so any affine ``to_world``, a non-uniform scale too,
    is honoured exactly.

    Args:
        images: the six images; slices: N planes across the cube in the best direction;
        hull: visual hull (binary silhouettes, §5) instead of depth;
        to_world: (4, 4) object-to-world matrix (default: identity).
    """
    n: int
    hull: bool
    c: list
    a: float
    delta: float
    alpha_tex: list
    color_tex: list
    normal_tex: list | None
    occupancy: mi.Bool
    skip_empty: bool
    to_world: mi.Transform4f
    to_object: mi.Transform4f

    def __init__(self, images: DepthImages, slices: int, hull: bool = False, to_world=None):
        from mi_displace.slicing.geometry import MAX_SLICES, transform_pair

        if not (isinstance(slices, int) and 1 <= slices <= MAX_SLICES):
            raise ValueError(f"depth object: 'slices' must be an integer in [1, {MAX_SLICES}], got {slices!r}")
        self.images, self.n, self.hull = images.check(), slices, bool(hull)
        self.c = [float(x) for x in images.center]
        self.a = float(images.half)
        self.delta = 2 * self.a / slices
        self.alpha_tex = _texture(images.alpha(self.hull), nearest=self.hull)
        self.color_tex = _texture(images.color, nearest=False)
        self.normal_tex = None if images.normal is None else _texture(images.normal, nearest=False)
        self.occupancy = mi.Bool(occupancy(images.alpha(self.hull)).ravel())
        self.skip_empty = True   # empty-space skipping (same result; off: every plane tested)
        self.matrix = np.eye(4) if to_world is None else np.asarray(to_world, np.float64)
        self.to_world, self.to_object = transform_pair(self.matrix)
        self.stats = {"slices": slices, "hull": self.hull, "resolution": images.resolution,
                      "bytes": images.nbytes()}

    def _proj(self, p: mi.Point3f, face: int):
        axis, sign = FACES[face]
        a1, a2 = (axis + 1) % 3, (axis + 2) % 3
        uv = mi.Point2f((p[a1] - self.c[a1] + self.a) / (2 * self.a),
                        (p[a2] - self.c[a2] + self.a) / (2 * self.a))
        h = (self.a + sign * (p[axis] - self.c[axis])) / (2 * self.a)
        return uv, h

    def inside(self, p: mi.Point3f) -> mi.Bool:
        """§4.1: the α-test passes for all six maps (and p lies in the cube).  The maps are
        read one after the other under symbolic ifs: a SIMD packet whose lanes have all
        failed skips the rest (the cup's raster frame at 512^2: 0.70-0.79x, the same image)."""
        def passes(face, ok):
            uv, h = self._proj(p, face)
            return ok & (h >= 0) & (h <= 1) & (self.alpha_tex[face].eval(uv, ok)[0] - h > 0)

        ok = passes(0, dr.full(mi.Bool, True, dr.width(p)))
        for face in range(1, 6):   # six maps, not elements
            ok = dr.if_stmt((ok,), ok, lambda m, f=face: (passes(f, m),), lambda m: (m,),
                            label="depth_object_alpha")[0]
        return ok

    def slab(self, o: mi.Point3f, d: mi.Vector3f):
        """(t_in, t_out) of the ray in the cube (t_in clamped to 0; t_out < t_in: miss)."""
        t_in, t_out = dr.zeros(mi.Float, dr.width(o)), dr.full(mi.Float, dr.inf, dr.width(o))
        for k in range(3):
            dk = dr.select(dr.abs(d[k]) > 1e-12, d[k], 1e-12)
            t0 = (self.c[k] - self.a - o[k]) / dk
            t1 = (self.c[k] + self.a - o[k]) / dk
            t_in = dr.maximum(t_in, dr.minimum(t0, t1))
            t_out = dr.minimum(t_out, dr.maximum(t0, t1))
        return t_in, t_out

    def skip(self, o: mi.Point3f, d: mi.Vector3f):
        """Empty-space skipping for :func:`~mi_displace.slicing.trace.first_passing_plane`:
        ``skip(t)`` is the ray parameter where the ray leaves the :data:`GRID` cell of
        ``o + t d`` when :func:`occupancy` says no point of it is inside (a hair short of
        it), else ``t``."""
        size = 2 * self.a / GRID
        lo = [self.c[k] - self.a for k in range(3)]

        def skip(t):
            p = o + t * d
            cell = [dr.floor((p[k] - lo[k]) / size) for k in range(3)]
            ok = mi.Bool(True)
            for x in cell:
                ok &= (x >= 0) & (x < GRID)
            index = mi.UInt32(cell[0]) * GRID * GRID + mi.UInt32(cell[1]) * GRID + mi.UInt32(cell[2])
            empty = ok & ~dr.gather(mi.Bool, self.occupancy, index, ok)
            exit_t = mi.Float(dr.inf)
            for k in range(3):
                far = lo[k] + (cell[k] + dr.select(d[k] > 0, 1.0, 0.0)) * size
                exit_t = dr.minimum(exit_t, dr.select(dr.abs(d[k]) > 1e-12,
                                                      (far - o[k]) / d[k], dr.inf))
            return dr.select(empty, dr.maximum(exit_t - 1e-4 * size, t), t)

        return skip

    def _local(self, p: mi.Point3f, d: mi.Vector3f):
        """World point and direction in object space (d not renormalised: same t)."""
        return self.to_object @ mi.Point3f(p), self.to_object @ mi.Vector3f(d)

    def _find_local(self, o: mi.Point3f, d: mi.Vector3f, active: mi.Bool):
        """Front-most slice point inside the object, object space: (found, t)."""
        t_in, t_out = self.slab(o, d)
        ad = [dr.abs(d[k]) for k in range(3)]
        found, t_hit = dr.zeros(mi.Bool, dr.width(o)), dr.zeros(mi.Float, dr.width(o))
        first = (ad[0] >= ad[1]) & (ad[0] >= ad[2])
        second = ~first & (ad[1] >= ad[2])
        masks = (first, second, ~first & ~second)   # the axis d is most parallel to
        for k in range(3):  # the best orthogonal direction (ties: lowest axis)
            mine = mi.Bool(active) & masks[k]
            m = mi.Vector3f(*[1.0 if j == k else 0.0 for j in range(3)])
            ok, t = first_passing_plane(o, d, m, self.c[k] - self.a + 0.5 * self.delta, self.delta,
                                        t_in, t_out, self.inside, mine, self.n + 2,
                                        self.skip(o, d) if self.skip_empty else None)
            found |= ok
            t_hit = dr.select(ok, t, t_hit)
        return found, t_hit

    def find(self, o: mi.Point3f, d: mi.Vector3f, active: mi.Bool):
        """Front-most slice point inside the object along the world ray ``o + t d``:
        (found, p), p a world point (``o`` where nothing was found)."""
        found, t = self._find_local(*self._local(o, d), active)
        return found, mi.Point3f(o + dr.select(found, t, 0.0) * d)

    def weights(self, d: mi.Vector3f):
        """§4.2: (face index, weight) of the three faces facing a viewer looking along d."""
        s = dr.abs(d[0]) + dr.abs(d[1]) + dr.abs(d[2])
        out = []
        for k in range(3):
            face = dr.select(d[k] < 0, 2 * k, 2 * k + 1)  # the face whose normal is -d's side
            out.append((face, dr.abs(d[k]) / s))
        return out

    def _blend(self, textures, p, d):
        value = dr.zeros(mi.Vector3f, dr.width(p))
        for k, (face, w) in enumerate(self.weights(d)):
            uv_pos, _ = self._proj(p, 2 * k)  # both faces of an axis share the coordinates
            for sign_face in (2 * k, 2 * k + 1):
                c = textures[sign_face].eval(uv_pos)
                value += dr.select(face == sign_face, w, 0.0) * mi.Vector3f(c[0], c[1], c[2])
        return value

    def color(self, p: mi.Point3f, d: mi.Vector3f) -> mi.Color3f:
        """View-dependent colour (§4.2) at world point p for a viewer looking along d."""
        return mi.Color3f(self._blend(self.color_tex, *self._local(p, d)))

    def normal(self, p: mi.Point3f, d: mi.Vector3f) -> mi.Vector3f:
        """Unit world shading normal at world point p (viewer looking along d): the
        object-space normal through ``to_world``'s inverse transpose."""
        n = self._normal_local(*self._local(p, d))
        return dr.normalize(mi.Vector3f(self.to_world @ mi.Normal3f(n)))

    def _normal_local(self, p: mi.Point3f, d: mi.Vector3f) -> mi.Vector3f:
        """Object-space normal: the normal images blended like the colour (reshading, §7);
        without normal images, the cube face normal of the best-facing image."""
        if self.normal_tex is not None:
            n = self._blend(self.normal_tex, p, d)
            ok = dr.squared_norm(n) > 1e-12
            return dr.select(ok, dr.normalize(n), -d)
        best = dr.zeros(mi.Vector3f, dr.width(p))
        ad = [dr.abs(d[k]) for k in range(3)]
        for k in range(3):
            big = (ad[k] >= ad[(k + 1) % 3]) & (ad[k] >= ad[(k + 2) % 3])
            e = mi.Vector3f(*[1.0 if j == k else 0.0 for j in range(3)])
            best = dr.select(big & (dr.norm(best) == 0), -dr.sign(d[k]) * e, best)
        return best

    def occluded(self, p: mi.Point3f, normal: mi.Vector3f, wl: mi.Vector3f, active: mi.Bool) -> mi.Bool:
        """Whether the object blocks world direction ``wl`` from world point p (the ray
        starts 1.5 slice spacings off p along ``normal``, in object space)."""
        p_obj, wl_obj = self._local(p, wl)
        n_obj = dr.normalize(mi.Vector3f(self.to_object @ mi.Normal3f(normal)))
        return self._find_local(p_obj + n_obj * (1.5 * self.delta), wl_obj, active)[0]
