"""Figures of model selection across a sweep: the rank matrix and the Pareto plot.

Each function takes the tables and results of :mod:`brdffit.selection` (never a solver)
and returns a matplotlib :class:`~matplotlib.figure.Figure` not registered with pyplot
(nothing to close; in Jupyter it shows as a cell's value): :func:`rank_matrix_figure`
(ranks per material, :mod:`brdffit.selection.crossrank`), :func:`pareto_figure` (error
against run time, :mod:`brdffit.selection.pareto`). (A reduction plots itself:
:meth:`brdffit.Reduction.plot`.)
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from brdffit.selection.crossrank import AggregateRow, Matrices, aggregate, material_order
from brdffit.selection.pareto import ParetoRow, pareto_caption
from brdffit.selection.rank import rank_text


def rank_matrix_figure(mx: Matrices, rows: tuple[AggregateRow, ...] | None = None):
    """Image of ranks, materials (:func:`material_order`) x models (best mean rank first).

    A rank reached by a fit that did not converge is marked ``*``. The figure is sized
    from its labels (constrained layout; the image at least 2.2 in tall, so the colour
    bar holds its label), so no label is cut off.
    """
    order = material_order(mx)
    cols = [mx.models.index(r.model) for r in (rows or aggregate(mx, n_boot=1))]
    img = mx.rank[np.ix_(order, cols)]
    n, k = img.shape
    ylabels = [f"{mx.families[i]}: {mx.materials[i]}" for i in order]
    xlabels = [mx.models[c] for c in cols]
    y_room, x_room = (0.06 * max(map(len, lab), default=0) for lab in (ylabels, xlabels))
    size = (1.9 + 0.55 * k + y_room, 1.1 + max(0.25 * n, 2.2) + 0.87 * x_room)
    fig = Figure(figsize=size, layout="constrained")
    ax = fig.subplots()
    im = ax.imshow(img, cmap="viridis_r", aspect="auto", vmin=1, vmax=max(k, 2))
    ax.set_xticks(range(k), xlabels, rotation=60, ha="right", rotation_mode="anchor", fontsize=8)
    ax.set_yticks(range(n), ylabels, fontsize=7)
    fams = [mx.families[i] for i in order]
    for y in range(1, n):
        if fams[y] != fams[y - 1]:
            ax.axhline(y - 0.5, color="w", lw=2)
    ok = np.ones_like(img, bool) if mx.converged is None else mx.converged[np.ix_(order, cols)]
    unconverged = np.isfinite(mx.loss[np.ix_(order, cols)]) & ~ok
    if n * k <= 400:
        for y in range(n):
            for x in range(k):
                c = "k" if img[y, x] <= (k + 1) / 2 else "w"
                t = rank_text(img[y, x]) + ("*" if unconverged[y, x] else "")
                ax.text(x, y, t, ha="center", va="center", fontsize=7, color=c)
    fig.colorbar(im, ax=ax, label="rank (1 = best)")
    note = "; * not converged" if unconverged.any() else ""
    ax.set_title(f"rank by {mx.metric} per material{note}", fontsize=10)
    return fig


def _log_axis(axis, values: np.ndarray) -> None:
    """Log scale whose tick labels do not collide: no minor labels, and majors at 1, 2, 5
    per decade when the data span less than a decade (else matplotlib's decades)."""
    from matplotlib import ticker  # deferred: heavy, figures only

    v = values[np.isfinite(values) & (values > 0)]
    axis.set_minor_formatter(ticker.NullFormatter())
    if v.size and np.log10(v.max() / v.min()) < 1.0:
        axis.set_major_locator(ticker.LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))


def pareto_figure(rows: tuple[ParetoRow, ...]):
    """Two panels: median error against median fit time and against evaluation cost.

    Log axes; the Pareto front is the red staircase, front models in red; the caption
    says which materials the medians are over (:func:`pareto_caption`). Model names sit
    beside their points on the side facing the middle of the panel, so they stay inside
    it; constrained layout keeps every label in the figure. A panel where no model has a
    positive finite error and time says so instead of drawing an empty log axis.
    """
    fig = Figure(figsize=(11, 4.6), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    y = np.array([r.median_loss for r in rows])
    drawn = False
    for ax, attr, front, label in (
        (axes[0], "median_wall_time", "front_time", "median fit wall time (s)"),
        (axes[1], "median_eval_ns", "front_eval", "evaluation cost (ns/sample)"),
    ):
        x = np.array([getattr(r, attr) for r in rows])
        on = np.array([getattr(r, front) for r in rows], bool)
        ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
        ax.scatter(x[ok & ~on], y[ok & ~on], color="0.5", s=20)
        ax.scatter(x[ok & on], y[ok & on], color="C3", s=30, zorder=3)
        ax.set_xlabel(label)
        if not ok.any():  # a log axis without a positive value cannot be drawn
            ax.text(0.5, 0.5, "no model has a finite error and cost", transform=ax.transAxes,
                    ha="center", va="center", fontsize=8)  # fmt: skip
            ax.set_xticks([])
            continue
        drawn = True
        ax.set_xscale("log")
        ax.set_yscale("log")
        lo, hi = np.log10(x[ok].min()), np.log10(x[ok].max())
        pad = max(0.15 * (hi - lo), 0.1)
        ax.set_xlim(10 ** (lo - pad), 10 ** (hi + pad))
        mid = np.mean(np.log10(ax.get_xlim()))
        for r, xi, yi, good in zip(rows, x, y, ok, strict=True):
            if good:
                right = np.log10(xi) > mid
                ax.annotate(
                    r.model, (xi, yi), fontsize=7, textcoords="offset points",
                    xytext=(-4 if right else 4, 3), ha="right" if right else "left",
                )  # fmt: skip
        idx = np.flatnonzero(ok & on)
        if idx.size:
            idx = idx[np.argsort(x[idx])]
            ax.step(x[idx], y[idx], where="post", color="C3", lw=1)
        _log_axis(ax.xaxis, x)
    if drawn:
        _log_axis(axes[0].yaxis, y)
    metric = rows[0].metric if rows else "loss"
    relative = bool(rows) and rows[0].basis == "relative"
    axes[0].set_ylabel(f"median {metric} / best" if relative else f"median {metric}")
    fig.suptitle(
        f"fit error against run time ({metric}); red: Pareto front\n{pareto_caption(rows)}",
        fontsize=10,
    )
    return fig
