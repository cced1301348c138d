"""Parameter transforms: every optimiser value maps to a value a user may pass back."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from brdffit.models._restrict import make_neutral
from hypothesis import given, settings
from hypothesis import strategies as st

from brdffit import ParameterError, models
from brdffit.parameters import Parameter
from tests.cases import CASES
from tests.helpers import random_pairs

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


def _with_neutral(case):
    m, _ = case.build()
    return [q.name for q in m.parameters if q.neutral is not None]


NEUTRAL_CASES = [c for c in CASES if _with_neutral(c)]


@pytest.mark.parametrize("case", NEUTRAL_CASES, ids=lambda c: c.id)
def test_pinning_every_neutral_parameter_is_the_base_at_those_values(case):
    m, p = case.build()
    names = _with_neutral(case)
    pinned = make_neutral(m, names)
    assert [q.name for q in pinned.parameters] == [
        q.name for q in m.parameters if q.name not in names
    ]
    wi, wo = random_pairs(2, 32)
    at = {**p, **{q.name: jnp.full(q.shape, q.neutral) for q in m.parameters if q.name in names}}
    got = pinned.eval({k: v for k, v in p.items() if k not in names}, wi, wo)
    assert np.array_equal(np.asarray(got), np.asarray(m.eval(at, wi, wo)))


def test_the_neutral_f0_of_disney_and_filament_is_the_common_dielectric():
    # Disney: F0 = 0.08 specular; Filament: f0 = 0.16 reflectance^2; IOR 1.5 gives
    # ((1.5 - 1) / (1.5 + 1))^2 = 0.04
    f0 = ((1.5 - 1.0) / (1.5 + 1.0)) ** 2
    assert math.isclose(0.08 * models.get("disney").parameter("specular").neutral, f0)
    assert math.isclose(0.16 * models.get("filament").parameter("reflectance").neutral ** 2, f0)
    assert models.get("walter").parameter("f0").neutral == pytest.approx(f0)


def test_a_neutral_value_outside_the_bounds_is_a_typed_error():
    with pytest.raises(ParameterError, match="'x': neutral 2.0 outside bounds"):
        Parameter("x", (), (0.0, 1.0), 0.5, "logit", "a fraction", neutral=2.0)
