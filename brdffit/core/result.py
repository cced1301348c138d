"""`FitResult`: what a Levenberg-Marquardt fit found, its report and its JSON form.

Losses per sample: ``low_e1`` and ``low_e2`` are sums over the samples (RGB summed within
each), so the same material fitted on a strided sub-grid and on the full grid gives
sums that differ by the ratio of sample counts (56x between ``--stride 3 3 5`` and
the full grid on one measured material). :func:`per_sample` divides them by the sample
count; ``ngan`` (a solid-angle weighted RMS) and ``log1p_l1`` (a mean) are normalised
already and are their own per-sample value. Reports and JSON give both, named.
"""

from __future__ import annotations

import enum
import html
import json
import math
from dataclasses import dataclass, field

import numpy as np

AT_BOUND_RTOL = 1e-6
"""A free scalar within this relative distance of a bound is flagged ``at bound``."""

AT_BOUND_ATOL = 1e-9
"""... or within this absolute distance (bounds at 0); such a value is printed as 0."""

SUMMED_METRICS = ("low_e1", "low_e2")
"""Metrics whose loss is a sum over samples (:mod:`brdffit.engine.metrics`: unnormalised
``sin theta_i`` weights); the others are a weighted RMS (``ngan``) or a mean
(``log1p_l1``)."""


#: The side, in degrees of (theta_h, theta_d), of the blocks that ``errors="blocks"``
#: treats as independent (:func:`brdffit.engine.uncertainty.block_covariance`).
BLOCK_DEG = 10.0


def errors_assumed(method: str, n_blocks: int = 0) -> str:
    """What the standard errors of ``method`` (``sandwich``, ``classic``, ``blocks``) assume,
    in the words reports print beside them."""
    if method == "classic":
        return "residuals independent, one variance; errors by classic (s^2 (J^T J)^-1)"
    if method == "blocks":
        return (
            f"residuals correlated within {BLOCK_DEG:g}-degree (theta_h, theta_d) blocks, "
            f"independent between them; errors by block jackknife over {n_blocks} blocks"
        )
    return "residuals independent, any variance; errors by sandwich"


def per_sample(metric: str, loss: float, n_samples: int) -> float:
    """The loss of ``metric`` per sample (module docstring): ``loss / n_samples`` for the
    summed metrics, ``loss`` itself for the normalised ones; NaN without samples."""
    if metric not in SUMMED_METRICS:
        return float(loss)
    return float(loss) / n_samples if n_samples > 0 else float("nan")


def loss_kind(metric: str) -> str:
    """What a loss value of ``metric`` is: ``"sum"``, ``"RMS"`` or ``"mean"`` over samples."""
    if metric in SUMMED_METRICS:
        return "sum"
    return "RMS" if metric == "ngan" else "mean"


class Status(enum.Enum):
    """How a fit ended; each member's value is a readable message."""

    CONVERGED = "converged: gradient, loss or step change below the tolerances"
    MAX_STEPS = "not converged: stopped at max_steps"
    NONFINITE = "failed: the loss or the parameters became NaN or Inf"
    SOLVER_FAILED = "failed: the solver reported an error"


def _floats(a: object) -> list[float] | float:
    arr = np.asarray(a, dtype=float)
    return float(arr) if arr.ndim == 0 else arr.tolist()


@dataclass(frozen=True, eq=False)
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
    down, :func:`brdffit.engine.uncertainty.unidentified`), ``coarse_samples`` /
    ``coarse_steps`` (the starts' thinned stage: its sample count, 0 when the starts
    ran on all samples, and its steps summed over starts, the descents under the other
    metric for the extra start included;
    ``n_steps`` counts the winner's steps on all samples), ``robust`` /
    ``robust_scale`` (the robust loss and its scale in residual units, or None),
    ``error_blocks`` (the blocks of ``errors="blocks"``, else 0).
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
        )

    def _coarse_text(self) -> str:
        if not self.coarse_samples:
            return ""
        return f"; starts on {self.coarse_samples} samples, {self.coarse_steps} steps"

    def report(self, correl_min: float = 0.3) -> str:
        """Human-readable report in the spirit of lmfit's ``fit_report``.

        Each scalar is ``value +/- error (relative %)``; a scalar without a finite error
        says so in words (``0 (at bound; no error)``), and the flags ``at bound``, ``not
        identified`` and ``did not move`` name only the channels they concern. The
        metric's value is given as computed (a sum, RMS or mean) and per sample.
        """
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options.items())
        cut = "no angle cut" if self.cut_deg is None else f"theta_i, theta_o < {self.cut_deg:g} deg"
        others = ", ".join(
            f"{k} {_loss_text(k, v, self.n_samples)}"
            for k, v in self.losses.items()
            if k != self.metric
        )
        lines = [
            f"[[Fit]] {self.model}({opts}) on {self.source}",
            f"    metric           {self.metric} = "
            f"{_loss_text(self.metric, self.loss, self.n_samples)}   ({cut})",
            f"    other metrics    {others}",
            f"    noise model      {errors_assumed(self.errors_method, self.error_blocks)}"
            + (f"; {self.robust} loss, scale {self.robust_scale:.3g}" if self.robust else ""),
            f"    status           {self.status.value}",
            f"    steps            {self.n_steps} "
            f"(best of {self.n_starts} starts{self._coarse_text()})",
            f"    wall time        {self.wall_time:.3f} s",
            f"    samples          {self.n_samples} ({self.n_data} residuals), "
            f"{self.n_free} free parameters",
            f"    AIC / BIC        {self.aic:.6g} / {self.bic:.6g}   (n = residuals)",
            f"    cond(J^T J)      {self.condition_number:.3g}",
            "[[Parameters]]",
        ]
        for name, value in self.params.items():
            lines += self._parameter_lines(name, value)
        if self.errors_reason:
            lines.append(f"    (no uncertainties: {self.errors_reason})")
        lines += self._correlation_lines(correl_min)
        for w in self.warnings:
            lines.append(f"[[Warning]] {w}")
        return "\n".join(lines)

    def _parameter_lines(self, name: str, value: np.ndarray) -> list[str]:
        """One report line per scalar of parameter ``name``."""
        flat = np.atleast_1d(value)
        init = np.atleast_1d(self.init_params.get(name, np.full_like(flat, np.nan)))
        err = None if self.stderr is None else np.atleast_1d(self.stderr[name])
        out = []
        for c in range(flat.size):
            label = name if flat.size == 1 else f"{name}[{'rgb'[c]}]"
            v, frozen, at = float(flat[c]), name in self.frozen, label in self.at_bound
            text = value_text(v, None if err is None else float(err[c]), frozen=frozen, at_bound=at)
            flags = [
                f
                for f, on in (("at bound", at), ("not identified", label in self.not_identified))
                if on
            ]
            if not frozen and np.isclose(v, init[c], rtol=1e-9, atol=0):
                flags.append("did not move")
            flag = f"  [{', '.join(flags)}]" if flags else ""
            out.append(f"    {label:<14} {text:<36} start {init[c]:.4g}{flag}")
        return out

    def _correlation_lines(self, correl_min: float) -> list[str]:
        if self.correlation is None:
            return []
        pairs = []
        n = len(self.labels)
        for i in range(n):
            for j in range(i + 1, n):
                r = self.correlation[i, j]
                if abs(r) >= correl_min:
                    pairs.append((abs(r), f"    C({self.labels[i]}, {self.labels[j]}) = {r:+.4f}"))
        if not pairs:
            return []
        return [f"[[Correlations]] (|C| >= {correl_min})"] + [
            p for _, p in sorted(pairs, reverse=True)
        ]

    def _repr_html_(self) -> str:
        return f"<pre>{html.escape(self.report())}</pre>"


def _loss_text(metric: str, loss: float, n_samples: int) -> str:
    """``1.59 (sum over 1252 samples; 0.00127 per sample)`` or ``0.0557 (RMS)``."""
    kind = loss_kind(metric)
    if kind != "sum":
        return f"{loss:.6g} ({kind} over samples)"
    mean = per_sample(metric, loss, n_samples)
    return f"{loss:.6g} (sum over {n_samples} samples; {mean:.6g} per sample)"


def value_text(v: float, err: float | None, *, frozen: bool = False, at_bound: bool = False) -> str:
    """A scalar and its standard error as the report prints them.

    ``value +/- error (relative %)``; ``(frozen)``; ``+/- (none)`` when the fit has no
    errors at all; ``(at bound; no error)`` or ``(no error)`` when this scalar's error
    is not finite (held on a bound, or singular). A value at a bound within
    :data:`AT_BOUND_ATOL` of 0 prints as 0 (the solver's round-off, e.g. 4e-18, is not a
    value), and the relative error is left out when the value is 0: never ``nan%``.
    """
    if at_bound and abs(v) <= AT_BOUND_ATOL:
        v = 0.0
    if frozen:
        return f"{v:.6g} (frozen)"
    if err is None:
        return f"{v:.6g} +/- (none)"
    if not math.isfinite(err):
        return f"{v:.6g} ({'at bound; ' if at_bound else ''}no error)"
    rel = f" ({abs(err / v) * 100:.2f}%)" if v != 0 else ""
    return f"{v:.6g} +/- {err:.3g}{rel}"


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
