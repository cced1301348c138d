"""errors="blocks": the cluster sandwich (CR2) over (theta_h, theta_d) blocks, with
Student-t intervals on Bell and McCaffrey's degrees of freedom.

Checked by simulation against the spread of the estimates themselves: Lambert data whose
noise is shared by every sample of a 10-degree (theta_h, theta_d) block (the shape of
model error on measured data) make the per-sample sandwich far too narrow, while the
block errors match the standard deviation of the estimates over repeated data sets.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import Measurements, ParameterError, fit_many, models, synthesize
from brdffit.core.result_terms import BLOCK_DEG
from brdffit.engine.block_errors import (
    BlockChunks,
    block_covariance,
    block_index,
    coverage_factor,
    effective_dof,
)
from brdffit.engine.metrics import get_metric, keep_mask, prepare
from brdffit.engine.objective import Objective, block_moments, natural_moments
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
    """Lambert under ngan is linear in kd: the one-step jackknife (power 1 of the leverage
    correction, CR3) is exact there, so it must equal (G-1)/G sum_b d_b d_b^T with d_b the
    move of a real refit without block b (weight 0: every refit keeps its sample count).
    The reported covariance is CR2 (power 1/2) widened by the t coverage factors."""
    data = _datasets(1, seed=5)[0]
    model = models.get("lambert")
    r = fit_many(model, [data], "ngan", errors="blocks", cut_deg=None)[0]
    prep = prepare(data, get_metric("ngan"), cut_deg=None)
    ids, g = block_index(prep)
    obj = Objective.build(model)
    z = jnp.asarray(obj.layout.solver_vector(r.params))
    jtj = np.asarray(natural_moments(obj, z, prep)[0])
    scores, grams = (np.asarray(a) for a in block_moments(obj, z, prep, BlockChunks.of(ids, g)))
    cr3, _ = block_covariance(jtj, scores, grams, power=1.0)
    cr2, _ = block_covariance(jtj, scores, grams)
    f = coverage_factor(effective_dof(jtj, grams))
    np.testing.assert_allclose(cr2 * np.outer(f, f), r.covariance, rtol=1e-12)
    np.testing.assert_allclose(r.error_dof["kd"], effective_dof(jtj, grams))
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


def _explicit_dof(x: np.ndarray, ids: np.ndarray, c: np.ndarray) -> float:
    """Bell and McCaffrey's degrees of freedom written out with n x n matrices: the CR2
    variance of ``c^T beta`` is ``e^T (I-H) G G^T (I-H) e``, column ``b`` of ``G`` being
    ``(I - H_bb)^-1/2 X_b A^-1 c`` on block ``b``'s rows; nu from the eigenvalues of
    ``G^T (I-H) G``."""
    a_inv = np.linalg.inv(x.T @ x)
    h = x @ a_inv @ x.T
    cols = []
    for b in np.unique(ids):
        rows = ids == b
        ev, v = np.linalg.eigh(np.eye(rows.sum()) - h[np.ix_(rows, rows)])
        col = np.zeros(len(x))
        col[rows] = v @ np.diag(ev**-0.5) @ v.T @ x[rows] @ a_inv @ c
        cols.append(col)
    g = np.array(cols).T
    lam = np.linalg.eigvalsh(g.T @ (np.eye(len(x)) - h) @ g)
    return lam.sum() ** 2 / np.sum(lam**2)


def test_effective_dof_equal_the_explicit_satterthwaite_formula():
    """effective_dof works on k x k block moments only; the explicit n x n formula is the
    independent check, on blocks of unequal size and leverage (one block holds most of
    the third column, as the specular peak holds a lobe's width)."""
    rng = np.random.default_rng(4)
    ids = np.repeat(np.arange(24), rng.integers(3, 12, 24))
    x = rng.standard_normal((len(ids), 3)) * np.array([1.0, 3.0, 0.05])
    x[ids == 5, 2] *= 40.0
    grams = np.array([x[ids == b].T @ x[ids == b] for b in range(24)])
    dof = effective_dof(x.T @ x, grams)
    want = [_explicit_dof(x, ids, c) for c in np.eye(3)]
    np.testing.assert_allclose(dof, want, rtol=1e-9)
    assert dof[2] < 4 < dof[0]  # the scalar one block carries has few degrees of freedom
    assert coverage_factor(np.array([1e9]))[0] == pytest.approx(1.0, abs=1e-6)
    assert coverage_factor(np.array([1.0]))[0] == pytest.approx(12.706 / 1.960, rel=1e-3)


def test_auto_errors_are_blocks_for_measured_and_sandwich_for_synthetic_data():
    lam = models.get("lambert")
    measured = _datasets(1, seed=6)[0]
    synthetic = synthesize(lam, {"kd": KD}, grid="directions", directions=(WI, WO))
    r_meas, r_syn = (fit_many(lam, [d], "ngan", cut_deg=None)[0] for d in (measured, synthetic))
    assert synthetic.synthetic and not measured.synthetic
    assert r_meas.errors_method == "blocks" and r_meas.error_dof is not None
    assert r_syn.errors_method == "sandwich" and r_syn.error_dof is None
    assert "Student-t" in r_meas.report()
    few = Measurements.from_directions(WI[:12], WO[:12], measured.values[:12])
    r_few = fit_many(lam, [few], "ngan", cut_deg=None)[0]
    assert r_few.errors_method == "sandwich" and r_few.stderr is not None
    assert any("not blocks" in w and "fewer than" in w for w in r_few.warnings)


def test_a_singular_or_non_finite_gram_matrix_is_a_reason_not_an_exception():
    grams = np.repeat(np.eye(2)[None] / 30.0, 30, axis=0)
    for jtj in (np.array([[1.0, np.nan], [np.nan, 1.0]]), np.array([[1.0, 1.0], [1.0, 1.0]])):
        cov, reason = block_covariance(jtj, np.zeros((30, 2)), grams)
        assert cov is None and ("not finite" in reason or "singular" in reason)
        assert effective_dof(jtj, grams) is None
