"""What a sweep report holds per metric, computed once for the Markdown and HTML writers.

:func:`metric_sections` turns a sweep folder read back
(:func:`brdffit.selection.sweep_results.load_sweep`) into one :class:`MetricSection`
per metric: the aggregate ranking, the best models per family, the per-material table
and the error-against-time table, each as Markdown and CSV text, the caption of the
Pareto medians, and the rank-matrix and Pareto figures
(:mod:`brdffit.report.selection_figures`). A figure that the results cannot fill (no
finite loss, no model with a finite error and time) is ``None`` and its note says why,
so a report on a sweep with too few results says so instead of failing.
:func:`brdffit.report.markdown.write_report` and :func:`brdffit.report.html.write_sweep_html`
format the sections; :func:`read_sweep` reads the folder for both.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from brdffit.report.selection_figures import pareto_figure, rank_matrix_figure
from brdffit.selection.crossrank import (
    aggregate,
    aggregate_table,
    family_table,
    matrices,
    per_material_table,
)
from brdffit.selection.families import read_families
from brdffit.selection.pareto import ParetoRow, error_vs_time, pareto_caption, pareto_table
from brdffit.selection.sweep_results import SweepResults, load_sweep

MAX_INLINE_ROWS = 200
"""Largest per-material table (materials x models rows) a report shows inline; a larger
one is only in ``per_material_<metric>.csv``."""


NO_PARETO_PLOT = (
    "No Pareto plot: no model has a finite median error with a fit time or evaluation cost."
)


@dataclass(frozen=True)
class Table:
    """One table of a report as Markdown and as CSV text."""

    markdown: str
    csv: str


@dataclass(frozen=True)
class MetricSection:
    """The tables and figures of one metric of a sweep report.

    ``aggregate``, ``families``, ``per_material``, ``pareto``: the tables of
    :func:`~brdffit.selection.crossrank.aggregate_table`,
    :func:`~brdffit.selection.crossrank.family_table`,
    :func:`~brdffit.selection.crossrank.per_material_table` and
    :func:`~brdffit.selection.pareto.pareto_table`; ``caption``: which materials the
    Pareto medians are over; ``n_rows``: the per-material table's rows (inline when at
    most :data:`MAX_INLINE_ROWS`); ``rank_matrix`` and ``pareto_plot``: matplotlib
    figures (not registered with pyplot: nothing to close) or ``None``, then ``rank_matrix_note`` or
    ``pareto_note`` says why there is none.
    """

    metric: str
    aggregate: Table
    families: Table
    per_material: Table
    pareto: Table
    caption: str
    n_rows: int
    rank_matrix: object | None
    pareto_plot: object | None
    rank_matrix_note: str = ""
    pareto_note: str = ""

    @property
    def inline(self) -> bool:
        """Whether the per-material table is shown in the report (else only its CSV)."""
        return self.n_rows <= MAX_INLINE_ROWS


def read_sweep(
    sweep_dir: str | os.PathLike[str], families: str | os.PathLike[str] | None = None
) -> SweepResults:
    """The sweep in ``sweep_dir``, families from the ``material,family`` CSV file
    ``families`` when one is given (:func:`brdffit.selection.families.read_families`)."""
    return load_sweep(sweep_dir, read_families(families) if families else None)


def metric_sections(
    res: SweepResults, *, n_boot: int = 1000, seed: int = 0
) -> Iterator[MetricSection]:
    """One :class:`MetricSection` per metric of ``res``, in the manifest's order.

    ``n_boot`` and ``seed`` set the bootstrap of
    :func:`~brdffit.selection.crossrank.aggregate`. Made one at a time, so a writer
    closes a metric's figures before the next metric's are drawn.
    """
    for metric in res.metrics:
        mx = matrices(res, metric)
        agg = aggregate(mx, n_boot=n_boot, seed=seed)
        par = error_vs_time(res, metric)
        ranked = bool(np.isfinite(mx.loss).any())
        timed = _has_points(par)
        yield MetricSection(
            metric=metric,
            aggregate=Table(aggregate_table(agg), aggregate_table(agg, "csv")),
            families=Table(family_table(mx), family_table(mx, "csv")),
            per_material=Table(per_material_table(mx), per_material_table(mx, "csv")),
            pareto=Table(pareto_table(par), pareto_table(par, "csv")),
            caption=pareto_caption(par),
            n_rows=len(mx.materials) * len(mx.models),
            rank_matrix=rank_matrix_figure(mx, agg) if ranked else None,
            pareto_plot=pareto_figure(par) if timed else None,
            rank_matrix_note="" if ranked else f"No rank matrix: no model has a finite {metric}.",
            pareto_note="" if timed else NO_PARETO_PLOT,
        )


def _has_points(rows: tuple[ParetoRow, ...]) -> bool:
    """Whether the Pareto plot has a point: a model whose median error is positive and
    finite, as is its fit time or its evaluation cost (the plot's axes are logarithmic)."""

    def good(x: float) -> bool:
        return math.isfinite(x) and x > 0

    return any(
        good(r.median_loss) and (good(r.median_wall_time) or good(r.median_eval_ns)) for r in rows
    )
