"""The Dr.Jit baker against a second implementation (trimesh + Embree) on the same rays."""
import numpy as np

from mi_displace.bake.baker import bake
from mi_displace.bake.naive import naive_bake
from mi_displace.bake.trace import OK


def test_same_displacement_as_naive_baker(sphere_pair):
    high, low = sphere_pair
    max_d, delta = 0.2, 1e-5
    for aa in (1, 2):
        ours = bake(high, low, res=64, aa=aa, max_distance=max_d, delta=delta, pad=0,
                    conservative=False)
        ref = naive_bake(high, low, 64, max_d, delta, aa=aa)
        both = (ours.status == OK) & np.isfinite(ref)
        assert both.sum() > 0.9 * (ours.status == OK).sum()
        assert np.isfinite(ref).sum() == (ours.status == OK).sum()
        np.testing.assert_allclose(ours.maps["displacement"][both], ref[both], atol=2e-6)
