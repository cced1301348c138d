"""The posterior a sampler returns: chains, diagnostics, summary, corner plot; its warnings.

:class:`Posterior` is what :func:`brdffit.engine.sample.sample` returns; the warning classes
are the ones it raises about the chain, and :func:`scalars_at_bound` is the at-bound check
it runs on the kept samples.

At-bound check: a parameter scalar with two finite bounds is flagged when its posterior
is piled against one of them. Each sample is mapped to its place ``t`` in [0, 1]
between the bounds, in the coordinate where the prior is uniform (linear for
``identity``/``logit``, ``log(x/low)/log(high/low)`` for ``log``), so the rule does not
depend on the parameter's units. With ``d`` the gap between the bound and the 2.5%
(lower bound) or 97.5% (upper bound) quantile of ``t``, and ``w`` the width of the
95% interval of ``t``, the scalar is flagged when ``d < AT_BOUND_SPAN`` (0.01: within
1% of the span) and ``d <= AT_BOUND_WIDTH * w`` (0.05: the interval reaches the bound
instead of sitting tightly beside it). For scale: ``d/w`` is 0.014 for a half-normal
posterior against the bound, 0.026 for one flat like the prior up to some cut ``a``
(flagged once ``a`` is under 40% of the span, since ``d`` = 0.025 ``a``), and 0.05
for a Gaussian whose 2.5% quantile is 0.2 sigma from the bound; a narrow posterior
well resolved just inside a bound (``d`` small, ``w`` far smaller) is not flagged.
Half-infinite ranges have no span and are not checked. Quantiles at a bound show the
prior's truncation, not the data: report such intervals as limits.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from brdffit.core.parameters import Parameter, ParameterLayout
from brdffit.errors import ChainTooShortError

AT_BOUND_SPAN = 0.01
"""At-bound check: largest gap to the bound, as a share of the span (prior coordinate)."""
AT_BOUND_WIDTH = 0.05
"""At-bound check: largest gap to the bound, as a share of the 95% interval's width."""


class ChainTooShortWarning(UserWarning):
    """The chain is shorter than the asked multiple of its autocorrelation time."""


class PosteriorAtBoundWarning(UserWarning):
    """Posterior mass is piled against a parameter bound (module docstring: at-bound check)."""


@dataclass(frozen=True, eq=False)
class Posterior:
    """Chains and diagnostics from :func:`brdffit.engine.sample.sample`; every field always present.

    Fields: ``model``, ``options``, ``metric``, ``noise``; ``labels`` of the sampled
    scalars (free parameters, then the log noise scales: ``log_sigma``, or
    ``log_sigma_add`` and ``log_sigma_mult`` for ``noise="mixed"``); ``chain``
    (steps, walkers, dim) in natural units; ``log_prob`` (steps, walkers);
    ``acceptance_fraction`` (walkers,);
    ``autocorr_time`` (dim,) integrated autocorrelation times in steps, measured after
    ``burn``; ``burn``; ``n_subsample`` samples the likelihood used; ``stuck_walkers``
    indices of walkers that barely moved; ``at_bound`` (label, bound) pairs of the
    scalars whose posterior is piled against that bound (natural units; module
    docstring); ``wall_time`` (s); ``warnings``.
    """

    model: str
    options: dict
    metric: str
    noise: str
    labels: tuple[str, ...]
    chain: np.ndarray
    log_prob: np.ndarray
    acceptance_fraction: np.ndarray
    autocorr_time: np.ndarray
    burn: int
    n_subsample: int
    stuck_walkers: tuple[int, ...]
    at_bound: tuple[tuple[str, float], ...]
    wall_time: float
    warnings: tuple[str, ...]

    @property
    def n_steps(self) -> int:
        """Steps per walker, burn-in included."""
        return int(self.chain.shape[0])

    def samples(self, *, burn: int | None = None, thin: int = 1) -> np.ndarray:
        """Flat samples (n, dim) after ``burn`` (default: the stored one), every ``thin``-th."""
        b = self.burn if burn is None else burn
        return self.chain[b::thin].reshape(-1, self.chain.shape[-1])

    @property
    def ess(self) -> np.ndarray:
        """Effective sample size per dimension: walkers x kept steps / autocorrelation time."""
        kept = (self.n_steps - self.burn) * self.chain.shape[1]
        return kept / np.maximum(self.autocorr_time, 1.0)

    def split_rhat(self) -> np.ndarray:
        """Split-R-hat per dimension over walkers (Gelman et al. 2013, BDA3 eq. 11.4)."""
        x = self.chain[self.burn :]
        half = x.shape[0] // 2
        chains = np.concatenate([x[:half], x[half : 2 * half]], axis=1)
        n = chains.shape[0]
        means = chains.mean(axis=0)
        w = chains.var(axis=0, ddof=1).mean(axis=0)
        b = n * means.var(axis=0, ddof=1)
        var = (n - 1) / n * w + b / n
        return np.sqrt(var / np.where(w > 0, w, np.inf))

    def require_converged(self, multiple: float = 50.0) -> np.ndarray:
        """The autocorrelation times, or :class:`ChainTooShortError` carrying them."""
        kept = self.n_steps - self.burn
        if not np.all(np.isfinite(self.autocorr_time)) or kept < multiple * np.max(
            self.autocorr_time
        ):
            raise ChainTooShortError(
                f"{kept} kept steps < {multiple} x max autocorrelation time "
                f"{np.max(self.autocorr_time):.1f}; run longer",
                estimate=self.autocorr_time,
            )
        return self.autocorr_time

    def quantiles(self, q: tuple[float, ...] = (0.025, 0.5, 0.975)) -> dict[str, np.ndarray]:
        """Quantiles of each sampled scalar, label -> array of len(q)."""
        s = self.samples()
        return {lab: np.quantile(s[:, i], q) for i, lab in enumerate(self.labels)}

    def summary(self) -> str:
        """Text table: median and 95% interval, autocorrelation, ESS, R-hat per scalar."""
        lines = [
            f"[[Posterior]] {self.model} ({self.metric}, noise {self.noise}), "
            f"{self.chain.shape[1]} walkers x {self.n_steps} steps, burn {self.burn}, "
            f"{self.n_subsample} samples in the likelihood",
            f"    acceptance fraction {np.mean(self.acceptance_fraction):.3f} "
            f"(min {np.min(self.acceptance_fraction):.3f}); wall time {self.wall_time:.1f} s",
            f"    {'scalar':<14} {'median':>12} {'2.5%':>12} {'97.5%':>12} "
            f"{'tau':>8} {'ESS':>8} {'R-hat':>7}",
        ]
        rhat = self.split_rhat()
        for i, (lab, qs) in enumerate(self.quantiles().items()):
            flag = "".join(f"  at bound {b:g}" for name, b in self.at_bound if name == lab)
            lines.append(
                f"    {lab:<14} {qs[1]:>12.6g} {qs[0]:>12.6g} {qs[2]:>12.6g} "
                f"{self.autocorr_time[i]:>8.1f} {self.ess[i]:>8.0f} {rhat[i]:>7.3f}{flag}"
            )
        lines += [f"[[Warning]] {w}" for w in self.warnings]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready summary (not the chain): quantiles, diagnostics, warnings."""
        return {
            "model": self.model,
            "options": dict(self.options),
            "metric": self.metric,
            "noise": self.noise,
            "labels": list(self.labels),
            "n_walkers": int(self.chain.shape[1]),
            "n_steps": self.n_steps,
            "burn": self.burn,
            "n_subsample": self.n_subsample,
            "quantiles_2.5_50_97.5": {k: v.tolist() for k, v in self.quantiles().items()},
            "autocorr_time": self.autocorr_time.tolist(),
            "ess": self.ess.tolist(),
            "split_rhat": self.split_rhat().tolist(),
            "acceptance_fraction": float(np.mean(self.acceptance_fraction)),
            "stuck_walkers": list(self.stuck_walkers),
            "at_bound": [[lab, b] for lab, b in self.at_bound],
            "wall_time": self.wall_time,
            "warnings": list(self.warnings),
        }

    def to_json(self, indent: int | None = 2) -> str:
        """The JSON text of :meth:`to_dict`."""
        return json.dumps(self.to_dict(), indent=indent)

    def corner(self, truths: Mapping[str, object] | None = None, **kwargs: object):
        """Corner plot (the ``corner`` package) of the kept samples; returns the figure.

        ``truths`` maps parameter names to values (RGB arrays expand to channels).
        """
        import corner  # deferred: heavy (imports matplotlib), figures only

        t = None
        if truths is not None:
            flat = {}
            for name, v in truths.items():
                v = np.atleast_1d(np.asarray(v, float))
                keys = [name] if v.size == 1 else [f"{name}[{c}]" for c in "rgb"]
                flat.update(dict(zip(keys, v, strict=True)))
            t = [flat.get(lab) for lab in self.labels]
        kwargs.setdefault("quantiles", [0.025, 0.5, 0.975])
        kwargs.setdefault("show_titles", True)
        kwargs.setdefault("title_fmt", ".4g")
        return corner.corner(self.samples(), labels=list(self.labels), truths=t, **kwargs)


def _bound_coordinate(p: Parameter, x: np.ndarray) -> np.ndarray | None:
    """Natural ``x`` -> place in [0, 1] between ``p``'s bounds, in the prior's uniform coordinate.

    Linear for ``identity``/``logit``, logarithmic for ``log``; None for a half-infinite range.
    """
    lo, hi = p.bounds
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return None
    if p.transform == "log":
        return np.log(np.maximum(x, lo) / lo) / math.log(hi / lo)
    return (x - lo) / (hi - lo)


def _piled(gap: float, width: float) -> bool:
    """At-bound rule (module docstring): near on the span's scale and on the posterior's."""
    return bool(gap < AT_BOUND_SPAN and gap <= AT_BOUND_WIDTH * width)


def scalars_at_bound(layout: ParameterLayout, kept: np.ndarray) -> tuple[tuple[str, float], ...]:
    """(label, bound) of every free scalar piled against a bound (module docstring).

    ``kept`` is the post-burn chain (steps, walkers, dim) in natural units.
    """
    out = []
    labels, i = layout.labels(), 0
    for p in layout.free:
        for j in range(p.size):
            t = _bound_coordinate(p, kept[..., i + j].ravel())
            if t is not None:
                q_lo, q_hi = (float(q) for q in np.quantile(t, [0.025, 0.975]))
                if _piled(q_lo, q_hi - q_lo):
                    out.append((labels[i + j], float(p.bounds[0])))
                if _piled(1.0 - q_hi, q_hi - q_lo):
                    out.append((labels[i + j], float(p.bounds[1])))
        i += p.size
    return tuple(out)
