"""The posterior a sampler returns: chains, diagnostics, summary, display; its warnings.

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

import html
import json
import math
from dataclasses import dataclass, field

import numpy as np

from brdffit.core.parameters import Parameter, ParameterLayout
from brdffit.errors import ChainTooShortError
from brdffit.util.text_table import render

AT_BOUND_SPAN = 0.01
"""At-bound check: largest gap to the bound, as a share of the span (prior coordinate)."""
AT_BOUND_WIDTH = 0.05
"""At-bound check: largest gap to the bound, as a share of the 95% interval's width."""

SUMMARY_HEAD = ("scalar", "median", "2.5%", "97.5%", "tau", "ESS", "R-hat")
"""The columns of :meth:`Posterior.summary` (the HTML form adds ``flags``)."""
_WIDTHS = (12, 12, 12, 8, 8, 7)  # of the summary's right-aligned columns after the label


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
    docstring); ``wall_time`` (s); ``warnings``; ``fixed`` the values of the parameters
    held fixed while sampling (name -> array, natural units), so that every sample names
    a whole parameter set (:meth:`parameter_sets`).
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
    fixed: dict[str, np.ndarray] = field(default_factory=dict)

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

    def parameter_sets(self, samples: np.ndarray) -> dict[str, np.ndarray]:
        """Rows of ``samples`` (n, dim), as from :meth:`samples`, as whole parameter sets:
        name -> array (n, *shape) in natural units, the fixed parameters repeated.

        The model's parameters only: the noise scales (``log_sigma*``) are left out.
        """
        samples = np.atleast_2d(samples)
        n = samples.shape[0]
        columns: dict[str, list[int]] = {}
        for i, lab in enumerate(self.labels):
            if not lab.startswith("log_sigma"):
                columns.setdefault(lab.split("[", 1)[0], []).append(i)
        out = {
            name: samples[:, ix[0]] if len(ix) == 1 and "[" not in self.labels[ix[0]]
            else samples[:, ix]
            for name, ix in columns.items()
        }  # fmt: skip
        for name, v in self.fixed.items():
            v = np.asarray(v, float)
            out[name] = np.broadcast_to(v, (n, *v.shape)).copy()
        return out

    def quantiles(self, q: tuple[float, ...] = (0.025, 0.5, 0.975)) -> dict[str, np.ndarray]:
        """Quantiles of each sampled scalar, label -> array of len(q)."""
        s = self.samples()
        return {lab: np.quantile(s[:, i], q) for i, lab in enumerate(self.labels)}

    def _headline(self) -> tuple[str, str]:
        """The two lines above the summary's table: the run, then acceptance and wall time."""
        acc = self.acceptance_fraction
        return (
            f"{self.model} ({self.metric}, noise {self.noise}), "
            f"{self.chain.shape[1]} walkers x {self.n_steps} steps, burn {self.burn}, "
            f"{self.n_subsample} samples in the likelihood",
            f"acceptance fraction {np.mean(acc):.3f} (min {np.min(acc):.3f}); "
            f"wall time {self.wall_time:.1f} s",
        )

    def summary_rows(self) -> list[tuple[tuple[str, ...], tuple[str, ...]]]:
        """The rows of :meth:`summary` and of the HTML table, one per sampled scalar:
        the cells under :data:`SUMMARY_HEAD` (label, median, 2.5%, 97.5%, tau, ESS, R-hat,
        as text) and the flags (``at bound 0``, one per bound the posterior is piled on)."""
        rhat, ess = self.split_rhat(), self.ess
        out = []
        for i, (lab, qs) in enumerate(self.quantiles().items()):
            cells = (
                lab,
                *(f"{q:.6g}" for q in (qs[1], qs[0], qs[2])),
                f"{self.autocorr_time[i]:.1f}",
                f"{ess[i]:.0f}",
                f"{rhat[i]:.3f}",
            )
            flags = tuple(f"at bound {b:g}" for name, b in self.at_bound if name == lab)
            out.append((cells, flags))
        return out

    def summary(self) -> str:
        """Text table: median and 95% interval, autocorrelation, ESS, R-hat per scalar."""

        def line(cells: tuple[str, ...]) -> str:
            nums = " ".join(f"{c:>{w}}" for c, w in zip(cells[1:], _WIDTHS, strict=True))
            return f"    {cells[0]:<14} {nums}"

        run, acceptance = self._headline()
        lines = [f"[[Posterior]] {run}", f"    {acceptance}", line(SUMMARY_HEAD)]
        for cells, flags in self.summary_rows():
            lines.append(line(cells) + "".join(f"  {f}" for f in flags))
        lines += [f"[[Warning]] {w}" for w in self.warnings]
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        """:meth:`summary` as HTML for Jupyter: the run, one table row per sampled scalar
        (with its flags), the warnings; from the same rows as :meth:`summary`."""
        run, acceptance = self._headline()
        body = [[*cells, ", ".join(flags)] for cells, flags in self.summary_rows()]
        out = [
            '<div class="brdffit-posterior">',
            f"<p><b>Posterior: {html.escape(run)}</b><br>{html.escape(acceptance)}</p>",
            render((*SUMMARY_HEAD, "flags"), body, "html").rstrip("\n"),
        ]
        out += [f'<p style="color:#a33">Warning: {html.escape(w)}</p>' for w in self.warnings]
        return "\n".join([*out, "</div>"])

    def __str__(self) -> str:
        return self.summary()

    def __repr__(self) -> str:
        """One line: model, metric, noise, scalars, walkers x steps, warnings."""
        return (
            f"<Posterior {self.model} {self.metric}, noise {self.noise}, "
            f"{len(self.labels)} scalars, {self.chain.shape[1]} walkers x {self.n_steps} steps, "
            f"{len(self.warnings)} warning{'' if len(self.warnings) == 1 else 's'}>"
        )

    def _repr_pretty_(self, p: object, cycle: bool) -> None:
        """IPython's text form: the summary."""
        p.text(repr(self) if cycle else self.summary())

    def to_dict(self) -> dict:
        """JSON-ready summary (not the chain): quantiles, diagnostics, warnings, the fixed
        parameters' values."""
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
            "fixed": {k: np.asarray(v).tolist() for k, v in self.fixed.items()},
        }

    def to_json(self, indent: int | None = 2) -> str:
        """The JSON text of :meth:`to_dict`."""
        return json.dumps(self.to_dict(), indent=indent)


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
