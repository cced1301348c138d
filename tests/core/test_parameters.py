"""Parameter transforms: every optimiser value maps to a value a user may pass back."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from brdffit import ParameterError, models
from brdffit.core.parameters import Parameter
from brdffit.models._restrict import make_neutral
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


def _low_layout(freeze=None):
    from brdffit.engine.objective import Objective

    return Objective.build(models.get("low"), freeze).layout


@settings(max_examples=40, deadline=None)
@given(
    b=st.floats(0.1, 1e8),
    c=st.floats(1e-3, 10.0),
)
def test_a_product_pair_is_solved_as_log_product_and_reciprocal(b, c):
    # Löw's C names B in product_with: the solver sees (ln BC, 1/C), and the map goes back
    lay = _low_layout()
    i, j = lay.pairs()[0]
    assert [lay.labels()[i], lay.labels()[j]] == ["B", "C"]
    params = models.get("low").defaults() | {"B": b, "C": c}
    z = lay.solver_vector(params)
    assert z[i] == pytest.approx(math.log(b * c), rel=1e-12, abs=1e-12)
    assert z[j] == pytest.approx(1.0 / c, rel=1e-12)
    np.testing.assert_allclose(
        np.asarray(lay.to_solver(jnp.asarray(lay.natural_vector(params)))),
        z,
        rtol=1e-12,
        atol=1e-12,
    )
    back = lay.params(jnp.asarray(z), "solver")
    # the flat inverse (the covariance's natural Jacobian) agrees with the dict one
    np.testing.assert_allclose(
        np.asarray(lay.from_solver(jnp.asarray(z))), lay.natural_vector(back), rtol=1e-15
    )
    assert float(back["B"]) == pytest.approx(b, rel=1e-12)
    assert float(back["C"]) == pytest.approx(c, rel=1e-12)
    lo, hi = lay.solver_bounds()
    assert lo[i] <= z[i] <= hi[i] and lo[j] <= z[j] <= hi[j]


@settings(max_examples=20, deadline=None)
@given(bc=st.lists(st.tuples(st.floats(0.1, 1e8), st.floats(1e-3, 10.0)), min_size=1, max_size=5))
def test_solver_rows_are_each_row_mapped_by_to_solver(bc):
    # many starts packed at once on the host (the pair included) against the traced map
    lay = _low_layout()
    rows = [models.get("low").defaults() | {"B": b, "C": c} for b, c in bc]
    expected = [np.asarray(lay.to_solver(jnp.asarray(lay.natural_vector(p)))) for p in rows]
    np.testing.assert_allclose(lay.solver_rows(rows), np.stack(expected), rtol=1e-12, atol=1e-12)
    assert lay.solver_rows([]).shape == (0, lay.size)


def test_a_pair_keeps_its_partner_inside_its_bounds_and_splits_when_one_is_frozen():
    lay = _low_layout()
    i, j = lay.pairs()[0]
    lo, hi = lay.solver_bounds()
    assert (lo[i], hi[i]) == pytest.approx((math.log(0.1 * 1e-3), math.log(1e8 * 10.0)))
    assert (lo[j], hi[j]) == pytest.approx((0.1, 1000.0))
    # the box's corner (BC = 1e9, 1/C = 1000) asks for B = 1e12: B is held at 1e8
    z = lay.solver_vector(models.get("low").defaults())
    z[i], z[j] = hi[i], hi[j]
    x = lay.params(jnp.asarray(z), "solver")
    assert float(x["B"]) == 1e8 and float(x["C"]) == pytest.approx(1e-3)
    # with B frozen, C is an ordinary log-scale parameter again
    frozen = _low_layout({"B": 5.0})
    assert frozen.pairs() == ()
    assert frozen.solver_vector({"kd": [0.3] * 3, "ks": [0.2] * 3, "C": 2.0, "eta": 1.5})[
        frozen.labels().index("C")
    ] == pytest.approx(math.log(2.0))


def test_product_with_needs_a_positive_scalar():
    with pytest.raises(ParameterError, match="product_with"):
        Parameter("C", (3,), (1e-3, 10.0), 1.0, "log", "x", product_with="B")
    with pytest.raises(ParameterError, match="product_with"):
        Parameter("C", (), (0.0, 10.0), 1.0, "logit", "x", product_with="B")


@settings(max_examples=25, deadline=None)
@given(b=st.floats(0.1, 1e8), c=st.floats(1e-3, 10.0), kd=st.floats(0.01, 0.9))
def test_the_solver_jacobian_is_the_derivative_of_to_solver(b, c, kd):
    # a pair (Löw's B, C), log scales and plain scalars: d z / d x against JAX's
    lay = _low_layout()
    params = models.get("low").defaults() | {"B": b, "C": c, "kd": [kd, 0.5 * kd, 0.2]}
    x = lay.natural_vector(params)
    want = np.asarray(jax.jacfwd(lay.to_solver)(jnp.asarray(x)))
    np.testing.assert_allclose(lay.solver_jacobian(x), want, rtol=1e-12, atol=1e-300)
