"""Tile layouts (§3.2, §5)."""
import numpy as np
import pytest

from mi_displace.ddm.layout import make_layout


def test_rect_layout_covers_the_domain():
    lay = make_layout("rect", 8, 4)
    assert lay.count == 32 and lay.size == (1 / 8, 1 / 4)
    u0, v0 = lay.offsets[:, 0], lay.offsets[:, 1]
    assert sorted(set(np.round(u0 * 8, 9))) == list(range(8))
    assert sorted(set(np.round(v0 * 4, 9))) == list(range(4))
    assert np.all(lay.tile_index == 0)


def test_gaps_shrink_tiles_inside_their_cells():
    lay = make_layout("rect", 4, 2, gap_u=0.2, gap_v=0.5, u0=0.01, v0=-0.02)
    su, sv = lay.size
    assert su == pytest.approx(0.25 * 0.8) and sv == pytest.approx(0.5 * 0.5)
    assert lay.offsets[0, 0] == pytest.approx(0.01 + 0.1 * 0.25)
    assert lay.offsets[0, 1] == pytest.approx(-0.02 + 0.25 * 0.5)


def test_hexagons_interlock_and_tile_the_domain_exactly():
    n, m = 6, 8
    lay = make_layout("hex", n, m)
    su, sv = lay.size
    # a pointy-top hexagon covers 3/4 of its bounding box: n*m of them cover [0,1]^2 once
    assert n * m * su * sv * 0.75 == pytest.approx(1.0)
    odd = lay.offsets[m // 2 * n:m // 2 * n + n, 0] if (m // 2) % 2 else lay.offsets[n:2 * n, 0]
    assert np.allclose((odd * n) % 1, 0.5)   # odd rows shifted by half a cell
    rows = np.unique(np.round(lay.offsets[:, 1] + sv / 2, 9))
    assert np.allclose(np.diff(rows), 1 / m)  # row pitch = 3/4 of the hexagon height
    assert np.diff(rows)[0] == pytest.approx(0.75 * sv)


def test_multi_tile_layouts():
    alt = make_layout("alternate", 4, 4, n_tiles=2)
    assert alt.tile_index.reshape(4, 4).tolist() == [[0, 1, 0, 1], [1, 0, 1, 0]] * 2
    pat = make_layout("alternate", 4, 2, n_tiles=3, pattern=[[2, 0]])
    assert pat.tile_index.tolist() == [2, 0, 2, 0] * 2
    r1 = make_layout("random", 10, 10, n_tiles=3, seed=4)
    r2 = make_layout("random", 10, 10, n_tiles=3, seed=4)
    r3 = make_layout("random", 10, 10, n_tiles=3, seed=5)
    assert np.array_equal(r1.tile_index, r2.tile_index)
    assert not np.array_equal(r1.tile_index, r3.tile_index)
    assert set(r1.tile_index.tolist()) == {0, 1, 2}


@pytest.mark.parametrize("kwargs, match", [
    (dict(kind="spiral"), "layout"),
    (dict(tiles_u=0), "tiles_u"),
    (dict(tiles_v=2.5), "tiles_v"),
    (dict(gap_u=1.0), "gap_u"),
    (dict(gap_v=-0.1), "gap_v"),
    (dict(u0=float("nan")), "u0"),
])
def test_bad_layout_parameters(kwargs, match):
    args = dict(kind="rect", tiles_u=4, tiles_v=4)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        make_layout(**args)


def test_one_cell_layout_and_one_entry_pattern():
    lay = make_layout("rect", 1, 1)
    assert lay.count == 1 and lay.size == (1.0, 1.0) and lay.offsets.tolist() == [[0.0, 0.0]]
    alt = make_layout("alternate", 3, 2, n_tiles=2, pattern=[[1]])
    assert alt.tile_index.tolist() == [1] * 6


def test_hex_rows_alternate_their_shift_and_gaps_shrink_hexagons():
    """Row j of a hex layout is shifted by half a cell when j is odd (every row, not only
    row 1); gaps shrink each hexagon inside its cell, centred: su = cu (1 - gap_u),
    sv = (4/3) cv (1 - gap_v), the cell's centre kept."""
    n, m, gu, gv = 5, 6, 0.2, 0.1
    lay = make_layout("hex", n, m, gap_u=gu, gap_v=gv)
    cu, cv = 1 / n, 1 / m
    su, sv = lay.size
    assert su == pytest.approx(cu * (1 - gu)) and sv == pytest.approx(cv * 4 / 3 * (1 - gv))
    o = lay.offsets.reshape(m, n, 2)
    for j in range(m):
        centre_u = (np.arange(n) + 0.5 + 0.5 * (j % 2)) * cu
        assert np.allclose(o[j, :, 0] + su / 2, centre_u), j
        assert np.allclose(o[j, :, 1] + sv / 2, (j + 0.5) * cv), j


def test_layout_messages_and_the_default_seed():
    """The messages name the parameter whole; ``random`` draws with seed 0 by default (the
    documented default of ``seed``)."""
    import re

    for name in ("u0", "v0"):
        with pytest.raises(ValueError, match=f"^ddm: '{name}' must be finite, got nan$"):
            make_layout("rect", 2, 2, **{name: float("nan")})
    with pytest.raises(ValueError, match="'tiles_v'"):
        make_layout("rect", 2, 0)
    with pytest.raises(ValueError, match="^" + re.escape(
            "ddm: 'pattern' must be rows of tile indices in 0..1") + "$"):
        make_layout("alternate", 2, 2, n_tiles=2, pattern=[[0, 2]])
    a = make_layout("random", 8, 8, n_tiles=3)
    assert np.array_equal(a.tile_index, make_layout("random", 8, 8, n_tiles=3, seed=0).tile_index)
    assert not np.array_equal(a.tile_index, make_layout("random", 8, 8, n_tiles=3, seed=1).tile_index)
