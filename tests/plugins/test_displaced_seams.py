"""Watertight mesh displacement across UV seams and hard edges.

Mitsuba's OBJ loader splits a position into one vertex per side of a UV seam (each with a
normal of its own side) and per corner where the file gives per-face normals.  Every copy
must move by the same vector, else the displaced surface cracks.  Truth: the welded
displaced mesh has exactly the base's open edges; rays aimed at seam points from outside
stop at the surface; at a cube corner the direction is the diagonal (angle-weighted normal).
"""
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

SPOT = "data/spot/spot_triangulated.obj"


def write_obj(path, pos, uvs, faces, normals=None, face_normals=None):
    """OBJ with per-corner position / uv (/ normal) indices: ``faces`` (F, 3, 2) or (F, 3, 3)."""
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in pos]
    lines += [f"vt {u:.9g} {v:.9g}" for u, v in uvs]
    if normals is not None:
        lines += [f"vn {x:.9g} {y:.9g} {z:.9g}" for x, y, z in normals]
    lines += ["f " + " ".join("/".join(str(i + 1) for i in corner) for corner in f) for f in faces]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def uv_sphere_obj(path, nu=16, nv=8):
    """Lat-long sphere: one position per ring point and pole, UVs with a seam column at
    u = 0 / 1 and one uv per pole corner (no normals: the loader computes one per side)."""
    theta = np.arange(1, nv) / nv * np.pi
    phi = np.arange(nu) / nu * 2 * np.pi
    ring = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                     np.repeat(np.cos(theta)[:, None], nu, 1)], -1).reshape(-1, 3)
    pos = np.concatenate([ring, [[0, 0, 1], [0, 0, -1]]])
    north, south = len(ring), len(ring) + 1
    uu, vv = np.meshgrid(np.arange(nu + 1) / nu, np.arange(nv + 1) / nv)
    uvs = np.stack([uu.ravel(), 1 - vv.ravel()], 1)                  # uv (i, j) -> j (nu+1) + i

    def p(i, j):      # position of grid point (column i, row j)
        return np.where(j == 0, north, np.where(j == nv, south, (j - 1) * nu + i % nu))

    i, j = np.meshgrid(np.arange(nu), np.arange(nv))
    i, j = i.ravel(), j.ravel()
    corners = [(i, j), (i, j + 1), (i + 1, j + 1), (i + 1, j)]
    quad = np.stack([np.stack([p(a, b), b * (nu + 1) + a], -1) for a, b in corners], 1)
    tris = np.concatenate([quad[:, [0, 1, 2]][j < nv - 1], quad[:, [0, 2, 3]][j > 0]])
    return write_obj(path, pos, uvs, tris)


def hard_cube_obj(path):
    """Unit cube with per-face normals and one UV chart per face (24 corners, 8 positions)."""
    pos = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads, normals = [], []
    for axis in range(3):
        for sign in (-1, 1):
            quad = np.flatnonzero(pos[:, axis] == sign)
            centre = np.zeros(3)
            centre[axis] = sign
            a = np.arctan2(*(pos[quad] - centre)[:, [k for k in range(3) if k != axis]].T)
            quad = quad[np.argsort(a)]
            if np.dot(np.cross(pos[quad[1]] - pos[quad[0]], pos[quad[2]] - pos[quad[0]]), centre) < 0:
                quad = quad[::-1]
            quads.append(quad)
            normals.append(centre)
    uvs = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]])
    tris = []
    for f, q in enumerate(quads):
        corner = [(q[k], k, f) for k in range(4)]
        tris += [[corner[0], corner[1], corner[2]], [corner[0], corner[2], corner[3]]]
    return write_obj(path, pos, uvs, np.array(tris), normals=np.array(normals))


def buffers(shape):
    p = mi.traverse(shape)
    pos = np.asarray(p["vertex_positions"]).reshape(-1, 3)
    nrm = np.asarray(p["vertex_normals"]).reshape(-1, 3)
    faces = np.asarray(p["faces"]).reshape(-1, 3)
    assert np.all(np.isfinite(pos)) and np.all(np.isfinite(nrm))
    return pos, nrm, faces


def welded_edges(positions, faces):
    """Edges over exactly equal positions: (number of open edges, non-manifold edges)."""
    _, w = np.unique(positions, axis=0, return_inverse=True)
    w = w.ravel()[faces]
    e = np.sort(np.stack([w, np.roll(w, -1, 1)], 2).reshape(-1, 2), 1)
    _, count = np.unique(e, axis=0, return_counts=True)
    return int((count == 1).sum()), int((count > 2).sum())


def load(filename, **kw):
    props = {"type": "displaced", "filename": filename, "height": {"type": "ripples"},
             "scale": 0.04, **kw}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # the thin-shell check may warn on coarse bases
        return mi.load_dict(props), mi.load_dict({**props, "scale": 0.0})


def seam_rays(flat, shape, nudge=1e-3):
    """Rays from outside at every seam edge (an edge whose copies are separate vertices on
    each side), aimed along the base's inward normal at the mean of the copies' midpoints
    (the sides' if they part), nudged ``nudge`` of the way into each adjacent triangle so
    that a closed surface is hit inside a face: a ray through exactly a shared edge can miss
    both faces in Embree without its robust mode (16 of 304 on the closed UV sphere with
    ``nudge=0``).  Returns the rays, the distance from each origin to its target and the
    base's size."""
    p0, n0, faces = buffers(flat)
    p, _, _ = buffers(shape)
    _, cls = np.unique(p0, axis=0, return_inverse=True)
    cls = cls.ravel()
    a, b = faces.ravel(), np.roll(faces, -1, 1).ravel()
    swap = cls[a] > cls[b]
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    pairs, inverse = np.unique(cls[a] * (cls.max() + 1) + cls[b], return_inverse=True)
    sides = np.zeros(len(pairs), int)
    np.add.at(sides, np.unique(np.stack([inverse, a, b], 1), axis=0)[:, 0], 1)
    seam = np.flatnonzero(sides[inverse] > 1)
    assert len(seam) > 0
    mid = 0.5 * (p[a[seam]] + p[b[seam]])
    total, count, normal = np.zeros((len(pairs), 3)), np.zeros(len(pairs)), np.zeros((len(pairs), 3))
    np.add.at(total, inverse[seam], mid)
    np.add.at(count, inverse[seam], 1)
    np.add.at(normal, inverse[seam], n0[a[seam]] + n0[b[seam]])
    target = total[inverse[seam]] / count[inverse[seam], None]
    normal = normal[inverse[seam]]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    centroid = p[faces[seam // 3]].mean(1)
    target = target + nudge * (centroid - mid)
    size = np.linalg.norm(p0.max(0) - p0.min(0))
    origin = target + 0.05 * size * normal
    ray = mi.Ray3f(mi.Point3f(*origin.T.astype(np.float32)),
                   mi.Vector3f(*(-normal).T.astype(np.float32)))
    return ray, 0.05 * size, size


def assert_rays_stop_at_the_seams(flat, shape):
    ray, expected, size = seam_rays(flat, shape)
    scene = mi.load_dict({"type": "scene", "s": shape})
    si = scene.ray_intersect(ray)
    t = np.where(np.asarray(si.is_valid()), np.asarray(si.t), np.inf)
    deeper = t > expected + 1e-4 * size
    assert not deeper.any(), (f"{deeper.sum()} of {len(t)} seam rays pass the surface, "
                              f"up to {np.max(t[deeper] - expected)} deeper")


@pytest.fixture
def sphere_obj(tmp_path):
    return uv_sphere_obj(tmp_path / "uv_sphere.obj")


@pytest.mark.parametrize("kw", [{"subdivision": 1}, {"subdivision": 4}])
def test_uv_sphere_with_seam_stays_closed(variant, sphere_obj, kw):
    shape, flat = load(sphere_obj, **kw)
    assert welded_edges(buffers(flat)[0], buffers(flat)[2]) == (0, 0)   # closed once welded
    assert welded_edges(buffers(shape)[0], buffers(shape)[2]) == (0, 0)
    assert_rays_stop_at_the_seams(flat, shape)


def test_uv_sphere_diced_stays_closed(variant, sphere_obj):
    cam = {"type": "perspective", "fov": 40, "film": {"type": "hdrfilm", "width": 64, "height": 64},
           "to_world": mi.ScalarTransform4f().look_at(origin=[0, -4, 1], target=[0, 0, 0], up=[0, 0, 1])}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = mi.load_dict({"type": "scene", "cam": cam, "s": {
            "type": "displaced", "filename": sphere_obj, "height": {"type": "ripples"},
            "scale": 0.04, "dicing_rate": 2.0, "r": {"type": "ref", "id": "cam"}}})
    shape = scene.shapes()[0]
    pos, _, faces = buffers(shape)
    assert shape.build_stats["edge_segments_max"] > 1          # really diced
    assert welded_edges(pos, faces) == (0, 0)


@pytest.mark.parametrize("kw", [{"subdivision": 1}, {"subdivision": 3}])
def test_cube_with_per_face_normals_stays_closed(variant, tmp_path, kw):
    obj = hard_cube_obj(tmp_path / "cube.obj")
    shape, flat = load(obj, **kw)
    p0, _, faces = buffers(flat)
    from mi_displace.core.mesh_io import load_uv_mesh

    assert len(np.unique(load_uv_mesh(obj)[1], axis=0)) == 6   # the loader kept the hard edges
    p, _, _ = buffers(shape)
    assert welded_edges(p, faces) == (0, 0)
    # a corner moves along the cube's diagonal (angle-weighted: three right angles)
    corner = np.all(np.abs(np.abs(p0) - 1) < 1e-6, axis=1)
    move = p[corner] - p0[corner]
    assert np.abs(move).max() > 1e-3
    diagonal = np.sign(p0[corner]) / np.sqrt(3)
    assert np.allclose(np.cross(move, diagonal), 0, atol=1e-6)
    assert_rays_stop_at_the_seams(flat, shape)


@pytest.mark.parametrize("kw", [{"subdivision": 2}, {"subdivision": 4}])
def test_spot_stays_closed(variant, kw):
    shape, flat = load(SPOT, scale=0.015, **kw)
    p0, _, faces = buffers(flat)
    assert welded_edges(p0, faces) == (0, 0)
    assert welded_edges(buffers(shape)[0], faces) == (0, 0)
    assert_rays_stop_at_the_seams(flat, shape)


def test_unwrapped_bunny_keeps_exactly_its_own_holes(variant, tmp_path):
    """The Stanford bunny (open at the bottom) charted by xatlas, written without normals:
    the displaced mesh has exactly the base's open edges, no more."""
    from mi_displace.bake.meshdata import load_mesh, save_obj
    from mi_displace.bake.unwrap import unwrap

    low = unwrap(load_mesh("data/bunny/bun_zipper_res3.ply"))
    obj = str(save_obj(tmp_path / "bunny.obj", low.positions, low.faces, low.uvs))
    shape, flat = load(obj, subdivision=3, scale=0.002)
    p0, _, faces = buffers(flat)
    holes = welded_edges(p0, faces)[0]
    assert holes > 0                                           # the scan's holes
    # (non-manifold counts differ: the scan's zero-area triangles make flat points coincide)
    assert welded_edges(buffers(shape)[0], faces)[0] == holes


def test_spot_diced_stays_closed(variant):
    cam = {"type": "perspective", "fov": 30, "film": {"type": "hdrfilm", "width": 64, "height": 64},
           "to_world": mi.ScalarTransform4f().look_at(origin=[3, 1, 3], target=[0, 0.2, 0], up=[0, 1, 0])}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = mi.load_dict({"type": "scene", "cam": cam, "s": {
            "type": "displaced", "filename": SPOT, "height": {"type": "ripples"},
            "scale": 0.015, "dicing_rate": 4.0, "r": {"type": "ref", "id": "cam"}}})
    pos, _, faces = buffers(scene.shapes()[0])
    assert welded_edges(pos, faces) == (0, 0)


def test_split_normals_keeps_each_copy_on_its_own_normal_and_warns_once(variant, sphere_obj):
    """The opt-out: every copy of a base vertex moves along its own (loader) normal, the
    seam opens, and the load warns once (an edit does not warn again)."""
    with pytest.warns(UserWarning, match=r"split_normals=true moves each copy of a position "
                                         r"along its own vertex normal; the copies disagree "
                                         r"at [0-9,]+ positions") as record:
        shape = mi.load_dict({"type": "displaced", "filename": sphere_obj, "subdivision": 2,
                              "height": {"type": "ripples"}, "scale": 0.04,
                              "split_normals": True})
    assert sum("split_normals" in str(w.message) for w in record) == 1
    flat = mi.load_dict({"type": "displaced", "filename": sphere_obj, "subdivision": 2,
                         "scale": 0.0, "split_normals": True})
    p0, _, faces = buffers(flat)
    p, _, _ = buffers(shape)
    assert welded_edges(p, faces)[0] > 0
    from mi_displace.core.mesh_io import load_uv_mesh

    base, base_n, base_uv, _ = load_uv_mesh(sphere_obj)
    # the tessellation's vertices that are base vertices: same position and same uv
    uv = np.asarray(mi.traverse(flat)["vertex_texcoords"]).reshape(-1, 2)
    keys = np.concatenate([np.concatenate([base, base_uv], 1),
                           np.concatenate([p0, uv], 1)]).astype(np.float32)
    _, ids = np.unique(keys, axis=0, return_inverse=True)
    ids = ids.ravel()
    of_id = np.full(ids.max() + 1, -1)
    of_id[ids[:len(base)]] = np.arange(len(base))
    copy = of_id[ids[len(base):]]
    on = copy >= 0
    assert on.sum() == len(base)                     # every copy of every base vertex
    move = p[on] - p0[on]
    assert np.linalg.norm(move, axis=1).max() > 1e-3
    assert np.allclose(np.cross(move, base_n[copy[on]]), 0, atol=1e-6)
    params = mi.traverse(shape)
    with warnings.catch_warnings(record=True) as again:
        warnings.simplefilter("always")
        params["scale"] = mi.Float(0.03)
        params.update()
    assert not any("split_normals" in str(w.message) for w in again)


def test_split_normals_needs_a_mesh_base(variant):
    with pytest.raises(Exception, match=r"displaced: 'split_normals' applies to base 'mesh' "
                                         r"only \(base is 'sphere'\)"):
        mi.load_dict({"type": "displaced", "base": "sphere", "split_normals": True})
