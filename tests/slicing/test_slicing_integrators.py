"""The numbers of ``python -m mi_displace.slicing.integrators`` on images whose answers are
known: the mean ratio over the pixels the truth covers (the sky excluded), the exactly
black pixels where the truth is lit, and the AOV errors."""
import numpy as np
import pytest

from mi_displace.slicing.integrators import SKY, compare


def test_compare_counts_what_the_docs_table_states():
    truth = np.full((4, 4, 3), SKY)
    truth[:2] = 0.5                                  # 8 covered pixels
    img = truth.copy()
    img[0] = 0.25                                    # half as bright on 4 of them
    img[1, 0] = 0.0                                  # one of the others black
    img[3, 3] = 0.0                                  # sky black: lit in the truth too
    row = compare(img, truth, aov=False)
    assert row["covered"] == 8
    assert row["mean_ratio"] == pytest.approx((4 * 0.25 + 3 * 0.5) / (8 * 0.5))
    assert row["black_where_truth_lit"] == 2


def test_compare_aov_depth_and_normal_errors():
    truth = np.zeros((2, 2, 4))
    truth[..., 0], truth[..., 3] = 2.0, 1.0          # depth 2, normal +z everywhere
    img = truth.copy()
    img[0, 0, 0] = 0.0                               # one pixel sees nothing
    img[1, 1, 0] = 3.0                               # one a unit too far ...
    img[1, 1, 1:4] = [1.0, 0.0, 0.0]                 # ... with a normal 90 degrees off
    row = compare(img, truth, aov=True)
    assert row["coverage"] == 0.75 and row["coverage_truth"] == 1.0
    assert row["depth_error"] == pytest.approx(1 / 3)
    assert row["normal_error_deg"] == pytest.approx(30.0)
