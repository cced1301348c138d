"""Parameter transforms: every optimiser value maps to a value a user may pass back."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.cases import CASES

SATURATING = sorted(
    {
        (p.name, p.bounds, p.transform): p
        for case in CASES
        for p in case.build()[0].parameters
        if p.saturates
    }.values(),
    key=lambda p: (p.name, p.bounds, p.transform),
)


@pytest.mark.parametrize("param", SATURATING, ids=lambda p: f"{p.name}{list(p.bounds)}")
@settings(max_examples=60, deadline=None)
@given(u=st.floats(-1e3, 1e3, allow_nan=False))
def test_a_saturating_transform_never_leaves_its_bounds(param, u):
    x = np.asarray(param.to_natural(jnp.full(param.shape, u)))
    lo, hi = param.bounds
    assert np.all(x >= lo) and np.all(x <= hi), (u, x.tolist())
    # what a fit reports can be its next start: before the clamp, a bounded log on
    # [0.001, 10] gave 10.000000000000009 at u = 36.75, which check_value refused
    param.check_value(x)
