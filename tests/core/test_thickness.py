"""Displacement deeper than the base's local thickness is detected (issue 12.3)."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import trimesh

from mi_displace.core import surfaces, tessellate
from mi_displace.core.thickness import crossing_check, crossing_warning

WALL = 0.015


def shell_mesh(wall: float = WALL):
    """A thin spherical shell: outer radius 1 (normals out), inner radius 1 - wall (normals
    into the cavity, faces wound to match), spherical UVs; (pos, nrm, uvs, faces)."""
    ico = trimesh.creation.icosphere(3)
    v = ico.vertices / np.linalg.norm(ico.vertices, axis=1)[:, None]
    uv = np.stack([np.arctan2(v[:, 1], v[:, 0]) / (2 * np.pi) + 0.5,
                   np.arccos(np.clip(v[:, 2], -1, 1)) / np.pi], 1)
    n = len(v)
    pos = np.concatenate([v, (1 - wall) * v])
    nrm = np.concatenate([v, -v])
    faces = np.concatenate([ico.faces, ico.faces[:, ::-1] + n])
    return pos, nrm, np.concatenate([uv, uv]), faces


def constant(value):
    return lambda uv: (dr.full(mi.Float, value, dr.width(uv)), dr.zeros(mi.Vector2f, dr.width(uv)))


@pytest.mark.parametrize("depth,crosses", [(0.03, True), (0.01, False)])
def test_inward_displacement_through_a_thin_shell(variant, depth, crosses):
    pos, nrm, uvs, faces = shell_mesh()
    t = tessellate.displace_mesh(pos, nrm, uvs, faces, constant(0.0), depth, 1.0, 2)
    check = crossing_check(t, base_mesh=(pos, faces))
    assert check["vertices"] == t.vertex_count
    if crosses:  # every vertex of both walls passes through the other wall (rays that
        # meet the other wall exactly at one of its vertices or edges may slip through)
        assert check["crossing_vertices"] > 0.95 * t.vertex_count
        assert check["max_depth_ratio"] == pytest.approx(depth / WALL, rel=0.05)
        message = crossing_warning("displaced 'shell'", check)
        assert "'shell'" in message and "thickness" in message
    else:
        assert check["crossing_vertices"] == 0
        assert crossing_warning("displaced 'shell'", check) is None


def test_outward_displacement_does_not_count(variant):
    pos, nrm, uvs, faces = shell_mesh()
    t = tessellate.displace_mesh(pos, nrm, uvs, faces, constant(1.0), 0.05, 0.0, 2)
    assert crossing_check(t, base_mesh=(pos, faces))["crossing_vertices"] == 0


def test_parametric_bases_use_their_analytic_thickness(variant):
    torus = surfaces.Torus(1.0, 0.1)
    assert torus.thickness() == pytest.approx(0.2) and surfaces.Plane().thickness() == np.inf
    t = tessellate.displace_parametric(torus, constant(0.0), 0.3, 1.0, 32, 16)
    assert crossing_check(t, thickness=torus.thickness())["crossing_vertices"] == t.vertex_count
    t = tessellate.displace_parametric(torus, constant(0.0), 0.1, 1.0, 32, 16)
    assert crossing_check(t, thickness=torus.thickness())["crossing_vertices"] == 0


def test_both_walls_moving_towards_each_other_cross(variant):
    """Each wall moves 0.01 inwards (less than the 0.015 wall): alone harmless, together they
    meet; counted once the other side's displacement is known."""
    pos, nrm, uvs, faces = shell_mesh()
    t = tessellate.displace_mesh(pos, nrm, uvs, faces, constant(0.0), 0.01, 1.0, 2)
    alone = crossing_check(t, base_mesh=(pos, faces))
    both = crossing_check(t, base_mesh=(pos, faces, uvs),
                          other_side=lambda uv: dr.full(mi.Float, -0.01, dr.width(uv)))
    assert alone["crossing_vertices"] == 0
    assert both["crossing_vertices"] > 0.95 * t.vertex_count
    assert both["max_depth_ratio"] == pytest.approx(0.02 / WALL, rel=0.1)


def _full_depth_check(pos, nrm, uvs, faces, base, scale):
    """Both walls of Spot moved ``scale`` inwards everywhere (h = 0, midlevel 1)."""
    t = tessellate.displace_mesh(pos, nrm, uvs, faces, constant(0.0), scale, 1.0, 2)
    return crossing_check(t, base_mesh=base,
                          other_side=lambda uv: dr.full(mi.Float, -scale, dr.width(uv)))


def test_spot_is_flagged_at_its_tail_only(variant):
    """vdm_spot's reference warns: Spot's tail (the nub at the rear, z > 0.95) is 0.035-0.039
    thick, less than both walls moving 0.02 inwards.  No false positives elsewhere (ears,
    horns, a vertex's own neighbourhood): up to 0.0175 per wall nothing is flagged, and the
    rest of the cow, cast against the whole base, is clean at 0.02 and 0.025."""
    from pathlib import Path

    from mi_displace.core.mesh_io import load_uv_mesh

    spot = Path(__file__).resolve().parents[2] / "data" / "spot" / "spot_triangulated.obj"
    pos, nrm, uvs, faces = load_uv_mesh(str(spot))
    base = (pos, faces, uvs)
    assert _full_depth_check(pos, nrm, uvs, faces, base, 0.0175)["crossing_vertices"] == 0
    assert _full_depth_check(pos, nrm, uvs, faces, base, 0.02)["crossing_vertices"] > 0
    x, y, z = pos[:, 0], pos[:, 1], pos[:, 2]
    tail = (z > 0.95) & (np.abs(x) < 0.1) & (y > -0.2) & (y < 0.05)   # the nub at the rear
    body = faces[~np.any(tail[faces], axis=1)]                       # the rest of the cow
    used, body = np.unique(body, return_inverse=True)
    body = body.reshape(-1, 3)
    assert 0.9 * len(faces) < len(body) < len(faces)
    for scale in (0.02, 0.025):
        check = _full_depth_check(pos[used], nrm[used], uvs[used], body, base, scale)
        assert check["crossing_vertices"] == 0, (scale, check)
