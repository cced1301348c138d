"""The helpers of the calibration benchmark (``benchmarks/calibration.py``): the binomial
intervals against scipy, the coverage count, and the canonical lobe order."""

import numpy as np
import pytest
from scipy.stats import binomtest

from benchmarks import calibration as cal


@pytest.mark.parametrize("k, n", [(0, 50), (1, 50), (47, 50), (49, 50), (50, 50), (25, 50), (3, 7)])
def test_binomial_intervals_match_scipy(k, n):
    exact = binomtest(k, n).proportion_ci(confidence_level=0.95, method="exact")
    score = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    # Both are closed forms of beta / normal quantiles: agreement to rounding.
    np.testing.assert_allclose(cal.clopper_pearson(k, n), (exact.low, exact.high), atol=1e-12)
    np.testing.assert_allclose(cal.wilson(k, n), (score.low, score.high), atol=1e-12)


def test_coverage_counts_only_existing_intervals():
    inside = np.array([[True, True], [False, True], [True, False], [True, True]])
    has = np.array([[True, True], [True, True], [True, False], [False, True]])
    c0, c1 = cal.coverage_of(inside, has)
    assert (c0["k"], c0["n"]) == (2, 3)  # row 3 has no interval for scalar 0
    assert (c1["k"], c1["n"]) == (3, 3)  # row 2 has none for scalar 1
    assert c1["lo"] < 1.0 == c1["hi"]


def test_lobes_sorted_by_exponent_carry_their_scalars():
    m = cal._model("lafortune2")
    labs = cal.labels_of(m)
    x = np.arange(len(labs), dtype=float)
    x[labs.index("n_1")] = 100.0  # lobe 1 sharper than lobe 2: swap
    perm, swapped = cal.canonical_perm(m, "n", np.stack([np.arange(len(labs), dtype=float), x]))
    assert swapped.tolist() == [False, True]
    y = np.take_along_axis(np.stack([x, x]), perm, -1)[1]
    assert y[labs.index("n_2")] == 100.0 and y[labs.index("cxy_2")] == x[labs.index("cxy_1")]
    assert y[labs.index("kd[g]")] == x[labs.index("kd[g]")]
