"""The robust loss's default scale against scipy's normal-consistent MAD."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import stats

from brdffit.engine.robust import ROBUST_TUNING, default_scale


@settings(max_examples=50, deadline=None)
@given(
    arrays(np.float64, st.integers(3, 200), elements=st.floats(-1e3, 1e3)),
    st.sampled_from(sorted(ROBUST_TUNING)),
)
def test_default_scale_is_the_tuning_constant_times_the_normal_mad(r, kind):
    sigma = stats.median_abs_deviation(r, scale="normal")  # MAD / Phi^-1(3/4)
    if sigma > 0:
        assert default_scale(kind, r) == pytest.approx(ROBUST_TUNING[kind] * sigma, rel=2e-6)
    else:  # more than half the residuals equal: the RMS instead
        rms = np.sqrt(np.mean(r * r))
        assert default_scale(kind, r) == pytest.approx(ROBUST_TUNING[kind] * max(rms, 1e-300))
