"""How a :class:`~brdffit.core.result.FitResult` reads: its text report and its HTML.

Both are built from the same fields by the same functions: :func:`title`,
:func:`statistics` (the named lines of the fit's header: metric, noise model, status, ...),
:func:`scalar_rows` (one :class:`ScalarRow` per parameter scalar: label, value and
error, start, flags) and :func:`correlations` (the pairs at or above a threshold).
:func:`report` writes them as text in the spirit of lmfit's ``fit_report``,
:func:`report_html` as HTML tables for Jupyter (``FitResult._repr_html_``).
"""

from __future__ import annotations

import html
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from brdffit.core.result_terms import (
    errors_assumed,
    loss_kind,
    per_sample,
    value_cells,
    value_text,
)
from brdffit.util.text_table import render

if TYPE_CHECKING:  # typing only: FitResult's methods call this module
    from brdffit.core.result import FitResult


@dataclass(frozen=True)
class ScalarRow:
    """One free or frozen parameter scalar as the report shows it: ``label`` (``alpha``,
    ``kd[g]``), ``value`` and ``stderr`` (None when the fit has no errors), ``start``,
    whether the parameter is ``frozen`` or the scalar ``at_bound``, and the ``flags``
    (``at bound``, ``not identified``, ``did not move``) the report prints beside it."""

    label: str
    value: float
    stderr: float | None
    start: float
    frozen: bool
    at_bound: bool
    flags: tuple[str, ...]

    @property
    def text(self) -> str:
        """The value and its error as one text (:func:`brdffit.core.result_terms.value_text`)."""
        return value_text(self.value, self.stderr, frozen=self.frozen, at_bound=self.at_bound)

    @property
    def cells(self) -> tuple[str, str, str]:
        """The value, its error and relative error in % as three texts
        (:func:`brdffit.core.result_terms.value_cells`)."""
        return value_cells(self.value, self.stderr, frozen=self.frozen, at_bound=self.at_bound)


def scalar_rows(r: FitResult) -> list[ScalarRow]:
    """One :class:`ScalarRow` per scalar of every parameter, in the order of ``r.params``."""
    out = []
    for name, value in r.params.items():
        flat = np.atleast_1d(value)
        init = np.atleast_1d(r.init_params.get(name, np.full_like(flat, np.nan)))
        err = None if r.stderr is None else np.atleast_1d(r.stderr[name])
        frozen = name in r.frozen
        for c in range(flat.size):
            label = name if flat.size == 1 else f"{name}[{'rgb'[c]}]"
            v, at = float(flat[c]), label in r.at_bound
            flags = [
                f
                for f, on in (("at bound", at), ("not identified", label in r.not_identified))
                if on
            ]
            if not frozen and np.isclose(v, init[c], rtol=1e-9, atol=0):
                flags.append("did not move")
            e = None if err is None else float(err[c])
            out.append(ScalarRow(label, v, e, float(init[c]), frozen, at, tuple(flags)))
    return out


def title(r: FitResult) -> str:
    """``model(option=value, ...) on source``."""
    opts = ", ".join(f"{k}={v!r}" for k, v in r.options.items())
    return f"{r.model}({opts}) on {r.source}"


def loss_text(metric: str, loss: float, n_samples: int) -> str:
    """``1.59 (sum over 1252 samples; 0.00127 per sample)`` or ``0.0557 (RMS over samples)``."""
    kind = loss_kind(metric)
    if kind != "sum":
        return f"{loss:.6g} ({kind} over samples)"
    mean = per_sample(metric, loss, n_samples)
    return f"{loss:.6g} (sum over {n_samples} samples; {mean:.6g} per sample)"


def statistics(r: FitResult) -> list[tuple[str, str]]:
    """The fit's header as (name, text) pairs: the metric's value as computed and per
    sample, the other metrics, noise model, status, steps, wall time, samples, AIC/BIC
    and the condition number."""
    cut = (
        "no fit angle cut"
        if r.cut_deg is None
        else f"fit's angle cut: theta_i, theta_o < {r.cut_deg:g} deg"
    )
    others = ", ".join(
        f"{k} {loss_text(k, v, r.n_samples)}" for k, v in r.losses.items() if k != r.metric
    )
    robust = f"; {r.robust} loss, scale {r.robust_scale:.3g}" if r.robust else ""
    coarse = (
        f"; starts on {r.coarse_samples} samples, {r.coarse_steps} steps"
        if r.coarse_samples
        else ""
    )
    return [
        ("metric", f"{r.metric} = {loss_text(r.metric, r.loss, r.n_samples)}   ({cut})"),
        ("other metrics", others),
        ("noise model", errors_assumed(r.errors_method, r.error_blocks, r.error_dof) + robust),
        ("status", r.status.value),
        ("steps", f"{r.n_steps} (best of {r.n_starts} starts{coarse})"),
        ("wall time", f"{r.wall_time:.3f} s"),
        ("samples", f"{r.n_samples} ({r.n_data} residuals), {r.n_free} free parameters"),
        ("AIC / BIC", f"{r.aic:.6g} / {r.bic:.6g}   (n = residuals)"),
        ("cond(J^T J)", f"{r.condition_number:.3g}"),
    ]


def correlations(r: FitResult, correl_min: float) -> list[tuple[str, str, float]]:
    """(label, label, C) of the pairs of free scalars with ``|C| >= correl_min``, largest
    ``|C|`` first; none without a correlation matrix."""
    if r.correlation is None:
        return []
    n = len(r.labels)
    pairs = [
        (r.labels[i], r.labels[j], float(r.correlation[i, j]))
        for i in range(n)
        for j in range(i + 1, n)
        if abs(r.correlation[i, j]) >= correl_min
    ]
    return sorted(pairs, key=lambda p: -abs(p[2]))


def report(r: FitResult, correl_min: float = 0.3) -> str:
    """The text report (``FitResult.report``)."""
    lines = [f"[[Fit]] {title(r)}"]
    lines += [f"    {name:<17}{text}" for name, text in statistics(r)]
    lines.append("[[Parameters]]")
    for row in scalar_rows(r):
        flag = f"  [{', '.join(row.flags)}]" if row.flags else ""
        lines.append(f"    {row.label:<14} {row.text:<36} start {row.start:.4g}{flag}")
    if r.errors_reason:
        lines.append(f"    (no uncertainties: {r.errors_reason})")
    pairs = correlations(r, correl_min)
    if pairs:
        lines.append(f"[[Correlations]] (|C| >= {correl_min})")
        lines += [f"    C({a}, {b}) = {c:+.4f}" for a, b, c in pairs]
    lines += [f"[[Warning]] {w}" for w in r.warnings]
    return "\n".join(lines)


PARAMETER_HEAD = ("parameter", "value", "± stderr", "relative %", "start", "flags")
"""The columns of the HTML parameter table."""


def report_html(r: FitResult, correl_min: float = 0.3) -> str:
    """The report as HTML (``FitResult._repr_html_``): a bold title, a statistics table,
    a parameter table (:data:`PARAMETER_HEAD`, one row per scalar), the reason for missing
    uncertainties, the correlations ``|C| >= correl_min`` as a table, and the warnings.
    Every text is escaped; no style sheet."""
    esc = html.escape
    body = [
        [row.label, *row.cells, f"{row.start:.4g}", ", ".join(row.flags)] for row in scalar_rows(r)
    ]
    out = [
        '<div class="brdffit-fit">',
        f"<p><b>Fit: {esc(title(r))}</b></p>",
        render(("statistic", "value"), statistics(r), "html"),
        "<p><b>Parameters</b></p>",
        render(PARAMETER_HEAD, body, "html"),
    ]
    if r.errors_reason:
        out.append(f"<p><small>(no uncertainties: {esc(r.errors_reason)})</small></p>")
    pairs = correlations(r, correl_min)
    if pairs:
        out.append(f"<p><b>Correlations</b> (|C| &gt;= {correl_min:g})</p>")
        rows = [[a, b, f"{c:+.4f}"] for a, b, c in pairs]
        out.append(render(("parameter 1", "parameter 2", "C"), rows, "html"))
    out += [f'<p style="color:#a33">Warning: {esc(w)}</p>' for w in r.warnings]
    return "\n".join([*(x.rstrip("\n") for x in out), "</div>"])
