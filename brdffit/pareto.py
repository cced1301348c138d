"""Fit error against run time, per model, from a sweep's results; the Pareto front.

For each model and fitted metric: the median over materials of the metric value
(converged fits), of the relative error ``loss / best - 1`` (:mod:`brdffit.crossrank`),
of the fit wall time (s, the fit's own clock in the sweep worker, compile included on
a worker's first fit, hence the median) and of the evaluation cost (ns per sample,
warm jitted ``model.eval``; :mod:`brdffit.sweep`). A model is on the Pareto front
when no other model is at least as good in both error and time and better in one.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from brdffit.crossrank import SweepResults, matrices
from brdffit.tables import render


@dataclass(frozen=True)
class ParetoRow:
    """One model under one metric; medians over the materials it converged on."""

    model: str
    metric: str
    n_materials: int
    n_free: int
    median_loss: float
    median_rel_err: float
    median_wall_time: float
    median_eval_ns: float
    front_time: bool
    front_eval: bool


def pareto_front(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Mask of the points not dominated when both ``x`` and ``y`` are minimised.

    A point with a non-finite coordinate is never on the front.
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = np.isfinite(x) & np.isfinite(y)
    front = ok.copy()
    for i in np.flatnonzero(ok):
        better_eq = ok & (x <= x[i]) & (y <= y[i])
        strictly = (x < x[i]) | (y < y[i])
        if np.any(better_eq & strictly):
            front[i] = False
    return front


def _median(v: list[float]) -> float:
    a = np.asarray(v, float)
    a = a[np.isfinite(a)]
    return float(np.median(a)) if a.size else float("nan")


def error_vs_time(res: SweepResults, metric: str) -> tuple[ParetoRow, ...]:
    """Per-model medians of error, fit time and evaluation cost under ``metric``."""
    mx = matrices(res, metric)
    rows = []
    for j, model in enumerate(mx.models):
        recs = [r for r in res.records if r.model == model and r.metric == metric and r.converged]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            med_rel = float(np.nanmedian(mx.rel[:, j])) if recs else float("nan")
        rows.append(
            dict(
                model=model,
                metric=metric,
                n_materials=len(recs),
                n_free=recs[0].n_free if recs else 0,
                median_loss=_median([r.loss for r in recs]),
                median_rel_err=med_rel,
                median_wall_time=_median([r.wall_time for r in recs]),
                median_eval_ns=_median([r.eval_ns for r in recs]),
            )
        )
    err = np.array([r["median_loss"] for r in rows])
    ft = pareto_front(np.array([r["median_wall_time"] for r in rows]), err)
    fe = pareto_front(np.array([r["median_eval_ns"] for r in rows]), err)
    out = [
        ParetoRow(**r, front_time=bool(a), front_eval=bool(b))
        for r, a, b in zip(rows, ft, fe, strict=True)
    ]
    return tuple(sorted(out, key=lambda r: (np.nan_to_num(r.median_loss, nan=np.inf), r.model)))


def pareto_table(rows: tuple[ParetoRow, ...], fmt: str = "markdown") -> str:
    """The error-against-time rows as a Markdown or CSV table (``*``: on the front)."""
    metric = rows[0].metric if rows else "loss"
    head = ["model", "k", "n", f"median {metric}", "median rel. error", "median fit time (s)"]
    head += ["front (fit time)", "eval cost (ns/sample)", "front (eval cost)"]
    body = [
        [r.model, str(r.n_free), str(r.n_materials), f"{r.median_loss:.6g}"]
        + [f"{r.median_rel_err:.4g}", f"{r.median_wall_time:.4g}", "*" if r.front_time else ""]
        + [f"{r.median_eval_ns:.4g}", "*" if r.front_eval else ""]
        for r in rows
    ]
    return render(head, body, fmt)


def pareto_figure(rows: tuple[ParetoRow, ...]):
    """Two panels: median error against median fit time and against evaluation cost.

    Log axes; the Pareto front is the red staircase, front models in red.
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    y = np.array([r.median_loss for r in rows])
    for ax, attr, front, label in (
        (axes[0], "median_wall_time", "front_time", "median fit wall time (s)"),
        (axes[1], "median_eval_ns", "front_eval", "evaluation cost (ns/sample)"),
    ):
        x = np.array([getattr(r, attr) for r in rows])
        on = np.array([getattr(r, front) for r in rows])
        ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
        ax.scatter(x[ok & ~on], y[ok & ~on], color="0.5", s=20)
        ax.scatter(x[ok & on], y[ok & on], color="C3", s=30, zorder=3)
        for r, xi, yi, good in zip(rows, x, y, ok, strict=True):
            if good:
                ax.annotate(
                    r.model, (xi, yi), fontsize=7, xytext=(3, 3), textcoords="offset points"
                )
        idx = np.flatnonzero(ok & on)
        if idx.size:
            idx = idx[np.argsort(x[idx])]
            ax.step(x[idx], y[idx], where="post", color="C3", lw=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(label)
    metric = rows[0].metric if rows else "loss"
    axes[0].set_ylabel(f"median {metric} over materials")
    fig.suptitle(f"fit error against run time ({metric}); red: Pareto front")
    fig.tight_layout()
    return fig
