"""Ranking of models fitted to one data set: by the metric, by AIC and by BIC.

AIC and BIC (see :mod:`brdffit.engine.fit`) treat the ``n`` residuals the LM minimised (three
RGB channels per valid sample inside the angle cut) as independent Gaussian with one
free variance: ``AIC = n ln(RSS/n) + 2k``, ``BIC = n ln(RSS/n) + k ln n``, ``k`` the free
parameters plus one. On measured data neighbouring samples share the same model
error, so the effective ``n`` is far smaller than the count: the penalty for extra
parameters is then too weak and differences of a few units mean little. The metric
column is the number to quote; AIC/BIC order models of similar error by complexity.

Ties: losses within a relative :data:`LOSS_RTOL` of each other are equal and share the
average of the ranks they span (two models tied for first both get 1.5); AIC and BIC
tie only when exactly equal.

A fit that did not converge (``MAX_STEPS``) but has a finite loss is ranked by that
loss and marked: its loss is one the model reached, so the model's best is at least
that good, and ranking it last would hide a model that beat the others even unfinished.
Only non-finite values (a failed fit) rank last, tied with each other.

Losses: ``low_e1`` and ``low_e2`` are sums over samples; the table gives them per
sample beside the sum (:func:`brdffit.core.result_terms.per_sample`), the number to compare
between fits on different sub-grids.
"""

from __future__ import annotations

import html
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from brdffit import models
from brdffit.core.result import FitResult
from brdffit.core.result_terms import loss_kind
from brdffit.engine.fit import fit
from brdffit.errors import ParameterError
from brdffit.models import label
from brdffit.util.progress import progress_bar, progress_line
from brdffit.util.text_table import render

LOSS_RTOL = 1e-5
"""Relative loss difference below which two fits tie.

A descent stops when a chunk of LM steps lowers the loss by less than 1e-9 relative
(:mod:`brdffit.engine.fit`), so one model's converged loss is reproducible to about that. Nested
models are not that close: a model that contains another as a special case (Oren-Nayar
at sigma = 0 is Lambert) approaches the boundary through a transformed parameter that
never reaches it, while the smaller model sits on it, so the two converge to the same
fit from different sides. On the 100 NBRDF materials Oren-Nayar stopped up to 3.5e-6
relative above Lambert. 1e-5 covers that with a factor 3 to spare and is still 1e4 times
the stopping tolerance; a real difference between models smaller than 1e-5 is not one to
rank by.
"""

TIES = (
    f"Losses within a relative {LOSS_RTOL:g} tie and share their average rank; a fit that "
    "did not converge is ranked by the loss it reached and marked, a failed fit (no finite "
    "loss) ranks last."
)

PER_SAMPLE = (
    "low_e1 and low_e2 are sums over the samples; 'per sample' divides them by the sample "
    "count (ngan, an RMS, and log1p_l1, a mean, are per sample already): compare fits on "
    "different sub-grids by it."
)

NOTE = (
    "n = residuals (3 x samples); samples with correlated model error make the effective "
    "n smaller, so AIC/BIC differences overstate the evidence."
)


@dataclass(frozen=True)
class RankRow:
    """One model's line: name and options, loss (as the metric defines it, and per
    sample), AIC/BIC and their deltas, ranks, status (:class:`brdffit.Status` name).

    Ranks are 1-based and tied values share their average (module docstring), so a
    rank may be fractional (2.5).
    """

    model: str
    options: str
    loss: float
    aic: float
    bic: float
    delta_aic: float
    delta_bic: float
    rank_loss: float
    rank_aic: float
    rank_bic: float
    n_free: int
    converged: bool
    wall_time: float
    loss_per_sample: float = float("nan")
    status: str = "CONVERGED"


@dataclass(frozen=True, repr=False)
class Ranking:
    """Models fitted to one data set under one metric, best first by ``by``."""

    metric: str
    source: str
    n_data: int
    by: str
    rows: tuple[RankRow, ...]

    def table(self, fmt: str = "text") -> str:
        """The ranking as a plain-text, Markdown (``fmt="markdown"``) or HTML (``fmt="html"``:
        a bold title, the table and the notes in small text) table, or CSV (the table only)."""
        head = [
            "rank",
            "model",
            "options",
            f"{self.metric} ({loss_kind(self.metric)})",
            f"{self.metric} per sample",
            "AIC",
            "dAIC",
            "BIC",
            "dBIC",
            "k",
            "converged",
            "time (s)",
        ]
        body = [
            [
                rank_text(getattr(r, f"rank_{self.by}")),
                r.model,
                r.options or "-",
                f"{r.loss:.6g}",
                f"{r.loss_per_sample:.6g}",
                f"{r.aic:.6g}",
                f"{r.delta_aic:.1f}",
                f"{r.bic:.6g}",
                f"{r.delta_bic:.1f}",
                str(r.n_free),
                "yes" if r.converged else f"NO ({r.status})",
                f"{r.wall_time:.2f}",
            ]
            for r in self.rows
        ]
        table = render(head, body, fmt)
        if fmt == "csv":
            return table
        title = self._title()
        if fmt == "markdown":
            return f"**{title}**\n\n{table}\n_{TIES} {PER_SAMPLE} {NOTE}_"
        if fmt == "html":
            notes = "<br>".join(html.escape(n) for n in (TIES, PER_SAMPLE, NOTE))
            return (
                f'<div class="brdffit-ranking">\n<p><b>{html.escape(title)}</b></p>\n'
                f"{table}<p><small>{notes}</small></p>\n</div>"
            )
        return f"{title}\n{table}{TIES}\n{PER_SAMPLE}\n{NOTE}"

    def _title(self) -> str:
        return f"Ranking by {self.by} on {self.source} (metric {self.metric}, n = {self.n_data})"

    def _repr_html_(self) -> str:
        """The ranking as HTML for Jupyter: :meth:`table` with ``fmt="html"``."""
        return self.table("html")

    def __str__(self) -> str:
        return self.table()

    def __repr__(self) -> str:
        """One line: criterion, source, metric, the number of models and the first."""
        best = self.rows[0].model if self.rows else "none"
        return (
            f"<Ranking by {self.by} on {self.source} ({self.metric}): "
            f"{len(self.rows)} models, best {best}>"
        )

    def _repr_pretty_(self, p: object, cycle: bool) -> None:
        """IPython's text form: the text table."""
        p.text(repr(self) if cycle else self.table())

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {
            "metric": self.metric,
            "source": self.source,
            "n_data": self.n_data,
            "by": self.by,
            "rows": [r.__dict__ for r in self.rows],
        }


def _changed_options(r: FitResult) -> str:
    """The static options that differ from the model's defaults: the ``k=v,...`` of its label."""
    return models.label(r.model, r.options).partition("[")[2].removesuffix("]")


def rank_text(r: float) -> str:
    """A rank as text: ``3`` or, for a tie, ``2.5``."""
    return f"{r:g}"


def ranks(values: np.ndarray, rtol: float = 0.0) -> np.ndarray:
    """1-based ranks of ``values`` (smaller is better), ties sharing their average rank.

    Sorted values tie with the first (smallest) value of their group while
    ``|v - first| <= rtol * max(|v|, |first|)``; a group spanning ranks ``i..j`` gets
    ``(i + j) / 2``. Anchoring on the group's first value keeps a chain of small steps
    from merging values further apart than ``rtol``. Non-finite values rank last, tied
    with each other. Use ``rtol=`` :data:`LOSS_RTOL` for losses.
    """
    key = np.asarray(values, float)
    key = np.where(np.isfinite(key), key, np.inf)
    order = np.argsort(key, kind="stable")
    out = np.empty(len(key), float)
    start = 0
    for pos in range(1, len(order) + 1):
        if pos < len(order) and _tied(key[order[start]], key[order[pos]], rtol):
            continue
        out[order[start:pos]] = (start + 1 + pos) / 2
        start = pos
    return out


def _tied(a: float, b: float, rtol: float) -> bool:
    """Equal within ``rtol`` relative; the non-finite stand-in ``inf`` ties only with itself."""
    if np.isinf(a) or np.isinf(b):
        return bool(a == b)
    return bool(abs(b - a) <= rtol * max(abs(a), abs(b)))


def fit_models(
    models_: Sequence[object],
    data: object,
    metric: str,
    *,
    progress: bool = True,
    **fit_kwargs: object,
) -> list[FitResult]:
    """Fit each model to ``data`` under ``metric`` (:func:`brdffit.fit`, ``throw=False``),
    in order, for :func:`rank`.

    ``progress``: a bar on stderr and, as each fit ends, a line ``rank: <label>  <s> s
    <metric> <loss> (<status>)``. ``fit_kwargs`` go to :func:`brdffit.fit`.
    """
    bar = progress_bar(len(models_), "rank", "fit", progress)
    out = []
    try:
        for m in models_:
            bar.set_postfix_str(label(m), refresh=True)
            t0 = time.perf_counter()
            r = fit(m, data, metric, throw=False, **fit_kwargs)
            state = "converged" if r.converged else r.status.name
            progress_line(
                bar,
                f"rank: {label(m)}  {time.perf_counter() - t0:.1f} s  {r.metric} "
                f"{r.loss:.6g} ({state})",
            )
            bar.update(1)
            out.append(r)
    finally:
        bar.close()
    return out


def rank(results: Sequence[FitResult], *, by: str = "loss") -> Ranking:
    """Rank fits of several models to the same data under the same metric.

    Arguments:
    - ``results``: :class:`FitResult` of one data set, one metric, any models.
    - ``by``: ``"loss"`` (the metric), ``"aic"`` or ``"bic"``; rows are sorted by it.
      A fit that did not converge is ranked by its finite values and marked; non-finite
      values rank last; ties as in the module docstring, tied rows in the order given.

    Raises :class:`ParameterError` if the results mix metrics or data sets.
    """
    if not results:
        raise ParameterError("rank needs at least one FitResult")
    if by not in ("loss", "aic", "bic"):
        raise ParameterError(f"by={by!r}: use 'loss', 'aic' or 'bic'")
    metrics = {r.metric for r in results}
    data = {(r.source, r.n_data) for r in results}
    if len(metrics) > 1 or len(data) > 1:
        raise ParameterError(
            f"rank compares fits of one data set under one metric; got metrics "
            f"{sorted(metrics)} and data {sorted(data)}"
        )

    def col(name: str) -> np.ndarray:
        return np.array([getattr(r, name) for r in results], float)

    loss, aic, bic = col("loss"), col("aic"), col("bic")
    rk = {"loss": ranks(loss, LOSS_RTOL), "aic": ranks(aic), "bic": ranks(bic)}
    rows = [
        RankRow(
            model=r.model,
            options=_changed_options(r),
            loss=r.loss,
            aic=r.aic,
            bic=r.bic,
            delta_aic=_delta(r.aic, aic),
            delta_bic=_delta(r.bic, bic),
            rank_loss=float(rk["loss"][i]),
            rank_aic=float(rk["aic"][i]),
            rank_bic=float(rk["bic"][i]),
            n_free=r.n_free,
            converged=r.converged,
            wall_time=r.wall_time,
            loss_per_sample=r.loss_per_sample,
            status=r.status.name,
        )
        for i, r in enumerate(results)
    ]
    rows.sort(key=lambda row: getattr(row, f"rank_{by}"))
    first = results[0]
    return Ranking(first.metric, first.source, first.n_data, by, tuple(rows))


def _delta(value: float, column: np.ndarray) -> float:
    """``value`` minus the smallest finite value of ``column`` (NaN if there is none)."""
    finite = column[np.isfinite(column)]
    return float(value - finite.min()) if finite.size else float("nan")
