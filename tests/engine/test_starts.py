"""The start policy's screen: Multi-Level Single Linkage against its definitions.

Rinnooy Kan & Timmer (1987, part II) start a local search from a sample point only if
no point of lower cost lies within the critical distance ``r``, chosen so that the ball
of radius ``r`` holds ``sigma ln(n) / n`` of the unit cube.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from brdffit import fit, models, synthesize
from brdffit.engine import lm, starts
from brdffit.io.merl_grid import merl_subgrid


@given(n=st.integers(2, 4096), dim=st.integers(1, 16))
def test_the_critical_ball_holds_sigma_log_n_over_n_of_the_cube(n, dim):
    r = starts.critical_distance(n, dim)
    ball = math.pi ** (dim / 2) * r**dim / math.gamma(1 + dim / 2)  # volume of a d-ball
    assert ball == pytest.approx(starts.MLSL_SIGMA * math.log(n) / n, rel=1e-12)


def _two_valleys() -> tuple[np.ndarray, np.ndarray]:
    """41 points on [0, 1] (spacing 0.025) and a cost with its lowest point at 0.2 and a
    higher valley at 0.8 (indices 8 and 32)."""
    x = np.linspace(0.0, 1.0, 41)
    return x[:, None], np.minimum((x - 0.2) ** 2, (x - 0.8) ** 2 + 0.01)


def test_single_linkage_starts_once_per_valley():
    x, cost = _two_valleys()
    behind = np.asarray(starts.shadowed(jnp.asarray(cost), jnp.asarray(x), 0.1))
    assert set(np.flatnonzero(~behind)) == {8, 32}


def test_single_linkage_merges_valleys_nearer_than_the_distance():
    x, cost = _two_valleys()
    behind = np.asarray(starts.shadowed(jnp.asarray(cost), jnp.asarray(x), 0.7))
    assert set(np.flatnonzero(~behind)) == {8}


def test_equal_costs_do_not_shadow_each_other():
    x = np.array([[0.0], [0.01]])
    behind = np.asarray(starts.shadowed(jnp.ones(2), jnp.asarray(x), 1.0))
    assert not behind.any()


def test_a_start_of_nan_stops_before_any_step():
    class Quadratic:
        def cost(self, z, prep):
            return 0.5 * jnp.sum(z * z)

        def linearize(self, z, prep):
            return self.cost(z, prep), z, jnp.eye(z.size)

    lo, hi = -jnp.ones(2), jnp.ones(2)
    d = lm.solve(Quadratic(), jnp.array([jnp.nan, 0.5]), None, lo, hi, lm.Tolerances())
    assert int(d.steps) == 0 and int(d.reason) == lm.Reason.NONFINITE
    d = lm.solve(Quadratic(), jnp.array([0.5, 0.5]), None, lo, hi, lm.Tolerances())
    assert lm.Reason(int(d.reason)).converged and np.allclose(d.z, 0.0, atol=1e-8)


def test_a_one_dimensional_screen_of_one_valley_gives_one_start():
    """GGX + Lambert without a separate ks has one nonlinear scalar (alpha); its
    screened costs fall to one minimum, so of the screen one start is left, beside the
    first start, its random neighbour and the cross-metric start."""
    model = models.from_spec("walter[specular_weight=false]")
    truth = {"kd": [0.2, 0.1, 0.05], "f0": [0.6, 0.5, 0.4], "alpha": 0.08}
    data = merl_subgrid(synthesize(model, truth, noise_mult=0.03, seed=0), (9, 9, 15))
    for metric in ("low_e2", "ngan"):
        r = fit(model, data, metric)
        assert r.n_starts == 4
        assert r.params["alpha"] == pytest.approx(0.08, rel=0.05)
