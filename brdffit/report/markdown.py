"""A Markdown report of a sweep folder, made from its JSON files alone.

``write_report(sweep_dir)`` writes ``<sweep_dir>/report/report.md`` and beside it,
per metric, the CSV tables (``aggregate_<metric>.csv``, ``per_material_<metric>.csv``,
``pareto_<metric>.csv``, ``families_<metric>.csv``) and the figures
(``rank_matrix_<metric>.png``, ``pareto_<metric>.png``; where the results cannot fill
one, the report says why instead), all computed once for this report and the HTML one
(:func:`brdffit.report.sweep_sections.metric_sections`). The text holds no date and no
absolute path and the bootstrap is seeded, so the same JSON files give the same report.
Material families come from a user's ``material,family`` CSV file when one is given
(:func:`brdffit.selection.families.read_families`), else from the sweep's manifest.
"""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

from brdffit.report.sweep_sections import metric_sections, read_sweep
from brdffit.selection.rank import LOSS_RTOL, NOTE, PER_SAMPLE
from brdffit.selection.survival import survival_table
from brdffit.util.atomic import save_figure, write_text

SAVE = {"dpi": 90, "bbox_inches": "tight", "pad_inches": 0.1}
"""How the report's figures are saved: the canvas grows to hold every label."""


def _header(res) -> list[str]:
    s = res.manifest["settings"]
    fams = Counter(res.family(m) for m in res.materials)
    cut = "none" if s["cut_deg"] is None else f"{s['cut_deg']:g} deg"
    done = len(res.records)
    total = len(res.materials) * len(res.models) * len(res.metrics)
    unconv = sum(not r.converged for r in res.records)
    return [
        "# Sweep report",
        "",
        f"- materials: {len(res.materials)} ("
        + ", ".join(f"{f} {n}" for f, n in sorted(fams.items()))
        + ")",
        f"- models: {', '.join(res.models)}",
        f"- metrics: {', '.join(res.metrics)} (the metric dominates the parameters: "
        "compare models only under the same metric)",
        f"- MERL grid stride {tuple(s['stride'])}, angle cut {cut}, "
        f"{s['n_restarts']} random restarts and a screen of {s.get('screen', 0)} candidates "
        f"(seed {s['seed']}), at most {s['max_steps']} LM steps",
        f"- results: {done} of {total} tasks, {unconv} not converged, {len(res.errors)} errors"
        + (
            f", {len(res.unreadable)} unreadable files (listed at the end)"
            if res.unreadable
            else ""
        ),
        *_provenance(res),
        "",
        "Ranks are by the metric value per material. A fit that did not converge is ranked "
        "by the loss it reached (the model does at least that well) and marked: 'no' in "
        "the converged column, * in the rank matrix; failed and missing fits rank last. "
        f"Losses within a relative {LOSS_RTOL:g} of each other tie and share their average "
        "rank (nested models converge to the same fit from different sides); a tie for "
        "first counts as a win for each tied model. A model with non-default options is "
        "ranked as a model of its own, named name[option=value,...]. The rank matrix "
        "groups materials by family and, within a family of 3 or more, puts materials that "
        "rank the models alike next to each other (average-linkage clustering). "
        "Relative error is loss / best loss on the material - 1. Intervals are 95% "
        "percentile bootstrap over materials (1000 resamples, seed 0). Fit times are the "
        "median over materials of each fit's wall time in its worker (compile included on "
        "a worker's first fit); evaluation cost is the best of 3 warm jitted evaluations, "
        "ns per sample. " + PER_SAMPLE,
        "",
    ]


def _provenance(res) -> list[str]:
    """Which code and device computed the results; a warning when they are mixed."""
    counts = Counter(r.provenance for r in res.records)
    lines = [f"- computed by: {label} ({n} results)" for label, n in sorted(counts.items())]
    if len(counts) > 1:
        lines.append(
            "- **warning**: the results come from more than one code version or device; "
            "losses and times are not all comparable"
        )
    return lines


def _errors(res) -> list[str]:
    if not res.errors:
        return []
    lines = ["## Errors", "", "| material | model | metric | error |", "|---|---|---|---|"]
    for e in res.errors:
        msg = " ".join(str(e.get("message", "")).split())[:200].replace("|", "/")
        lines.append(f"| {e['material']} | {e['model']} | {e['metric']} | {e['error']}: {msg} |")
    return lines + [""]


def _unreadable(res) -> list[str]:
    """The result files the report left out, each with why
    (:func:`brdffit.selection.sweep_results.load_sweep`)."""
    if not res.unreadable:
        return []
    lines = ["## Unreadable result files (left out of this report)", ""]
    lines += [f"- `{path}`: {why}" for path, why in res.unreadable]
    return lines + [""]


def _figure_line(fig: object | None, note: str, alt: str, name: str, metric: str) -> str:
    """The Markdown image of a saved figure, or the note saying why there is none."""
    return f"![{alt}]({name}_{metric}.png)" if fig is not None else f"_{note}_"


def write_report(
    sweep_dir: str | os.PathLike[str],
    *,
    n_boot: int = 1000,
    seed: int = 0,
    families: str | os.PathLike[str] | None = None,
) -> Path:
    """Write the report of the sweep in ``sweep_dir``; returns the path of ``report.md``.

    ``n_boot`` and ``seed`` set the bootstrap of :func:`brdffit.selection.crossrank.aggregate`;
    ``families`` is a ``material,family`` CSV file whose families replace the recorded
    ones. Raises :class:`brdffit.errors.SweepError` if the folder holds no
    ``sweep.json`` or the families file is not usable. Figures are saved with a tight
    bounding box, so no label is cut off; matplotlib's backend is left as it is (in
    Jupyter, figures drawn after it still show inline).
    """
    res = read_sweep(sweep_dir, families)
    out = Path(sweep_dir) / "report"
    out.mkdir(parents=True, exist_ok=True)
    lines = _header(res)
    for sec in metric_sections(res, n_boot=n_boot, seed=seed):
        metric = sec.metric
        write_text(out / f"aggregate_{metric}.csv", sec.aggregate.csv)
        write_text(out / f"per_material_{metric}.csv", sec.per_material.csv)
        write_text(out / f"pareto_{metric}.csv", sec.pareto.csv)
        write_text(out / f"families_{metric}.csv", sec.families.csv)
        for fig, name in ((sec.rank_matrix, "rank_matrix"), (sec.pareto_plot, "pareto")):
            if fig is not None:
                save_figure(fig, out / f"{name}_{metric}.png", **SAVE)
        lines += [
            f"## Metric `{metric}`",
            "",
            "### Ranking over all materials",
            "",
            sec.aggregate.markdown,
            _figure_line(
                sec.rank_matrix, sec.rank_matrix_note, "rank matrix", "rank_matrix", metric
            ),
            "",
            "### Best models per material family",
            "",
            sec.families.markdown,
            "### Fit error against run time",
            "",
            f"Over which materials: {sec.caption}.",
            "",
            sec.pareto.markdown,
            _figure_line(sec.pareto_plot, sec.pareto_note, "Pareto plot", "pareto", metric),
            "",
            "### Per material",
            "",
        ]
        if sec.inline:
            lines += [sec.per_material.markdown, f"_{NOTE}_", ""]
        else:
            csv = f"per_material_{metric}.csv"
            lines += [f"{sec.n_rows} rows: see [{csv}]({csv}).", ""]
    survivors = survival_table(sweep_dir)  # "" unless the sweep ran with --simplify
    if survivors:
        lines += ["## Model reduction (sweep --simplify)", "", survivors, ""]
    lines += _errors(res)
    lines += _unreadable(res)
    path = out / "report.md"
    write_text(path, "\n".join(lines).rstrip() + "\n")
    return path
