"""Ranking of models fitted to one data set: by the metric, by AIC and by BIC.

AIC and BIC (see :mod:`brdffit.fit`) treat the ``n`` residuals the LM minimised (three
RGB channels per valid sample inside the angle cut) as independent Gaussian with one
free variance: ``AIC = n ln(RSS/n) + 2k``, ``BIC = n ln(RSS/n) + k ln n``, ``k`` the free
parameters plus one. On measured data neighbouring samples share the same model
error, so the effective ``n`` is far smaller than the count: the penalty for extra
parameters is then too weak and differences of a few units mean little. The metric
column is the number to quote; AIC/BIC order models of similar error by complexity.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from brdffit.errors import ParameterError
from brdffit.result import FitResult
from brdffit.tables import render

NOTE = (
    "n = residuals (3 x samples); samples with correlated model error make the effective "
    "n smaller, so AIC/BIC differences overstate the evidence."
)


@dataclass(frozen=True)
class RankRow:
    """One model's line: name and options, loss, AIC/BIC and their deltas, ranks."""

    model: str
    options: str
    loss: float
    aic: float
    bic: float
    delta_aic: float
    delta_bic: float
    rank_loss: int
    rank_aic: int
    rank_bic: int
    n_free: int
    converged: bool
    wall_time: float


@dataclass(frozen=True)
class Ranking:
    """Models fitted to one data set under one metric, best first by ``by``."""

    metric: str
    source: str
    n_data: int
    by: str
    rows: tuple[RankRow, ...]

    def table(self, fmt: str = "text") -> str:
        """The ranking as a plain-text or Markdown (``fmt="markdown"``) table, or CSV."""
        head = [
            "rank",
            "model",
            "options",
            self.metric,
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
                str(getattr(r, f"rank_{self.by}")),
                r.model,
                r.options or "-",
                f"{r.loss:.6g}",
                f"{r.aic:.6g}",
                f"{r.delta_aic:.1f}",
                f"{r.bic:.6g}",
                f"{r.delta_bic:.1f}",
                str(r.n_free),
                "yes" if r.converged else "NO",
                f"{r.wall_time:.2f}",
            ]
            for r in self.rows
        ]
        table = render(head, body, fmt)
        if fmt == "csv":
            return table
        title = f"Ranking by {self.by} on {self.source} (metric {self.metric}, n = {self.n_data})"
        if fmt == "markdown":
            return f"**{title}**\n\n{table}\n_{NOTE}_"
        return f"{title}\n{table}{NOTE}"

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
    """The static options that differ from the model's defaults, as ``k=v`` text."""
    from brdffit import models

    try:
        default = models.get(r.model).options()
    except ParameterError:  # a model no longer registered: show every option
        default = {}
    return ", ".join(f"{k}={v}" for k, v in r.options.items() if default.get(k, object()) != v)


def _ranks(values: np.ndarray) -> np.ndarray:
    """1-based ranks, NaN last."""
    order = np.argsort(np.where(np.isfinite(values), values, np.inf), kind="stable")
    out = np.empty(len(values), int)
    out[order] = np.arange(1, len(values) + 1)
    return out


def rank(results: Sequence[FitResult], *, by: str = "loss") -> Ranking:
    """Rank fits of several models to the same data under the same metric.

    Arguments:
    - ``results``: :class:`FitResult` of one data set, one metric, any models.
    - ``by``: ``"loss"`` (the metric), ``"aic"`` or ``"bic"``; rows are sorted by it.
      Unconverged fits keep their numbers but are ranked last.

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
    ok = np.array([r.converged for r in results])

    def col(name: str) -> np.ndarray:
        v = np.array([getattr(r, name) for r in results], float)
        return np.where(ok, v, np.nan)

    loss, aic, bic = col("loss"), col("aic"), col("bic")
    rk = {"loss": _ranks(loss), "aic": _ranks(aic), "bic": _ranks(bic)}
    rows = [
        RankRow(
            model=r.model,
            options=_changed_options(r),
            loss=r.loss,
            aic=r.aic,
            bic=r.bic,
            delta_aic=r.aic - np.nanmin(aic) if ok.any() else float("nan"),
            delta_bic=r.bic - np.nanmin(bic) if ok.any() else float("nan"),
            rank_loss=int(rk["loss"][i]),
            rank_aic=int(rk["aic"][i]),
            rank_bic=int(rk["bic"][i]),
            n_free=r.n_free,
            converged=r.converged,
            wall_time=r.wall_time,
        )
        for i, r in enumerate(results)
    ]
    rows.sort(key=lambda row: getattr(row, f"rank_{by}"))
    first = results[0]
    return Ranking(first.metric, first.source, first.n_data, by, tuple(rows))
