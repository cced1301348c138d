"""What a model reduction found (:func:`brdffit.simplify`): the path, the choice, its readings.

:class:`Reduction` holds the search path (one :class:`PathRow` per fitted variant), the
chosen variant's label and fit, the start model's fit and the settings; it prints the
path as a table and names the features that were removed and those that survive
(:func:`brdffit.selection.variants.features`).
:meth:`Reduction.plot` draws the criterion against the parameter count on axes (an
axes-level method, as pandas' ``.plot``).
"""

from __future__ import annotations

import dataclasses
import html
import json
import math
from dataclasses import dataclass

from brdffit import models
from brdffit.core.result import FitResult, nan_to_none
from brdffit.selection.variants import features
from brdffit.util.text_table import render

DECISIONS = ("start", "kept", "deferred", "passed", "removed", "chosen", "failed")
"""A path row's ``decision``: ``start`` (the start model), ``kept`` (the criterion
rejected the variant: the feature stays), ``deferred`` (rejected at this step, but the
same change was taken at a later step, from the variant reached meanwhile:
:func:`brdffit.selection.simplify._mark_deferred`), ``passed`` (the criterion accepted it, but a
simpler or better variant of the same step was taken), ``removed`` (taken), ``chosen``
(the variant the search ends on) or ``failed`` (its fit was not finite)."""


@dataclass(frozen=True)
class PathRow:
    """One fitted variant: search ``step`` (0 the start), its ``label``, the ``change``
    from its parent, ``n_free`` scalars, the metric's in-sample ``loss``, the criterion
    ``value`` (BIC or held-out loss), and for cv the test against the best model met so
    far on the path (:mod:`brdffit.selection.simplify`): ``held_ratio``, the geometric mean over
    the folds of the held-out loss ratio to it, and ``t``, the mean of the per-fold
    log ratios over its standard error (both NaN for bic and the start); then the
    ``decision`` (:data:`DECISIONS`)."""

    step: int
    label: str
    change: str
    n_free: int
    loss: float
    value: float
    held_ratio: float
    t: float
    decision: str


@dataclass(frozen=True, eq=False, repr=False)
class Reduction:
    """What :func:`brdffit.simplify` found. Fields: ``path`` (rows in search order),
    ``chosen`` (label of the chosen variant, a spec every command accepts), ``result``
    (its fit on all data), ``full`` (the start model's fit), ``cost_ratio`` (jitted
    evaluation time of the chosen over the start model on the data's directions),
    ``criterion``, ``folds`` (0 for bic), ``n_se`` (the CV threshold on t; NaN for bic),
    ``min_gain`` (the CV margin, a fraction of the held-out loss; NaN for bic),
    ``metric``, ``source``."""

    path: tuple[PathRow, ...]
    chosen: str
    result: FitResult
    full: FitResult
    cost_ratio: float
    criterion: str
    folds: int
    n_se: float
    min_gain: float
    metric: str
    source: str

    @property
    def full_label(self) -> str:
        """The start model's label."""
        return models.label(self.full.model, self.full.options)

    @property
    def removed(self) -> tuple[str, ...]:
        """The changes the search took, in order (``clearcoat=false``, ``grey kd``)."""
        return tuple(r.change for r in self.path if r.step and r.decision in ("removed", "chosen"))

    @property
    def kept(self) -> tuple[str, ...]:
        """The removable features the chosen variant still has
        (:func:`brdffit.selection.variants.features`: ``clearcoat``, ``n_lobes=2``, ``RGB kd``)."""
        return features(models.from_spec(self.chosen), frozen=self.full.frozen)

    @property
    def loss_ratio(self) -> float:
        """The chosen variant's in-sample loss over the start model's (>= 1 up to the
        solver's tolerance: the start nests every variant)."""
        return self.result.loss / self.full.loss if self.full.loss else math.nan

    def summary(self) -> dict:
        """The short record a sweep stores per task: ``criterion``, ``start``, ``chosen``,
        ``n_free``, ``n_free_full``, ``loss``, ``loss_full``, ``loss_ratio``,
        ``cost_ratio``, ``removed``, ``kept`` (lists) and ``converged`` (the chosen fit)."""
        return {
            "criterion": self.criterion, "start": self.full_label, "chosen": self.chosen,
            "n_free": self.result.n_free, "n_free_full": self.full.n_free,
            "loss": self.result.loss, "loss_full": self.full.loss, "loss_ratio": self.loss_ratio,
            "cost_ratio": self.cost_ratio, "removed": list(self.removed), "kept": list(self.kept),
            "converged": self.result.converged,
        }  # fmt: skip

    def table(self, fmt: str = "text") -> str:
        """The path as a plain-text, Markdown (``fmt="markdown"``) or HTML (``fmt="html"``:
        a bold title, the table, the choice in small text) table, with the choice."""
        cv = self.criterion == "cv"
        head = ["step", "variant", "change", "k", self.metric, "held-out" if cv else "BIC"]
        head += ["x best", "t", "decision"] if cv else ["decision"]
        body = []
        for r in self.path:
            row = [str(r.step), r.label, r.change, str(r.n_free), f"{r.loss:.6g}", f"{r.value:.6g}"]
            if cv:
                row += ["-", "-"] if math.isnan(r.t) else [f"{r.held_ratio:.4f}", f"{r.t:.2f}"]
            body.append([*row, r.decision])
        how = (
            "BIC, n = residuals (correlated residuals make BIC favour big models)"
            if self.criterion == "bic"
            else f"{self.folds}-fold CV over 10-degree (theta_h, theta_d) blocks dealt evenly "
            f"over both bands; x best: held-out loss over the best's; a feature stays when "
            f"its held-out gain exceeds {self.min_gain:.3g} with t > {self.n_se:.3g}"
        )
        title = f"Simplify {self.full_label} on {self.source} (metric {self.metric}; {how})"
        tail = (
            f"chosen: {self.chosen} ({self.result.n_free} of {self.full.n_free} parameters, "
            f"loss x{self.loss_ratio:.4g} and evaluation cost x{self.cost_ratio:.2f} of the "
            "full model)"
        )
        table = render(head, body, fmt)
        if fmt == "markdown":
            return f"**{title}**\n\n{table}\n\n{tail}"
        if fmt == "html":
            return (
                f'<div class="brdffit-reduction">\n<p><b>{html.escape(title)}</b></p>\n'
                f"{table}<p><small>{html.escape(tail)}</small></p>\n</div>"
            )
        return f"{title}\n{table}\n{tail}"

    def _repr_html_(self) -> str:
        """The path as HTML for Jupyter: :meth:`table` with ``fmt="html"``."""
        return self.table("html")

    def __str__(self) -> str:
        return self.table()

    def __repr__(self) -> str:
        """One line: start model, chosen variant, criterion, variants fitted."""
        return (
            f"<Reduction {self.full_label} -> {self.chosen} by {self.criterion} "
            f"({len(self.path)} variants fitted)>"
        )

    def _repr_pretty_(self, p: object, cycle: bool) -> None:
        """IPython's text form: the text table."""
        p.text(repr(self) if cycle else self.table())

    def to_dict(self) -> dict:
        """JSON-ready form: :meth:`summary`, the settings, the path and both fits
        (:meth:`FitResult.to_dict`)."""
        return {
            **self.summary(), "folds": self.folds, "n_se": self.n_se,
            "min_gain": self.min_gain, "metric": self.metric,
            "source": self.source, "path": [dataclasses.asdict(r) for r in self.path],
            "result": self.result.to_dict(), "full": self.full.to_dict(),
        }  # fmt: skip

    def plot(self, ax=None, y: str = "value"):
        """Criterion (``y="value"``) or in-sample loss (``y="loss"``) against the parameter
        count: every variant, the accepted path as a line, the chosen variant starred.
        Returns the axes."""
        import matplotlib.pyplot as plt  # deferred: heavy, figures only

        if ax is None:
            ax = plt.subplots(figsize=(5.5, 4.0))[1]
        get = (lambda r: r.value) if y == "value" else (lambda r: r.loss)
        ax.plot([r.n_free for r in self.path], [get(r) for r in self.path], "o", color="0.6",
                ms=4, label="variants tried")  # fmt: skip
        walk = [r for r in self.path if r.decision in ("start", "removed", "chosen")]
        ax.plot([r.n_free for r in walk], [get(r) for r in walk], "-", color="C0", label="path")
        pick = next(r for r in self.path if r.decision == "chosen")
        ax.plot([pick.n_free], [get(pick)], "*", color="C3", ms=14, label=pick.label)
        crit = "BIC" if self.criterion == "bic" else f"held-out {self.metric}"
        ax.set_xlabel("free parameters")
        ax.set_ylabel(crit if y == "value" else f"{self.metric} (all data)")
        source = self.source.split(" (", 1)[0]  # the name; the path follows in brackets
        ax.set_title(f"{self.full_label} on {source}", fontsize=9)
        ax.legend(fontsize=8)
        return ax

    def to_json(self, indent: int | None = 2) -> str:
        """The JSON text of :meth:`to_dict` (NaN and Inf written as null)."""
        return json.dumps(nan_to_none(self.to_dict()), indent=indent)
