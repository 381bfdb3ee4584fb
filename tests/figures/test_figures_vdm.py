"""The VDM figure's sweep points (one tradeoff over explicit points): every term pair and
every table size once, the paper's sizes shared between the two tables."""
from mi_displace.figures import vdm as figures


def test_sweep_points_cover_each_value_once():
    terms, sizes = figures.sweep_points(quick=False)
    pairs = [(p["svd_terms"], p["mvm_terms"]) for p in terms]
    assert len(set(pairs)) == len(pairs)
    assert {(k, min(k, 4)) for k in figures.SVD_TERMS} <= set(pairs)
    assert {(8, k) for k in figures.MVM_TERMS} <= set(pairs)
    assert len(pairs) == len({(k, min(k, 4)) for k in figures.SVD_TERMS}
                             | {(8, k) for k in figures.MVM_TERMS})
    assert [(key, v) for key, v, _ in sizes] == [(key, v) for key, values in
                                                 figures.TABLE_GRID.items() for v in values]
    for key, value, point in sizes:
        if value == figures.TABLE_BASE[key]:   # the paper's table: the shared 8 + 4 point
            assert point == {"svd_terms": 8, "mvm_terms": 4} and point in terms
        else:
            assert point == {key: value}
