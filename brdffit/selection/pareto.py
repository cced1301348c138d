"""Fit error against run time, per model, from a sweep's results; the Pareto front.

Every model is compared on the same materials: the medians are taken over the
materials on which every compared model has a finite loss (the ranking's rule,
:mod:`brdffit.selection.crossrank`: a fit that did not converge counts with the loss it
reached; a model with no finite loss anywhere is left out of the comparison). A median
over each model's own materials would compare a model that failed on the hard materials
with one that did not, and contradict the ranking beside it. When no material has every
model, the error is normalised per material instead: the median of ``loss / best loss
on that material`` over each model's own materials.

Per model and fitted metric: the median of the metric value (as the metric defines it
and per sample, :func:`brdffit.core.result_terms.per_sample`), of the relative error ``loss / best
- 1``, of the fit wall time (s, the fit's own clock in the sweep worker, compile
included on a worker's first fit, hence the median) and of the evaluation cost (ns per
sample, warm jitted ``model.eval``; :mod:`brdffit.sweep.run`). A model is on the Pareto front
when no other model is at least as good in both error and time and better in one.
:func:`brdffit.report.selection_figures.pareto_figure` draws the rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brdffit.core.result_terms import loss_kind
from brdffit.selection.crossrank import matrices
from brdffit.selection.sweep_results import SweepResults
from brdffit.util.text_table import render


@dataclass(frozen=True)
class ParetoRow:
    """One model under one metric.

    ``n_materials``: materials where the model has a finite loss. The medians are over
    the ``n_common`` materials every compared model has (``basis == "common"``), or,
    when there are none (``basis == "relative"``), ``median_loss`` is the median of
    ``loss / best`` over the model's own materials and the other medians are over those.
    """

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
    median_loss_per_sample: float = float("nan")
    n_common: int = 0
    basis: str = "common"


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


def _median(v: np.ndarray) -> float:
    a = np.asarray(v, float)
    a = a[np.isfinite(a)]
    return float(np.median(a)) if a.size else float("nan")


def _per_record(res: SweepResults, metric: str, mx, attr: str) -> np.ndarray:
    """Materials x models array of a record attribute (NaN where no finite loss)."""
    out = np.full(mx.loss.shape, np.nan)
    im = {m: i for i, m in enumerate(mx.materials)}
    jm = {m: j for j, m in enumerate(mx.models)}
    for r in res.records:
        i, j = im.get(r.material), jm.get(r.model)
        if r.metric == metric and i is not None and j is not None:
            out[i, j] = getattr(r, attr)
    return np.where(np.isfinite(mx.loss), out, np.nan)


def error_vs_time(res: SweepResults, metric: str) -> tuple[ParetoRow, ...]:
    """Per-model medians of error, fit time and evaluation cost under ``metric`` over the
    materials every compared model has (module docstring); best median error first."""
    mx = matrices(res, metric)
    have = np.isfinite(mx.loss)
    compared = have.any(axis=0)
    common = have[:, compared].all(axis=1) if compared.any() else np.zeros(len(have), bool)
    basis = "common" if common.any() else "relative"
    wall, ns = (_per_record(res, metric, mx, a) for a in ("wall_time", "eval_ns"))
    n_free = {r.model: r.n_free for r in res.records if r.metric == metric}
    per = mx.loss_per_sample if mx.loss_per_sample is not None else np.full_like(mx.loss, np.nan)
    rows = []
    for j, model in enumerate(mx.models):
        sel = common if basis == "common" else have[:, j]
        y = mx.loss[sel, j] if basis == "common" else mx.rel[sel, j] + 1.0
        rows.append(
            dict(
                model=model,
                metric=metric,
                n_materials=int(have[:, j].sum()),
                n_free=n_free.get(model, 0),
                median_loss=_median(y) if compared[j] else float("nan"),
                median_rel_err=_median(mx.rel[sel, j]) if compared[j] else float("nan"),
                median_wall_time=_median(wall[sel, j]),
                median_eval_ns=_median(ns[sel, j]),
                median_loss_per_sample=_median(per[sel, j]) if basis == "common" else np.nan,
                n_common=int(common.sum()),
                basis=basis,
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


def pareto_caption(rows: tuple[ParetoRow, ...]) -> str:
    """What the medians of ``rows`` are taken over, in one sentence."""
    if not rows:
        return "no result"
    r = rows[0]
    if r.basis == "relative":
        return (
            f"no material has a result for every model: error is the median of {r.metric} / "
            "best on each material, over each model's own materials"
        )
    left = [x.model for x in rows if x.n_materials == 0]
    out = f"medians over the {r.n_common} materials every model has a {r.metric} result for"
    return out + (f" (no result at all: {', '.join(left)})" if left else "")


def pareto_table(rows: tuple[ParetoRow, ...], fmt: str = "markdown") -> str:
    """The error-against-time rows as a Markdown or CSV table (``*``: on the front)."""
    metric = rows[0].metric if rows else "loss"
    relative = bool(rows) and rows[0].basis == "relative"
    what = f"median {metric} / best" if relative else f"median {metric} ({loss_kind(metric)})"
    head = ["model", "k", "n", what, "per sample", "median rel. error", "median fit time (s)"]
    head += ["front (fit time)", "eval cost (ns/sample)", "front (eval cost)"]
    body = [
        [r.model, str(r.n_free), str(r.n_materials), f"{r.median_loss:.6g}"]
        + [f"{r.median_loss_per_sample:.6g}", f"{r.median_rel_err:.4g}"]
        + [f"{r.median_wall_time:.4g}", "*" if r.front_time else ""]
        + [f"{r.median_eval_ns:.4g}", "*" if r.front_eval else ""]
        for r in rows
    ]
    return render(head, body, fmt)
