"""The bounded LM solver against its definitions and against scipy's trf.

The answer of a descent must be a first-order Karush-Kuhn-Tucker point of the box
(inside it; zero gradient on free scalars; gradient pointing out on held ones), and
from the same start it must end no higher than scipy's ``least_squares`` on the same
residual (an independent implementation of a bounded trust-region method).
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import least_squares

from brdffit import Measurements, models, synthesize
from brdffit.engine import lm, metrics, race
from brdffit.engine.objective import Objective, plain_residuals

TRUTH = {"kd": [0.1, 0.2, 0.3], "ks": [0.8, 0.7, 0.9], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}


def _solve(obj: Objective, z0, prep, **tol):
    lo, hi = (jnp.asarray(a) for a in obj.layout.solver_bounds())
    return lm.solve_one(obj, jnp.asarray(z0), prep, lo, hi, lm.Tolerances(**tol))


def _kkt(obj: Objective, d, prep) -> None:
    lo, hi = obj.layout.solver_bounds()
    z = np.asarray(d.z)
    assert np.all(z >= lo) and np.all(z <= hi)
    cost, g, h = (np.asarray(a) for a in obj.linearize(jnp.asarray(z), prep))
    scale = np.sqrt(np.diag(h) * 2 * cost)  # MINPACK's |J_i| |r|
    on_lo, on_hi = z <= lo, z >= hi
    inside = ~(on_lo | on_hi)
    # free scalars: the gradient is orthogonal to the residuals to 1e-5. gtol is 1e-10,
    # but a descent may stop on ftol = 1e-10 instead: a cost within 1e-10 (relative) of a
    # quadratic minimum leaves a gradient ratio of about sqrt(1e-10) = 1e-5.
    assert np.all(np.abs(g[inside]) <= 1e-5 * scale[inside]), g / scale
    assert np.all(g[on_lo] >= 0) and np.all(g[on_hi] <= 0), (g, on_lo, on_hi)


@pytest.mark.parametrize("metric", ["low_e2", "ngan"])
def test_noisy_walter_ends_at_a_kkt_point_no_higher_than_scipy(metric):
    walter = models.get("walter")
    data = synthesize(walter, TRUTH, stride=(5, 5, 5), noise_mult=0.05, seed=3)
    prep = metrics.prepare(data, metrics.get_metric(metric))
    obj = Objective.build(walter)
    z0 = obj.layout.solver_vector(walter.defaults())
    d = _solve(obj, z0, prep)
    assert lm.Reason(int(d.reason)).converged, lm.Reason(int(d.reason))
    _kkt(obj, d, prep)

    lo, hi = obj.layout.solver_bounds()
    ref = least_squares(
        lambda z: np.asarray(plain_residuals(obj, jnp.asarray(z), prep)),
        np.asarray(z0),
        bounds=(lo, hi),
        method="trf",
        x_scale="jac",
        ftol=1e-12,
        xtol=1e-12,
        gtol=1e-12,
    )
    ours, theirs = float(d.cost), 0.5 * float(ref.fun @ ref.fun)
    print(f"{metric}: cost {ours:.15g} (brdffit, {int(d.steps)} steps), {theirs:.15g} (scipy)")
    assert ours <= theirs * (1 + 1e-9)


def test_an_optimum_outside_the_box_ends_on_the_bound_with_an_outward_gradient():
    # Lambert data 1.5x brighter than kd = 1 allows: the unconstrained optimum is 1.5.
    lam = models.get("lambert")
    bright = synthesize(lam, {"kd": 1.0}, grid="random", n=3000, seed=0)
    data = Measurements.from_directions(bright.wi, bright.wo, bright.values * 1.5)
    prep = metrics.prepare(data, metrics.get_metric("low_e2"))
    obj = Objective.build(lam)
    d = _solve(obj, obj.layout.solver_vector({"kd": jnp.full(3, 0.3)}), prep)
    np.testing.assert_array_equal(np.asarray(d.z), 1.0)  # exactly on the bound
    assert np.all(np.asarray(d.binding)) and lm.Reason(int(d.reason)).converged
    _kkt(obj, d, prep)


def test_a_robust_descent_minimises_the_robust_objective():
    # IRLS inside the solver: the gradient it drives to zero is that of 0.5 sum rho.
    walter = models.get("walter")
    clean = synthesize(walter, TRUTH, stride=(9, 9, 9), noise_mult=0.02, seed=4)
    values = clean.values.copy()
    hit = np.random.default_rng(5).choice(len(values), len(values) // 100, replace=False)
    values[hit] *= 100.0
    data = Measurements.from_directions(clean.wi, clean.wo, values, weights=clean.weights)
    prep = metrics.prepare(data, metrics.get_metric("low_e2"))
    obj = Objective.build(walter, robust="cauchy", scale=0.01)
    d = _solve(obj, obj.layout.solver_vector(TRUTH), prep)
    assert lm.Reason(int(d.reason)).converged
    _kkt(obj, d, prep)


def test_max_steps_counts_tried_steps():
    walter = models.get("walter")
    data = synthesize(walter, TRUTH, stride=(9, 9, 9))
    prep = metrics.prepare(data, metrics.get_metric("low_e2"))
    obj = Objective.build(walter)
    d = _solve(obj, obj.layout.solver_vector(walter.defaults()), prep, max_steps=2)
    assert int(d.steps) == 2 and lm.Reason(int(d.reason)) is lm.Reason.MAX_STEPS


class _LeastSquares(eqx.Module):
    """A plain residual function seen as the solver sees an Objective (no data)."""

    fn: Callable = eqx.field(static=True)

    def cost(self, z, prep=None):
        r = self.fn(z)
        return 0.5 * r @ r

    def linearize(self, z, prep=None):
        r, j = self.fn(z), jax.jacfwd(self.fn)(z)
        return 0.5 * r @ r, j.T @ r, j.T @ j


def _brown_dennis(z):
    t = jnp.arange(1, 21) / 5.0
    return (z[0] + t * z[1] - jnp.exp(t)) ** 2 + (z[2] + z[3] * jnp.sin(t) - jnp.cos(t)) ** 2


def _jennrich_sampson(z):
    i = jnp.arange(1, 11.0)
    return 2 + 2 * i - (jnp.exp(i * z[0]) + jnp.exp(i * z[1]))


@pytest.mark.parametrize(
    ("fn", "z0", "published"),
    [
        (_brown_dennis, [25.0, 5.0, -5.0, -1.0], "85822.2"),
        (_jennrich_sampson, [0.3, 0.4], "124.362"),
    ],
    ids=["brown_dennis", "jennrich_sampson"],
)
def test_large_residual_problems_reach_the_published_minimum_without_crawling(fn, z0, published):
    # Moré, Garbow & Hillstrom (1981), problems 16 and 6: sums of squares that stay large
    # at the minimum, so Gauss-Newton's matrix misses most of the curvature. Plain
    # Levenberg-Marquardt (this solver without its secant term) crawls for 302 steps on
    # Brown and Dennis's function; with the augmented model it takes 55: at most a third
    # of plain LM's is asked.
    k = len(z0)
    inf = jnp.full(k, jnp.inf)
    d = lm.solve_one(_LeastSquares(fn), jnp.asarray(z0), None, -inf, inf, lm.Tolerances())
    assert lm.Reason(int(d.reason)).converged
    # the sum of squares 2 C, to the digits published (half a unit of the last one)
    half_unit = 0.5 * 10.0 ** -len(published.split(".")[1])
    assert abs(2 * float(d.cost) - float(published)) <= half_unit, 2 * float(d.cost)
    assert int(d.steps) <= 100, int(d.steps)


def test_an_undershooting_gauss_newton_model_gives_way_to_the_augmented_one():
    # r = (z - 1, R - k z^2 / 2): the large second residual's curvature takes curvature
    # away (S = -k R = -1/2 against J^T J ~ 1), so each Gauss-Newton step is accepted
    # with a gain ratio near 1.5 and the error only halves a step; plain LM stops on the
    # cost test 2e-5 short of the minimum after 15 steps. The minimum is the real root of
    # k^2 z^3 / 2 + (1 - k R) z - 1 = 0 (the gradient).
    big, k = 10.0, 0.05
    roots = np.roots([0.5 * k * k, 0.0, 1.0 - k * big, -1.0])
    z_star = float(roots[np.abs(roots.imag) < 1e-12].real[0])
    fn = lambda z: jnp.array([z[0] - 1.0, big - 0.5 * k * z[0] ** 2])  # noqa: E731
    inf = jnp.full(1, jnp.inf)
    d = lm.solve_one(_LeastSquares(fn), jnp.zeros(1), None, -inf, inf, lm.Tolerances())
    assert lm.Reason(int(d.reason)).converged
    assert abs(float(d.z[0]) - z_star) <= 1e-7 * z_star, (float(d.z[0]), z_star)
    assert int(d.steps) <= 8, int(d.steps)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 6))
def test_the_secant_update_meets_its_secant_condition(seed, k):
    # Dennis-Gay-Welsch: the updated S is symmetric and maps the step to y# = g+ - g - H+ s
    # (after sizing); a step with y.s <= 0 leaves S as it was.
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(k, k))
    curv, h1 = a + a.T, a @ a.T + np.eye(k)
    sz, g0 = rng.normal(size=k), rng.normal(size=k)
    g1 = g0 + (h1 + np.eye(k)) @ sz  # y = g1 - g0 with y.s > 0
    new = np.asarray(lm._secant(*(jnp.asarray(v) for v in (curv, sz, g0, g1, h1))))
    np.testing.assert_allclose(new, new.T, atol=1e-12)
    np.testing.assert_allclose(new @ sz, g1 - g0 - h1 @ sz, rtol=1e-9, atol=1e-9)
    g1 = g0 - (h1 + np.eye(k)) @ sz  # y.s < 0: no update
    same = np.asarray(lm._secant(*(jnp.asarray(v) for v in (curv, sz, g0, g1, h1))))
    np.testing.assert_array_equal(same, curv)


@settings(max_examples=50, deadline=None)
@given(st.integers(1, 40), st.integers(1, 600))
def test_successive_halving_keeps_a_third_with_three_times_the_steps(n_starts, max_steps):
    sched = race.rungs(n_starts, max_steps)
    keeps, budgets = [k for k, _ in sched], [b for _, b in sched]
    assert keeps[0] == n_starts and budgets[-1] == max_steps
    assert budgets[0] == (race.RUNG_STEPS if len(sched) > 1 else max_steps)
    for (k0, b0), (k1, b1) in zip(sched, sched[1:], strict=False):
        assert k1 == -(-k0 // race.RUNG_GROWTH)
        assert b1 == (race.RUNG_GROWTH * b0 if b1 < max_steps else max_steps) and b1 > b0
    # the race ends with one start, unless the step budget ran out first
    assert keeps[-1] == 1 or budgets[-1] == max_steps


def test_the_lowest_raced_start_descends_as_it_would_alone():
    # Brown and Dennis's function from starts spread over a wide box: the race drops the
    # costlier ones at each rung; the one it keeps must end where its own descent ends,
    # step for step, and every dropped one must have stopped within its rung's budget.
    rng = np.random.default_rng(0)
    z0 = jnp.asarray(np.array([25.0, 5.0, -5.0, -1.0]) + rng.normal(0, 10, (7, 4)))
    inf, tol = jnp.full(4, jnp.inf), lm.Tolerances()
    problem = _LeastSquares(_brown_dennis)
    d = race.race_one(problem, z0, None, -inf, inf, tol, None)
    best = int(np.argmin(np.asarray(d.cost)))
    alone = lm.solve_one(problem, z0[best], None, -inf, inf, tol)
    assert lm.Reason(int(d.reason[best])).converged
    assert int(d.steps[best]) == int(alone.steps)
    np.testing.assert_allclose(float(d.cost[best]), float(alone.cost), rtol=1e-12)
    sched = race.rungs(7, tol.max_steps)
    dropped = np.asarray(d.reason) == lm.Reason.RUNNING
    # the budget as an input of the program (as fit passes it) runs the same schedule,
    # also when it cuts the halving short (rungs(7, 20): 8 steps, then the best 3 to 20)
    for t in (tol, lm.Tolerances(max_steps=20)):
        static = race.race_one(problem, z0, None, -inf, inf, t, None)
        given = race.race_one(problem, z0, None, -inf, inf, t.as_inputs(), None)
        for a, b in zip(jax.tree.leaves(static), jax.tree.leaves(given), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert dropped.sum() >= 7 - sched[1][0]  # the first cut dropped 4 of 7
    assert np.all(np.asarray(d.steps)[dropped] <= sched[-2][1])
