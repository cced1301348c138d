"""`FitResult`: what a Levenberg-Marquardt fit found, its report and its JSON form.

The report (text) and its HTML form are written by :mod:`brdffit.core.result_text`.

Losses per sample: ``low_e1`` and ``low_e2`` are sums over the samples (RGB summed within
each), so the same material fitted on a strided sub-grid and on the full grid gives
sums that differ by the ratio of sample counts (56x between ``--stride 3 3 5`` and
the full grid on one measured material). :func:`~brdffit.core.result_terms.per_sample`
divides them by the sample count; ``ngan`` (a solid-angle weighted RMS) and ``log1p_l1``
(a mean) are normalised already and are their own per-sample value. Reports and JSON
give both, named.
"""

from __future__ import annotations

import enum
import json
import math
from dataclasses import dataclass, field

import numpy as np

from brdffit.core import result_text
from brdffit.core.result_terms import (
    SUMMED_METRICS,
    loss_kind,
    per_sample,
)


class Status(enum.Enum):
    """How a fit ended; each member's value is a readable message."""

    CONVERGED = "converged: gradient, loss or step change below the tolerances"
    MAX_STEPS = "not converged: stopped at max_steps"
    NONFINITE = "failed: the loss or the parameters became NaN or Inf"
    SOLVER_FAILED = "failed: the solver reported an error"


def _floats(a: object) -> list[float] | float:
    arr = np.asarray(a, dtype=float)
    return float(arr) if arr.ndim == 0 else arr.tolist()


@dataclass(frozen=True, eq=False, repr=False)
class FitResult:
    """The outcome of :func:`brdffit.fit`; every field is always present.

    Parameters are in natural units. ``stderr`` and ``covariance`` are ``None`` with
    ``errors_reason`` saying why when they cannot be computed. ``covariance`` and
    ``correlation`` are over the free scalars named by ``labels``.

    Fields: ``model`` (registry name), ``options`` (static options), ``metric``,
    ``params`` / ``init_params`` (name -> array), ``stderr`` (name -> array, frozen
    parameters 0), ``covariance``, ``correlation``, ``labels``, ``frozen`` (names),
    ``errors_method`` ("sandwich", "classic" or "blocks"), ``errors_reason``, ``loss`` (the
    metric's value: a sum, RMS or mean, :func:`loss_kind`; per sample:
    :attr:`loss_per_sample`), ``losses`` (every metric, same samples), ``cost`` (``0.5 sum r^2``
    LM minimised), ``n_samples``, ``n_data`` (residuals = 3 x samples), ``n_free``,
    ``aic``, ``bic``, ``condition_number`` (of the column-scaled ``J^T J``),
    ``status``, ``n_steps``, ``n_starts``, ``wall_time`` (s), ``cut_deg``, ``source``,
    ``at_bound`` (labels of the free scalars, ``alpha`` or ``kd[b]`` as in ``labels``,
    within :data:`AT_BOUND_RTOL` / :data:`AT_BOUND_ATOL` of a bound or held on it),
    ``warnings``, ``not_identified`` (labels of the free scalars the data do not pin
    down, :func:`brdffit.engine.assembly.unidentified`), ``coarse_samples`` /
    ``coarse_steps`` (the starts' thinned stage: its sample count, 0 when the starts
    ran on all samples, and its steps summed over starts, the descents under the other
    metric for the extra start and the winner's refinement on more thinned samples
    (:func:`brdffit.engine.batch.refine_size`) included;
    ``n_steps`` counts the winner's steps on all samples), ``robust`` /
    ``robust_scale`` (the robust loss and its scale in residual units, or None),
    ``error_blocks`` (the blocks of ``errors="blocks"``, else 0), ``error_dof`` (name ->
    array: each free scalar's effective degrees of freedom under ``errors="blocks"``,
    whose ``stderr`` is widened so that ``value +/- 1.96 stderr`` is the Student-t 95%
    interval of these degrees; NaN for scalars without an error; None for the other
    kinds, :mod:`brdffit.engine.uncertainty`).
    """

    model: str
    options: dict
    metric: str
    params: dict[str, np.ndarray]
    init_params: dict[str, np.ndarray]
    stderr: dict[str, np.ndarray] | None
    covariance: np.ndarray | None
    correlation: np.ndarray | None
    labels: tuple[str, ...]
    frozen: tuple[str, ...]
    errors_method: str
    errors_reason: str | None
    loss: float
    losses: dict[str, float]
    cost: float
    n_samples: int
    n_data: int
    n_free: int
    aic: float
    bic: float
    condition_number: float
    status: Status
    n_steps: int
    n_starts: int
    wall_time: float
    cut_deg: float | None
    source: str
    at_bound: tuple[str, ...] = ()
    warnings: tuple[str, ...] = field(default_factory=tuple)
    not_identified: tuple[str, ...] = ()
    coarse_samples: int = 0
    coarse_steps: int = 0
    robust: str | None = None
    robust_scale: float | None = None
    error_blocks: int = 0
    error_dof: dict[str, np.ndarray] | None = None

    @property
    def converged(self) -> bool:
        """True only for a finished, finite fit."""
        return self.status is Status.CONVERGED

    @property
    def loss_per_sample(self) -> float:
        """``loss`` per sample (:func:`per_sample`): comparable across sub-grids."""
        return per_sample(self.metric, self.loss, self.n_samples)

    @property
    def losses_per_sample(self) -> dict[str, float]:
        """Every metric of ``losses`` per sample (:func:`per_sample`)."""
        return {k: per_sample(k, v, self.n_samples) for k, v in self.losses.items()}

    def to_dict(self) -> dict:
        """JSON-ready dict (arrays as lists of floats)."""
        return {
            "model": self.model,
            "options": {k: v for k, v in self.options.items()},
            "metric": self.metric,
            "params": {k: _floats(v) for k, v in self.params.items()},
            "init_params": {k: _floats(v) for k, v in self.init_params.items()},
            "stderr": None
            if self.stderr is None
            else {k: _floats(v) for k, v in self.stderr.items()},
            "covariance": None if self.covariance is None else self.covariance.tolist(),
            "correlation": None if self.correlation is None else self.correlation.tolist(),
            "labels": list(self.labels),
            "frozen": list(self.frozen),
            "errors_method": self.errors_method,
            "errors_reason": self.errors_reason,
            "loss": self.loss,
            "loss_kind": loss_kind(self.metric),
            "loss_per_sample": self.loss_per_sample,
            "losses": dict(self.losses),
            "losses_per_sample": self.losses_per_sample,
            "cost": self.cost,
            "n_samples": self.n_samples,
            "n_data": self.n_data,
            "n_free": self.n_free,
            "aic": self.aic,
            "bic": self.bic,
            "condition_number": self.condition_number,
            "status": self.status.name,
            "converged": self.converged,
            "n_steps": self.n_steps,
            "n_starts": self.n_starts,
            "wall_time": self.wall_time,
            "cut_deg": self.cut_deg,
            "source": self.source,
            "at_bound": list(self.at_bound),
            "warnings": list(self.warnings),
            "not_identified": list(self.not_identified),
            "coarse_samples": self.coarse_samples,
            "coarse_steps": self.coarse_steps,
            "robust": self.robust,
            "robust_scale": self.robust_scale,
            "error_blocks": self.error_blocks,
            "error_dof": None
            if self.error_dof is None
            else {k: _floats(v) for k, v in self.error_dof.items()},
        }

    def to_json(self, indent: int | None = 2) -> str:
        """The JSON text of :meth:`to_dict` (NaN and Inf written as null)."""
        return json.dumps(nan_to_none(self.to_dict()), indent=indent)

    @classmethod
    def from_dict(cls, d: dict) -> FitResult:
        """Rebuild a result from :meth:`to_dict` output (e.g. a sweep's JSON file)."""

        def arrays(m: dict | None) -> dict | None:
            return None if m is None else {k: np.asarray(v, float) for k, v in m.items()}

        def num(x: object) -> float:
            return float("nan") if x is None else float(x)

        return cls(
            model=d["model"],
            options=dict(d.get("options", {})),
            metric=d["metric"],
            params=arrays(d["params"]),
            init_params=arrays(d.get("init_params", {})),
            stderr=arrays(d.get("stderr")),
            covariance=None if d.get("covariance") is None else np.asarray(d["covariance"]),
            correlation=None if d.get("correlation") is None else np.asarray(d["correlation"]),
            labels=tuple(d.get("labels", ())),
            frozen=tuple(d.get("frozen", ())),
            errors_method=d.get("errors_method", "sandwich"),
            errors_reason=d.get("errors_reason"),
            loss=num(d["loss"]),
            losses={k: num(v) for k, v in d.get("losses", {}).items()},
            cost=num(d.get("cost")),
            n_samples=int(d.get("n_samples", 0)),
            n_data=int(d.get("n_data", 0)),
            n_free=int(d.get("n_free", 0)),
            aic=num(d.get("aic")),
            bic=num(d.get("bic")),
            condition_number=num(d.get("condition_number")),
            status=Status[d["status"]],
            n_steps=int(d.get("n_steps", 0)),
            n_starts=int(d.get("n_starts", 1)),
            wall_time=num(d.get("wall_time")),
            cut_deg=d.get("cut_deg"),
            source=d.get("source", "unknown"),
            at_bound=scalar_labels(d.get("at_bound", ()), d["params"]),
            warnings=tuple(d.get("warnings", ())),
            not_identified=tuple(d.get("not_identified", ())),
            coarse_samples=int(d.get("coarse_samples", 0)),
            coarse_steps=int(d.get("coarse_steps", 0)),
            robust=d.get("robust"),
            robust_scale=d.get("robust_scale"),
            error_blocks=int(d.get("error_blocks", 0)),
            error_dof=arrays(d.get("error_dof")),
        )

    def report(self, correl_min: float = 0.3) -> str:
        """Human-readable report in the spirit of lmfit's ``fit_report``
        (:func:`brdffit.core.result_text.report`).

        Each scalar is ``value +/- error (relative %)``; a scalar without a finite error
        says so in words (``0 (at bound; no error)``), and the flags ``at bound``, ``not
        identified`` and ``did not move`` name only the channels they concern. The
        metric's value is given as computed (a sum, RMS or mean) and per sample.
        """
        return result_text.report(self, correl_min)

    def _repr_html_(self) -> str:
        """The report as HTML tables for Jupyter, from the same fields as :meth:`report`."""
        return result_text.report_html(self)

    def __str__(self) -> str:
        return self.report()

    def __repr__(self) -> str:
        """One line: ``<FitResult walter low_e2=1.234 (per sample 5.6e-05), 7 free, CONVERGED>``."""
        per = (
            "" if self.metric not in SUMMED_METRICS else f" (per sample {self.loss_per_sample:.4g})"
        )
        return (
            f"<FitResult {self.model} {self.metric}={self.loss:.4g}{per}, "
            f"{self.n_free} free, {self.status.name}>"
        )

    def _repr_pretty_(self, p: object, cycle: bool) -> None:
        """IPython's text form: the report."""
        p.text(repr(self) if cycle else self.report())


def scalar_labels(names: object, params: dict) -> tuple[str, ...]:
    """Per-scalar labels from ``at_bound`` as stored: labels kept; a bare name of an RGB
    parameter (results written before the labels) becomes its three channel labels."""
    out: list[str] = []
    for lab in names or ():
        value = params.get(lab)
        if "[" in lab or value is None or np.size(value) == 1:
            out.append(lab)
        else:
            out += [f"{lab}[{c}]" for c in "rgb"]
    return tuple(out)


def nan_to_none(x: object) -> object:
    """NaN and Inf -> None, numpy scalars -> Python, recursively (strict JSON)."""
    if isinstance(x, dict):
        return {str(k): nan_to_none(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [nan_to_none(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x
