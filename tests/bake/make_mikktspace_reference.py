"""Writes tests/bake/data/mikktspace_reference.npz: a test mesh and the tangents of the reference
mikktspace.c (genTangSpaceDefault, through the pymikktspace binding; docs/bake.md says how to
build it) per face corner.  Run from the worktree root: python tests/bake/make_mikktspace_reference.py"""
import sys
import numpy as np
import mikktspace as C
sys.path.insert(0, "tests/bake")
import mitsuba as mi
mi.set_variant("llvm_ad_rgb")
import bake_meshes
from mi_displace.bake.meshdata import vertex_normals

sp = bake_meshes._sphere_mesh(32, 16, 0.05)
p, f, uv = sp.positions, sp.faces, sp.uvs.copy()
rng = np.random.default_rng(7)
uv[p[:, 0] > 0.2, 0] = 1.0 - uv[p[:, 0] > 0.2, 0]          # mirrored region: fans with both orientations
uv[rng.random(len(uv)) < 0.03] = 0.25                        # collapsed UVs: zero-UV-area triangles
fin = np.array([[f[5, 0], f[5, 1], len(p)]])                 # a third face on one edge (non-manifold)
p = np.vstack([p, p[f[5, 0]] + [0, 0, 0.3]]).astype(np.float32)
uv = np.vstack([uv, [[0.9, 0.9]]]).astype(np.float32)
f = np.vstack([f, fin])
n = vertex_normals(p, f)
P, N, U = (a[f].reshape(-1, a.shape[1]).astype(np.float32) for a in (p, n, uv))
out = C.gen_default(list(range(len(P))), P.ravel().copy(), N.ravel().copy(), U.ravel().copy())
a = np.frombuffer(out, np.float32).reshape(len(f), 3, 4)
np.savez_compressed("tests/bake/data/mikktspace_reference.npz", positions=p, faces=f, normals=n,
                    uvs=uv, tangents=a[..., :3].copy(), signs=a[..., 3].copy())
print(len(f), "faces")
