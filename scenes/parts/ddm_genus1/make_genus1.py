"""Makes genus1.obj: a lumpy, twisted torus (genus 1, not the analytic torus) unwrapped by
xatlas into several UV charts — the 'unseen-style' mesh base of scenes/ddm_genus1.xml.

    .venv/bin/python scenes/parts/ddm_genus1/make_genus1.py

Deterministic (no random numbers); xatlas 0.0.11 with its default options.
"""
from pathlib import Path

import numpy as np
import trimesh
import xatlas

N_MAJOR, N_MINOR = 64, 24
R, r = 1.0, 0.38


def lumpy_torus():
    th, ph = np.meshgrid(np.linspace(0, 2 * np.pi, N_MAJOR, endpoint=False),
                         np.linspace(0, 2 * np.pi, N_MINOR, endpoint=False), indexing="ij")
    rad = r * (1 + 0.22 * np.sin(3 * th) * np.cos(ph + th) + 0.1 * np.cos(5 * th))
    centre = R * (1 + 0.15 * np.cos(2 * th))
    z0 = 0.25 * np.sin(2 * th)
    x = (centre + rad * np.cos(ph)) * np.cos(th)
    y = (centre + rad * np.cos(ph)) * np.sin(th)
    z = z0 + rad * np.sin(ph)
    verts = np.stack([x, y, z], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(N_MAJOR), np.arange(N_MINOR), indexing="ij")
    a = i * N_MINOR + j
    b = ((i + 1) % N_MAJOR) * N_MINOR + j
    c = ((i + 1) % N_MAJOR) * N_MINOR + (j + 1) % N_MINOR
    d = i * N_MINOR + (j + 1) % N_MINOR
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    return verts, faces


def main(out=Path(__file__).with_name("genus1.obj")):
    verts, faces = lumpy_torus()
    mesh = trimesh.Trimesh(verts, faces, process=False)
    assert mesh.euler_number == 0 and mesh.is_watertight   # genus 1
    normals = mesh.vertex_normals
    vmap, idx, uvs = xatlas.parametrize(verts, faces)
    lines = ["# lumpy torus (genus 1), UV charts by xatlas; made by make_genus1.py (CC0)"]
    lines += [f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}" for p in verts]
    lines += [f"vt {t[0]:.6f} {t[1]:.6f}" for t in uvs]
    lines += [f"vn {n[0]:.6f} {n[1]:.6f} {n[2]:.6f}" for n in normals]
    lines += ["f " + " ".join(f"{vmap[k] + 1}/{k + 1}/{vmap[k] + 1}" for k in tri) for tri in idx]
    out.write_text("\n".join(lines) + "\n")
    return out


if __name__ == "__main__":
    print(main())
