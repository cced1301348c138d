"""Ranking of models across many materials, from a sweep folder's JSON files alone.

The folder is read by :func:`brdffit.selection.sweep_results.load_sweep`; this module
turns its results into materials x models arrays (:func:`matrices`), the aggregate
ranking and its tables, and the row order of the rank matrix
(:func:`brdffit.report.selection_figures.rank_matrix_figure` draws it).

Per material, the models fitted under one metric are ranked as :func:`brdffit.rank`
does (by the metric value, losses within a relative :data:`~brdffit.selection.rank.LOSS_RTOL`
tied and given their average rank; AIC and BIC ranks beside it; a fit that did not
converge ranked by the finite loss it reached and marked, failed and missing fits
last). Over all materials each model gets its mean rank, its wins (materials where
it ranks first; a tie for first is a win for every tied model, so wins can add up to
more than the number of materials) and its median relative error ``loss / best loss on
that material - 1``, each with a 95% percentile bootstrap interval
over materials (``numpy.random.default_rng(seed)``, materials drawn with replacement).
A model is named by its label (:func:`brdffit.models.label`), so each variant of a model
(``lafortune[n_lobes=2]``) ranks as a model of its own. Families come from a
``families`` mapping (a user's file, :func:`brdffit.selection.families.read_families`), else the
sweep manifest, else :func:`brdffit.selection.families.family_of`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from brdffit.core.result_terms import loss_kind
from brdffit.errors import SweepError
from brdffit.selection.families import FAMILIES
from brdffit.selection.rank import LOSS_RTOL, rank_text, ranks
from brdffit.selection.sweep_results import SweepResults
from brdffit.util.text_table import render


@dataclass(frozen=True)
class Matrices:
    """Materials x models arrays for one metric (NaN where missing or failed).

    ``loss``, ``loss_per_sample``, ``aic``, ``bic``, ``rel`` (loss / best - 1); ``rank``,
    ``rank_aic``, ``rank_bic`` (1 = best, ties share their average rank, a fit that did
    not converge ranked by its finite loss, missing and failed ranked last; module
    docstring); ``win`` (bool: a finite loss tied for the best); ``converged`` (bool: a
    fit exists and converged; a finite loss where it is False is marked not converged).
    """

    metric: str
    materials: tuple[str, ...]
    families: tuple[str, ...]
    models: tuple[str, ...]
    loss: np.ndarray
    aic: np.ndarray
    bic: np.ndarray
    rel: np.ndarray
    rank: np.ndarray
    rank_aic: np.ndarray
    rank_bic: np.ndarray
    win: np.ndarray
    loss_per_sample: np.ndarray | None = None
    converged: np.ndarray | None = None


def matrices(res: SweepResults, metric: str) -> Matrices:
    """The per-material values and ranks of every model under ``metric``."""
    if metric not in res.metrics:
        raise SweepError(f"metric {metric!r} is not in this sweep ({', '.join(res.metrics)})")
    mats, mods = res.materials, res.models
    shape = (len(mats), len(mods))
    loss, aic, bic, per = (np.full(shape, np.nan) for _ in range(4))
    ok = np.zeros(shape, bool)
    im, jm = {m: i for i, m in enumerate(mats)}, {m: j for j, m in enumerate(mods)}
    for r in res.records:
        if r.metric == metric and math.isfinite(r.loss) and r.material in im and r.model in jm:
            i, j = im[r.material], jm[r.model]
            loss[i, j], aic[i, j], bic[i, j] = r.loss, r.aic, r.bic
            per[i, j], ok[i, j] = r.loss_per_sample, r.converged
    best = np.array([np.nanmin(row) if np.isfinite(row).any() else np.nan for row in loss])
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = loss / best[:, None] - 1.0
    rank = np.array([ranks(row, LOSS_RTOL) for row in loss]).reshape(shape)
    first = rank.min(axis=1, keepdims=True) if mods else rank
    return Matrices(
        metric,
        tuple(mats),
        tuple(res.family(m) for m in mats),
        tuple(mods),
        loss,
        aic,
        bic,
        rel,
        rank,
        np.array([ranks(row) for row in aic]).reshape(shape),
        np.array([ranks(row) for row in bic]).reshape(shape),
        np.isfinite(loss) & (rank == first),
        per,
        ok,
    )


@dataclass(frozen=True)
class AggregateRow:
    """One model over all materials; each ``(lo, hi)`` is a 95% bootstrap interval.

    ``n_materials`` counts the materials with a finite loss, ``n_unconverged`` those of
    them whose fit did not converge (ranked by the loss it reached).
    """

    model: str
    mean_rank: float
    mean_rank_ci: tuple[float, float]
    wins: int
    wins_ci: tuple[float, float]
    median_rel_err: float
    median_rel_err_ci: tuple[float, float]
    n_materials: int
    n_unconverged: int = 0


def _stats(rank: np.ndarray, win: np.ndarray, rel: np.ndarray, axis: int):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns -> NaN
        return rank.mean(axis), win.sum(axis), np.nanmedian(rel, axis)


def aggregate(mx: Matrices, *, n_boot: int = 1000, seed: int = 0) -> tuple[AggregateRow, ...]:
    """Mean rank, wins and median relative error per model, best mean rank first.

    A tie for first counts as a win for each tied model (module docstring).
    """
    n = len(mx.materials)
    mean, wins, med = _stats(mx.rank, mx.win, mx.rel, 0)
    idx = np.random.default_rng(seed).integers(0, n, (n_boot, n))
    b_mean, b_wins, b_med = _stats(mx.rank[idx], mx.win[idx], mx.rel[idx], 1)

    def ci(b: np.ndarray, j: int) -> tuple[float, float]:
        col = b[:, j][np.isfinite(b[:, j])]
        if col.size == 0:
            return (math.nan, math.nan)
        return tuple(float(x) for x in np.percentile(col, [2.5, 97.5]))

    rows = [
        AggregateRow(
            model=m,
            mean_rank=float(mean[j]),
            mean_rank_ci=ci(b_mean, j),
            wins=int(wins[j]),
            wins_ci=ci(b_wins.astype(float), j),
            median_rel_err=float(med[j]),
            median_rel_err_ci=ci(b_med, j),
            n_materials=int(np.isfinite(mx.loss[:, j]).sum()),
            n_unconverged=_n_unconverged(mx, j),
        )
        for j, m in enumerate(mx.models)
    ]
    return tuple(sorted(rows, key=lambda r: (r.mean_rank, r.model)))


def _n_unconverged(mx: Matrices, j: int) -> int:
    if mx.converged is None:
        return 0
    return int((np.isfinite(mx.loss[:, j]) & ~mx.converged[:, j]).sum())


def aggregate_table(rows: tuple[AggregateRow, ...], fmt: str = "markdown") -> str:
    """The aggregate ranking as a Markdown (``fmt="markdown"``) or CSV table."""
    if fmt == "csv":
        head = ["model", "mean_rank", "mean_rank_lo", "mean_rank_hi", "wins", "wins_lo"]
        head += ["wins_hi", "median_rel_err", "median_rel_err_lo", "median_rel_err_hi", "n"]
        head += ["n_unconverged"]
        body = [
            [r.model, f"{r.mean_rank:.6g}", *(f"{x:.6g}" for x in r.mean_rank_ci), str(r.wins)]
            + [f"{x:.6g}" for x in (*r.wins_ci, r.median_rel_err, *r.median_rel_err_ci)]
            + [str(r.n_materials), str(r.n_unconverged)]
            for r in rows
        ]
        return render(head, body, "csv")
    head = ["model", "mean rank [95% CI]", "wins [95% CI]", "median rel. error [95% CI]", "n"]
    body = [
        [
            r.model,
            f"{r.mean_rank:.2f} [{r.mean_rank_ci[0]:.2f}, {r.mean_rank_ci[1]:.2f}]",
            f"{r.wins} [{r.wins_ci[0]:.0f}, {r.wins_ci[1]:.0f}]",
            f"{r.median_rel_err:.3g} [{r.median_rel_err_ci[0]:.3g}, {r.median_rel_err_ci[1]:.3g}]",
            f"{r.n_materials}" + (f" ({r.n_unconverged} not converged)" if r.n_unconverged else ""),
        ]
        for r in rows
    ]
    return render(head, body, "markdown")


def per_material_table(mx: Matrices, fmt: str = "markdown") -> str:
    """Every (material, model): metric value (as defined, and per sample), AIC, BIC,
    their ranks, relative error, and whether the fit converged (``no``: ranked by the
    loss it reached; ``-``: no result)."""
    kind = loss_kind(mx.metric)
    head = ["material", "family", "model", f"{mx.metric} ({kind})", "per sample", "AIC", "BIC"]
    head += ["rank", "rank AIC", "rank BIC", "rel. error", "converged"]
    per = mx.loss_per_sample if mx.loss_per_sample is not None else np.full_like(mx.loss, np.nan)
    body = []
    for i, mat in enumerate(mx.materials):
        for j in np.argsort(mx.rank[i], kind="stable"):
            vals = (mx.loss[i, j], per[i, j], mx.aic[i, j], mx.bic[i, j])
            body.append(
                [mat, mx.families[i], mx.models[j], *(f"{v:.6g}" for v in vals)]
                + [rank_text(x) for x in (mx.rank[i, j], mx.rank_aic[i, j], mx.rank_bic[i, j])]
                + [f"{mx.rel[i, j]:.4g}", _converged_text(mx, i, int(j))]
            )
    return render(head, body, fmt)


def _converged_text(mx: Matrices, i: int, j: int) -> str:
    if not np.isfinite(mx.loss[i, j]):
        return "-"
    return "yes" if mx.converged is None or mx.converged[i, j] else "no"


def family_table(mx: Matrices, fmt: str = "markdown", top: int = 3) -> str:
    """Per material family: its size and the ``top`` models by mean rank over its materials.

    Mean ranks are those of :attr:`Matrices.rank` (ties averaged, unconverged last),
    so a model's place within a family reads like the overall ranking.
    """
    head = ["family", "n", *(f"#{k + 1} (mean rank)" for k in range(top))]
    body = []
    for fam in sorted(set(mx.families)):
        rows = np.array([f == fam for f in mx.families])
        mean = mx.rank[rows].mean(axis=0)
        best = np.argsort(mean, kind="stable")[:top]
        cells = [f"{mx.models[j]} ({mean[j]:.2f})" for j in best]
        body.append([fam, str(int(rows.sum())), *cells, *[""] * (top - len(cells))])
    return render(head, body, fmt)


def cluster_order(vectors: np.ndarray) -> np.ndarray:
    """Row order putting similar rows next to each other; fewer than 3 rows keep their order.

    Average-linkage hierarchical clustering of the rows (Euclidean distance), leaves
    ordered by ``scipy.cluster.hierarchy.optimal_leaf_ordering`` (adjacent rows as close
    as the tree allows), the order turned so that it starts at the end holding the lower
    original index, and runs of identical rows kept in their original order.
    Deterministic: the same rows give the same order.
    """
    n = len(vectors)
    if n < 3:
        return np.arange(n)
    from scipy.cluster import hierarchy  # deferred: scipy submodule, clustering only

    x = np.asarray(vectors, float)
    tree = hierarchy.linkage(x, method="average", metric="euclidean")
    order = hierarchy.leaves_list(hierarchy.optimal_leaf_ordering(tree, x))
    order = list(order if order[0] < order[-1] else order[::-1])
    start = 0
    for pos in range(1, n + 1):  # runs of identical rows in their original order
        if pos == n or not np.array_equal(x[order[pos]], x[order[start]]):
            order[start:pos] = sorted(order[start:pos])
            start = pos
    return np.array(order, int)


def material_order(mx: Matrices) -> np.ndarray:
    """Row order grouping materials by family (family order of :data:`FAMILIES`).

    Inside a family the materials follow :func:`cluster_order` of their rank vectors
    (``mx.rank`` rows), so materials that rank the models alike sit together; a family
    of fewer than 3 materials keeps the manifest order.
    """
    fam = {f: k for k, f in enumerate(FAMILIES)}
    groups: dict[str, list[int]] = {}
    for i in sorted(range(len(mx.materials)), key=lambda i: (fam.get(mx.families[i], 99), i)):
        groups.setdefault(mx.families[i], []).append(i)
    out = [np.array(g)[cluster_order(mx.rank[g])] for g in groups.values()]
    return np.concatenate(out).astype(int) if out else np.zeros(0, int)
