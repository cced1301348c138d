"""Generic properties of every model row in ``cases.CASES``.

Independent of any implementation: positivity, zero below the horizon, reciprocity
(where the model claims it), invariance under rotation about the normal for
isotropic models, finite values and gradients on extreme directions and at the
parameter bounds in float32 and float64, and jit/vmap agreement.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from brdffit.models.check import check_params
from tests.cases import CASES
from tests.helpers import params_at_bounds, random_pairs, random_params, rotate_z

IDS = [c.id for c in CASES]


def _option_rows_slow() -> list:
    """CASES with every row but each model's first marked ``slow``, for the two tests that
    compile a program per row (and dtype): the extremes and jit/vmap checks of the option
    rows took about 150 s of the default suite's CPU time. The default suite keeps each
    model's base form at the extremes and bounds in both precisions, and every option
    row in the cheaper tests of this file (positivity, reciprocity, rotation, float32
    against float64) and in its model's reference tests; ``benchmarks/slow_checks.sh``
    runs the rest."""
    seen, out = set(), []
    for c in CASES:
        slow = c.model in seen
        out.append(pytest.param(c, id=c.id, marks=pytest.mark.slow if slow else ()))
        seen.add(c.model)
    return out


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_positive_and_zero_below_horizon(case):
    model, params = case.build()
    # 256 pairs, as the rotation and float32 tests below: the operations compiled for this
    # model's op-by-op evaluation serve them too (SGD and STD compile for seconds)
    wi, wo = random_pairs(0, 256)
    f = np.asarray(model.eval(params, wi, wo))
    assert np.all(np.isfinite(f)) and np.all(f >= 0)
    below = wo * np.array([1, 1, -1])
    assert np.all(np.asarray(model.eval(params, wi, below)) == 0)
    assert np.all(np.asarray(model.eval(params, below, wo)) == 0)


@pytest.mark.parametrize("case", CASES, ids=IDS)
# 4 draws x 88 rows (8 took 53 s of the suite): a term that is not symmetric in wi and wo
# shows at any parameter value, and every option row is drawn
@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_reciprocity_under_random_parameters(case, seed):
    model, _ = case.build()
    if not model.reciprocal:
        pytest.skip(f"{model.name} is not reciprocal (see its docstring)")
    rng = np.random.default_rng(seed)
    params = random_params(model, rng)
    wi, wo = random_pairs(seed, 64)
    a = np.asarray(model.eval(params, wi, wo))
    b = np.asarray(model.eval(params, wo, wi))
    # float64 evaluation; relative 1e-9 leaves room for a few reassociated operations.
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_isotropic_models_ignore_rotation_about_normal(case):
    model, params = case.build()
    if not model.isotropic:
        pytest.skip("anisotropic by construction")
    wi, wo = random_pairs(1, 256)
    a = np.asarray(model.eval(params, wi, wo))
    b = np.asarray(model.eval(params, rotate_z(wi, 0.7), rotate_z(wo, 0.7)))
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("which", ["case", "low", "high"])
@pytest.mark.parametrize("case", _option_rows_slow())
def test_extremes_finite_value_and_gradient(case, which, dtype):
    """brdffit.models.check on the extreme pairs: finite, non-negative f and finite d sum(f)/dp."""
    model, params = case.build()
    if which != "case":
        params = params_at_bounds(model, which)
    row = check_params(model, params, dtype, which)
    assert row.passed, row


@pytest.mark.parametrize("case", _option_rows_slow())
def test_jit_and_vmap_agree_with_eager(case):
    model, params = case.build()
    wi, wo = random_pairs(2, 16)
    eager = model.eval(params, wi, wo)
    jitted = jax.jit(model.eval)(params, wi, wo)
    one = jax.vmap(lambda a, b: model.eval(params, a[None], b[None])[0])(
        jnp.asarray(wi), jnp.asarray(wo)
    )
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(eager), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(one), np.asarray(eager), rtol=1e-12)


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_float32_matches_float64(case):
    model, params = case.build()
    wi, wo = random_pairs(3, 256)
    f64 = np.asarray(model.eval(params, wi, wo))
    f32 = np.asarray(model.eval(params, wi.astype(np.float32), wo.astype(np.float32)))
    assert f32.dtype == np.float32
    # float32 has 24 bits; 1e-4 relative covers exponent amplification (n log cos) in lobes.
    np.testing.assert_allclose(f32, f64, rtol=1e-4, atol=1e-6 * float(np.max(f64)))
