"""errors="blocks": the cluster jackknife over (theta_h, theta_d) blocks.

Checked by simulation against the spread of the estimates themselves: Lambert data whose
noise is shared by every sample of a 10-degree (theta_h, theta_d) block (the shape of
model error on measured data) make the per-sample sandwich far too narrow, while the
block errors match the standard deviation of the estimates over repeated data sets.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import Measurements, ParameterError, fit_many, models
from brdffit.core.result_terms import BLOCK_DEG
from brdffit.engine.metrics import get_metric, keep_mask, prepare
from brdffit.engine.objective import Objective, block_moments, natural_moments
from brdffit.engine.uncertainty import block_covariance, block_index
from tests.helpers import random_pairs

WI, WO = random_pairs(11, 4000)
KD = np.array([0.2, 0.4, 0.6])


def _datasets(n: int, seed: int) -> list[Measurements]:
    """Lambert values with block-shared relative noise (5%) plus independent noise (1%)."""
    ones = Measurements.from_directions(WI, WO, np.ones((len(WI), 3)))
    keep = np.flatnonzero(keep_mask(ones, None))
    ids, g = block_index(prepare(ones, get_metric("ngan"), cut_deg=None))
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        shared = 0.05 * rng.standard_normal((g, 3))[ids]
        own = 0.01 * rng.standard_normal((len(ids), 3))
        f = np.broadcast_to(KD / np.pi, (len(WI), 3)).copy()
        f[keep] *= 1.0 + shared + own
        out.append(Measurements.from_directions(WI, WO, f, source=f"blocks {i}"))
    return out


def test_block_errors_match_the_spread_of_estimates_and_sandwich_does_not():
    data = _datasets(120, seed=3)
    model = models.get("lambert")
    blocks = fit_many(model, data, "ngan", errors="blocks", cut_deg=None)
    plain = fit_many(model, data, "ngan", errors="sandwich", cut_deg=None)
    est = np.array([r.params["kd"] for r in blocks])
    spread = est.std(axis=0, ddof=1)
    se_blocks = np.mean([r.stderr["kd"] for r in blocks], axis=0)
    se_plain = np.mean([r.stderr["kd"] for r in plain], axis=0)
    # 120 data sets: the sample sd is within ~13% of the truth (2 sigma); the blocks'
    # small-sample factor keeps the mean stderr within a few % of the sd for ~60 blocks.
    np.testing.assert_allclose(se_blocks / spread, 1.0, atol=0.25)
    assert np.all(se_plain / spread < 0.5)  # the independent-residual sandwich: overconfident
    inside = np.abs(est - KD) <= 1.96 * np.array([r.stderr["kd"] for r in blocks])
    assert 0.88 <= inside.mean() <= 0.99, inside.mean()
    assert all(r.error_blocks == blocks[0].error_blocks > 20 for r in blocks)
    assert "blocks" in blocks[0].report() and f"{BLOCK_DEG:g}-degree" in blocks[0].report()


def test_blocks_are_occupied_cells_of_the_theta_h_theta_d_grid():
    ones = Measurements.from_directions(WI, WO, np.ones((len(WI), 3)))
    prep = prepare(ones, get_metric("ngan"), cut_deg=None)
    ids, g = block_index(prep)
    th = np.degrees(np.arccos(np.asarray(prep.g.cos_h)))
    td = np.degrees(np.arccos(np.asarray(prep.g.cos_d)))
    assert ids.min() == 0 and ids.max() == g - 1 and len(np.unique(ids)) == g
    for b in range(g):  # one block never spans more than one 10 x 10 degree cell
        assert np.ptp(np.floor(th[ids == b] / BLOCK_DEG)) == 0
        assert np.ptp(np.floor(td[ids == b] / BLOCK_DEG)) == 0


def test_unknown_errors_kind_is_named():
    with pytest.raises(ParameterError, match="errors='bootstrap'.*blocks"):
        fit_many(models.get("lambert"), _datasets(1, 0), "ngan", errors="bootstrap")


def test_block_errors_equal_refits_leaving_each_block_out_for_a_linear_model():
    """Lambert under ngan is linear in kd: the one-step jackknife (errors="blocks", power 1
    of the leverage correction) is exact there, so it must equal (G-1)/G sum_b d_b d_b^T
    with d_b the move of a real refit without block b (weight 0: every refit keeps its
    sample count)."""
    data = _datasets(1, seed=5)[0]
    model = models.get("lambert")
    r = fit_many(model, [data], "ngan", errors="blocks", cut_deg=None)[0]
    prep = prepare(data, get_metric("ngan"), cut_deg=None)
    ids, g = block_index(prep)
    obj = Objective.build(model)
    z = jnp.asarray(obj.layout.solver_vector(r.params))
    jtj = np.asarray(natural_moments(obj, z, prep)[0])
    scores, grams = (np.asarray(a) for a in block_moments(obj, z, prep, jnp.asarray(ids), g))
    cr3, _ = block_covariance(jtj, scores, grams)
    cr2, _ = block_covariance(jtj, scores, grams, power=0.5)
    np.testing.assert_allclose(cr3, r.covariance, rtol=1e-12)
    keep = np.flatnonzero(keep_mask(data, None))
    left_out = []
    for b in range(g):
        w = data.weights.copy()
        w[keep[ids == b]] = 0.0
        left_out.append(Measurements.from_directions(data.wi, data.wo, data.values, weights=w))
    refits = fit_many(model, left_out, "ngan", cut_deg=None)
    moves = np.array([q.params["kd"] for q in refits]) - r.params["kd"]
    np.testing.assert_allclose(cr3, (g - 1) / g * moves.T @ moves, rtol=1e-6)
    assert np.all(np.diag(cr2) < np.diag(cr3))  # CR2 corrects the leverage half as much
