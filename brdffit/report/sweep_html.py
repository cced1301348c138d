"""One self-contained HTML file per sweep: ``<sweep_dir>/report.html`` with, per metric,
the tables and figures of the Markdown sweep report
(:func:`brdffit.report.markdown.write_report`), computed once for both
(:func:`brdffit.report.sweep_sections.metric_sections`), built from the blocks of
:mod:`brdffit.report.html` (figures as base64 PNGs, inline style, written atomically).
"""

from __future__ import annotations

import html
import os
from collections import Counter
from pathlib import Path

from brdffit.report.html import (
    figure_or_note,
    html_table,
    page,
    table_from_csv,
    table_from_markdown,
    write_page,
)
from brdffit.report.sweep_sections import metric_sections, read_sweep
from brdffit.selection.rank import NOTE, TIES
from brdffit.selection.survival import survival_table
from brdffit.selection.sweep_results import SweepResults

# --------------------------------------------------------------------------- a sweep


def _sweep_header(res: SweepResults) -> list[str]:
    s = res.manifest["settings"]
    fams = Counter(res.family(m) for m in res.materials)
    unconv = sum(not r.converged for r in res.records)
    total = len(res.materials) * len(res.models) * len(res.metrics)
    items = [
        f"materials: {len(res.materials)} ("
        + ", ".join(f"{f} {n}" for f, n in sorted(fams.items()))
        + ")",
        f"models: {', '.join(res.models)}",
        f"metrics: {', '.join(res.metrics)} (compare models only under the same metric)",
        f"MERL grid stride {tuple(s.get('stride', ()))}, angle cut {s.get('cut_deg')} deg",
        f"results: {len(res.records)} of {total} tasks, {unconv} not converged, "
        f"{len(res.errors)} errors",
        *(f"unreadable, left out: {path} ({why})" for path, why in res.unreadable),
    ]
    provenance = Counter(r.provenance for r in res.records)
    items += [f"computed by: {p} ({n} results)" for p, n in sorted(provenance.items())]
    return ["<ul>", *(f"<li>{html.escape(i)}</li>" for i in items), "</ul>"]


def sweep_html(
    sweep_dir: str | os.PathLike[str],
    *,
    n_boot: int = 1000,
    seed: int = 0,
    families: str | os.PathLike[str] | None = None,
) -> str:
    """The HTML text of :func:`write_sweep_html` (arguments there)."""
    res = read_sweep(sweep_dir, families)
    title = f"brdffit sweep report: {Path(sweep_dir).resolve().name}"
    body = [f"<h1>{html.escape(title)}</h1>", *_sweep_header(res)]
    body.append(f'<p class="note">{html.escape(TIES)} {html.escape(NOTE)}</p>')
    for sec in metric_sections(res, n_boot=n_boot, seed=seed):
        body += [
            f"<h2>Metric {html.escape(sec.metric)}</h2>",
            "<h3>Ranking over all materials</h3>",
        ]
        body.append(table_from_markdown(sec.aggregate.markdown))
        body.append(
            figure_or_note(sec.rank_matrix, sec.rank_matrix_note, "rank matrix",
                            "Rank per material.")
        )  # fmt: skip
        body += ["<h3>Best models per material family</h3>", table_from_csv(sec.families.csv)]
        body.append("<h3>Fit error against run time</h3>")
        body.append(f'<p class="note">Over which materials: {html.escape(sec.caption)}.</p>')
        body.append(table_from_csv(sec.pareto.csv))
        body.append(
            figure_or_note(sec.pareto_plot, sec.pareto_note, "Pareto plot",
                            "Red: the Pareto front.")
        )  # fmt: skip
        body.append("<h3>Per material</h3>")
        if sec.inline:
            body.append(table_from_csv(sec.per_material.csv))
        else:
            body.append(
                f'<p class="note">{sec.n_rows} rows: see '
                f"report/per_material_{html.escape(sec.metric)}.csv.</p>"
            )
    survivors = survival_table(sweep_dir, fmt="text")  # "" unless the sweep ran --simplify
    if survivors:
        body += [
            "<h2>Model reduction (sweep --simplify)</h2>",
            f"<pre>{html.escape(survivors)}</pre>",
        ]
    if res.errors:
        rows = [
            [e["material"], e["model"], e["metric"], f"{e['error']}: {e.get('message', '')}"]
            for e in res.errors
        ]
        body += ["<h2>Errors</h2>", html_table(["material", "model", "metric", "error"], rows)]
    return page(title, body)


def write_sweep_html(
    sweep_dir: str | os.PathLike[str],
    *,
    n_boot: int = 1000,
    seed: int = 0,
    families: str | os.PathLike[str] | None = None,
) -> Path:
    """Write ``<sweep_dir>/report.html`` from the sweep's JSON files, atomically.

    ``n_boot``, ``seed`` and ``families`` (a ``material,family`` CSV file) as in
    :func:`brdffit.report.markdown.write_report`, so the numbers match its Markdown report.
    Returns the path. Raises :class:`brdffit.errors.SweepError` when the folder holds no
    ``sweep.json`` or the families file is not usable.
    """
    text = sweep_html(sweep_dir, n_boot=n_boot, seed=seed, families=families)
    return write_page(Path(sweep_dir) / "report.html", text)
