"""Posterior sampling with emcee's affine-invariant ensemble sampler.

Likelihood: the metric's residual vector ``r`` (:func:`brdffit.engine.misfit.residuals`) on
a seeded subsample of the valid samples, Gaussian with free noise scales:

* ``noise="mixed"`` (the default): ``r_i ~ N(0, (sigma_add a_i)^2 + (sigma_mult m_i)^2)``
  with ``a_i = |d r_i / d f_i|`` and ``m_i = |d r_i / d ln f_i|``: noise on the data of
  variance ``sigma_add^2 + (sigma_mult f)^2`` (an absolute floor in 1/sr plus a
  relative part), propagated through the metric to first order. It contains the two
  below as its edges, so it is right whichever of them the data have, and both scales
  are sampled;
* ``noise="multiplicative"``: ``r_i ~ N(0, (sigma m_i)^2)``, right for log-normal noise
  on the data (DESIGN.md: heteroscedastic residuals break a constant scale even when
  the model is right);
* ``noise="additive"``: ``r_i ~ N(0, (sigma a_i)^2)``, for Gaussian noise of constant
  size in 1/sr;
* ``noise="constant"``: ``r_i ~ N(0, sigma^2)``, one variance for every residual. No
  metric in brdffit has such residuals on data with either kind of noise (the weights
  and the log make the scale vary from cell to cell), so its intervals are wrong in
  both directions; it is kept for comparison. ``benchmarks/results/calibration.md``
  measures the coverage of each.

The factors ``a_i``, ``m_i`` are computed once, at the start model (the LM optimum),
each floored at 1e-3 of its median.
Each scale is sampled as its logarithm on [-30, 10] (``log_sigma``, or
``log_sigma_add`` and ``log_sigma_mult`` for ``mixed``). A single scale has the
log-uniform prior (flat in ``log_sigma``): the data always pin it. The two scales of
``mixed`` are uniform in ``sigma`` instead, because either may be zero: a log-uniform
prior would leave a flat, improper-looking plateau down to ``exp(-30)`` under a scale
the data cannot see, which the walkers would wander over. A uniform prior on a scale
that may vanish is the usual choice for variance components (Gelman 2006, "Prior
distributions for variance parameters in hierarchical models").

Priors come from the parameter bounds: log-uniform for ``log``-transformed
parameters, uniform otherwise; ``priors`` overrides any of them with a JAX function
of the natural value returning a log density. The walkers move in the unconstrained
space of the transforms (the log-Jacobian is added), so bounds are never walls;
chains are reported in natural units. The log-probability is jitted and vectorised
over walkers; data-only geometry is computed once.

At-bound check: a parameter scalar whose posterior is piled against one of its two
finite bounds is flagged (:mod:`brdffit.engine.posterior` gives the rule).

What the uncertainty means: the spread of parameters compatible with the subsample
under this noise model. With model error (real materials) neighbouring residuals are
correlated and the posterior is too narrow; read it as a lower bound.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Mapping

import emcee
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import nnls

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.measurements import Measurements
from brdffit.core.parameters import Parameter, ParameterLayout
from brdffit.core.result import FitResult
from brdffit.engine import metrics as metrics_mod
from brdffit.engine import misfit
from brdffit.engine.objective import Objective, freeze_map, start_params
from brdffit.engine.posterior import (
    ChainTooShortWarning,
    Posterior,
    PosteriorAtBoundWarning,
    scalars_at_bound,
)
from brdffit.engine.settings import Freeze
from brdffit.errors import ParameterError

NOISE_MODELS = ("mixed", "multiplicative", "additive", "constant")
LOG_SIGMA_BOUNDS = (-30.0, 10.0)


def _log_prior_natural(p: Parameter, x: jax.Array) -> jax.Array:
    lo, hi = p.bounds
    if p.transform == "log":
        return -jnp.sum(jnp.log(x))
    if math.isfinite(lo) and math.isfinite(hi):
        return jnp.zeros((), x.dtype) - p.size * math.log(hi - lo)
    return jnp.zeros((), x.dtype)


class _Target(eqx.Module):
    """The jitted log-posterior in unconstrained coordinates (free scalars + log scales).

    ``scales`` (k, residuals) holds the per-residual factor of each of the k noise
    scales; the residual variance is ``sum_k (exp(log_sigma_k) scales_k)^2``.
    """

    objective: Objective
    priors: tuple = eqx.field(static=True)
    uniform_sigma: bool = eqx.field(static=True)

    def __call__(self, theta, prep, scales):
        k = scales.shape[0]
        u, log_sigma = theta[:-k], theta[-k:]
        inside = jnp.all((log_sigma > LOG_SIGMA_BOUNDS[0]) & (log_sigma < LOG_SIGMA_BOUNDS[1]))
        lp = jnp.where(inside, 0.0, -jnp.inf)
        if self.uniform_sigma:
            lp = lp + jnp.sum(log_sigma)  # p(sigma) uniform: p(log sigma) = sigma
        i = 0
        for p, prior in zip(self.objective.free, self.priors, strict=True):
            up = u[i : i + p.size]
            x = p.to_natural(up)
            logdet = jnp.sum(jnp.log(jnp.abs(jax.vmap(jax.grad(p.to_natural))(up))))
            lp = lp + logdet + (prior(x.reshape(p.shape)) if prior else _log_prior_natural(p, x))
            i += p.size
        obj = self.objective
        params = obj.layout.params(u, "unconstrained")
        r = misfit.residuals(obj.model.evaluate(params, prep.g), prep)
        var = jnp.sum((jnp.exp(log_sigma)[:, None] * scales) ** 2, axis=0)
        ll = -0.5 * jnp.sum(jnp.log(var)) - 0.5 * jnp.sum(r * r / var)
        out = lp + ll
        return jnp.where(jnp.isfinite(out), out, -jnp.inf)


@eqx.filter_jit
def _batched(target, thetas, prep, scales):
    return jax.vmap(lambda t: target(t, prep, scales))(thetas)


@eqx.filter_jit
def _factor(prep, f_model, relative: bool):
    """``|d r_i / d ln f|`` (``relative``) or ``|d r_i / d f|`` at the model, floored.

    Floor: 1e-3 x the median. Taken at the start model (the LM optimum), not at the
    noisy data: weights that depend on the data's own noise bias the estimate (by
    about -sigma^2).
    """

    def r_of(f):
        return misfit.residuals(f, prep)

    tangent = f_model if relative else jnp.ones_like(f_model)
    s = jnp.abs(jax.jvp(r_of, (f_model,), (tangent,))[1])
    return jnp.maximum(s, 1e-3 * jnp.median(s))


def _noise_scales(prep, f_model, noise: str) -> tuple[jax.Array, tuple[str, ...]]:
    """Per-residual factors (k, residuals) of the ``noise`` model's scales, and their labels."""
    if noise == "constant":
        return jnp.ones((1, 3 * prep.rows)), ("log_sigma",)
    add = _factor(prep, f_model, False) if noise in ("additive", "mixed") else None
    mult = _factor(prep, f_model, True) if noise in ("multiplicative", "mixed") else None
    if noise == "mixed":
        return jnp.stack([add, mult]), ("log_sigma_add", "log_sigma_mult")
    return (add if add is not None else mult)[None, :], ("log_sigma",)


def _start_sigmas(r0: np.ndarray, scales: np.ndarray, passes: int = 3) -> np.ndarray:
    """Start values of the noise scales from the start model's residuals ``r0``.

    One scale: the root mean square of ``r0 / scale``. Several: a moment estimate,
    ``r0_i^2 ~ sum_k v_k scales_ki^2`` solved for ``v >= 0`` by non-negative least
    squares, weighted by ``1 / var_i^2`` (``Var r_i^2 = 2 var_i^2`` for a Gaussian
    residual) with ``var_i`` from the previous pass, starting from an equal split.
    Each scale is kept at least 1e-2 of the value it would have if it explained the
    residuals alone, so that every walker starts at a finite log scale; the sampler
    then finds the posterior (this is only its start).
    """
    alone = np.sqrt(np.mean((r0[None, :] / scales) ** 2, axis=1))
    if scales.shape[0] == 1:
        return alone

    a = scales.T**2
    v = alone**2 / scales.shape[0]
    for _ in range(passes):
        w = 1.0 / (a @ v)
        v, _ = nnls(a * w[:, None], r0**2 * w)
        v = np.maximum(v, (1e-2 * alone) ** 2)
    return np.sqrt(v)


MIN_SPREAD: float = 1e-4
"""Least spread of the initial walkers per unconstrained dimension, times ``max(1, |u|)``.

On noise-free data the LM errors are ~0 and a tenth of them gave walkers that emcee
refused as linearly dependent ("large condition number", a ratio above 1e8 between the
ball's extent and its offset); 1e-4 keeps that ratio near 1e5."""


def check_arguments(
    model: AbstractModel,
    *,
    freeze: Freeze = None,
    noise: str = "mixed",
    n_walkers: int | None = None,
    n_steps: int = 2000,
    burn: int | None = None,
    n_subsample: int = 10_000,
) -> int:
    """Check :func:`sample`'s settings before any work (the command line calls it before
    its LM fit); returns the number of walkers.

    Raises :class:`ParameterError` naming the argument: an unknown ``noise``, fewer than 2
    steps, ``burn`` outside ``[0, n_steps)``, ``n_subsample < 1``, or fewer walkers than
    twice the sampled dimension (emcee's stretch move needs that many).
    """
    if noise not in NOISE_MODELS:
        raise ParameterError(f"noise={noise!r}: use one of {NOISE_MODELS}")

    def is_int(x: object) -> bool:
        return isinstance(x, int | np.integer) and not isinstance(x, bool)

    if not is_int(n_steps) or n_steps < 2:
        raise ParameterError(f"n_steps={n_steps!r}: use an integer >= 2 (default 2000)")
    if burn is not None and (not is_int(burn) or not 0 <= burn < n_steps):
        raise ParameterError(f"burn={burn!r}: use an integer in [0, n_steps={n_steps})")
    if not is_int(n_subsample) or n_subsample < 1:
        raise ParameterError(f"n_subsample={n_subsample!r}: use an integer >= 1")
    n_free = Objective.build(model, freeze_map(model, freeze, start_params(model, None))).size
    k = 2 if noise == "mixed" else 1
    ndim = n_free + k
    if n_walkers is None:
        return max(32, 4 * ndim)
    if not is_int(n_walkers) or n_walkers < 2 * ndim:
        raise ParameterError(
            f"n_walkers={n_walkers!r}: emcee's stretch move needs at least twice the "
            f"dimension, {2 * ndim} here ({n_free} free parameters and {k} noise "
            f"scale{'s' if k > 1 else ''}); default max(32, 4 x dimension)"
        )
    return int(n_walkers)


def _start_ball(layout: ParameterLayout, init: object, u0: np.ndarray, k: int) -> np.ndarray:
    """Per-dimension spread of the initial walkers in unconstrained units.

    A tenth of the LM standard errors mapped through the transforms when ``init`` is a
    :class:`FitResult` with errors, else 1e-4; 1e-2 for the ``k`` log noise scales; at
    least :data:`MIN_SPREAD` ``x max(1, |u0|)`` (a ball emcee accepts on noise-free data).
    """
    spread = np.full(u0.size, 1e-4)
    spread[-k:] = 1e-2
    if isinstance(init, FitResult) and init.stderr is not None:
        i = 0
        for p in layout.free:
            x = jnp.asarray(init.params[p.name], jnp.float64).ravel()
            dudx = jax.vmap(jax.grad(lambda v, p=p: p.to_unconstrained(v)))(x)
            sd = np.asarray(init.stderr[p.name], float).ravel() * np.abs(np.asarray(dudx))
            spread[i : i + p.size] = np.where(np.isfinite(sd) & (sd > 0), 0.1 * sd, 1e-4)
            i += p.size
    return np.maximum(spread, MIN_SPREAD * np.maximum(1.0, np.abs(u0)))


def sample(
    model: AbstractModel,
    data: Measurements,
    *,
    metric: str | None = None,
    init: FitResult | Mapping[str, object] | None = None,
    freeze: Freeze = None,
    noise: str = "mixed",
    priors: Mapping[str, Callable[[jax.Array], jax.Array]] | None = None,
    n_walkers: int | None = None,
    n_steps: int = 2000,
    burn: int | None = None,
    n_subsample: int = 10_000,
    cut_deg: float | None = 80.0,
    seed: int = 0,
    progress: bool = True,
    min_autocorr_multiple: float = 50.0,
) -> Posterior:
    """Sample the posterior of ``model``'s parameters given ``data`` with emcee.

    Arguments:
    - ``model``, ``data``, ``freeze``, ``cut_deg``: as in :func:`brdffit.fit`.
    - ``metric``: residuals of the likelihood; default the ``init`` fit's, else ``low_e2``.
    - ``init``: the LM result (or a natural parameter dict) the walkers start around;
      walkers start in a Gaussian ball a tenth of its standard errors wide.
    - ``noise``: ``"mixed"`` (default), ``"multiplicative"``, ``"additive"`` or
      ``"constant"`` (module docstring).
    - ``priors``: name -> log density of the natural value (JAX function).
    - ``n_walkers`` (default ``max(32, 4 dim)``), ``n_steps``, ``burn`` (default a third).
    - ``n_subsample``: samples drawn (seeded) from the valid ones for the likelihood.
    - ``progress``: tqdm progress bar.
    - ``min_autocorr_multiple``: warn (:class:`ChainTooShortWarning`) below this many
      autocorrelation times.
    """
    t0 = time.perf_counter()
    n_walkers = check_arguments(
        model, freeze=freeze, noise=noise, n_walkers=n_walkers, n_steps=n_steps, burn=burn,
        n_subsample=n_subsample,
    )  # fmt: skip
    if isinstance(init, FitResult):
        metric = metric or init.metric
        start = start_params(model, init.params)
    else:
        start = start_params(model, init)
    m = metrics_mod.get_metric(metric or "low_e2")
    obj = Objective.build(model, freeze_map(model, freeze, start))
    layout, frozen = obj.layout, obj.frozen
    unknown = sorted(set(priors or {}) - {p.name for p in layout.free})
    if unknown:
        raise ParameterError(f"priors given for {unknown}, which are not free parameters")
    rng = np.random.default_rng(seed)
    keep = np.flatnonzero(metrics_mod.keep_mask(data, cut_deg))
    if keep.size > n_subsample:
        keep = np.sort(rng.choice(keep, size=n_subsample, replace=False))
    prep = metrics_mod.prepare(data, m, keep=keep)

    full = {**start, **frozen}
    f_start = model.evaluate(full, prep.g)
    scales, sigma_labels = _noise_scales(prep, f_start, noise)
    r0 = np.asarray(misfit.residuals(f_start, prep))
    sigma0 = _start_sigmas(r0, np.asarray(scales))
    u0 = np.concatenate(
        [np.asarray(layout.unconstrained(start)), np.log(np.maximum(sigma0, 1e-12))]
    )
    ndim = u0.size
    spread = _start_ball(layout, init, u0, len(sigma_labels))
    p0 = u0 + spread * rng.standard_normal((n_walkers, ndim))

    target = _Target(obj, tuple((priors or {}).get(p.name) for p in layout.free), noise == "mixed")

    def log_prob(thetas: np.ndarray) -> np.ndarray:
        return np.asarray(_batched(target, jnp.asarray(thetas), prep, scales))

    sampler = emcee.EnsembleSampler(n_walkers, ndim, log_prob, vectorize=True)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
    sampler.run_mcmc(p0, n_steps, progress=progress)
    chain_u = sampler.get_chain()
    chain = _to_natural(layout, chain_u)
    burn = n_steps // 3 if burn is None else burn
    tau = emcee.autocorr.integrated_time(chain_u[burn:], tol=0)
    acc = np.asarray(sampler.acceptance_fraction)
    stuck = tuple(int(i) for i in np.flatnonzero(acc < 0.2 * np.median(acc)))
    at_bound = scalars_at_bound(layout, chain[burn:])
    notes: list[tuple[str, type[UserWarning]]] = []
    if n_steps - burn < min_autocorr_multiple * np.max(tau):
        text = (
            f"chain of {n_steps - burn} kept steps is shorter than {min_autocorr_multiple:g} "
            f"autocorrelation times (max tau {np.max(tau):.1f}); estimates are unreliable"
        )
        notes.append((text, ChainTooShortWarning))
    if stuck:
        text = f"{len(stuck)} stuck walkers (acceptance < 0.2 x median): {list(stuck)}"
        notes.append((text, UserWarning))
    if at_bound:
        where = ", ".join(f"{lab} at {b:g}" for lab, b in at_bound)
        text = (
            f"posterior piled against a bound: {where}; the interval there is set by the "
            "bound (prior), not the data"
        )
        notes.append((text, PosteriorAtBoundWarning))
    for text, category in notes:
        warnings.warn(text, category, stacklevel=2)
    labels = tuple(layout.labels()) + sigma_labels
    return Posterior(
        model=model.name,
        options=model.options(),
        metric=m.name,
        noise=noise,
        labels=labels,
        chain=chain,
        log_prob=np.asarray(sampler.get_log_prob()),
        acceptance_fraction=acc,
        autocorr_time=np.asarray(tau),
        burn=burn,
        n_subsample=prep.n,
        stuck_walkers=stuck,
        at_bound=at_bound,
        wall_time=time.perf_counter() - t0,
        warnings=tuple(text for text, _ in notes),
        fixed={k: np.asarray(v, float) for k, v in frozen.items()},
    )


def _to_natural(layout: ParameterLayout, chain_u: np.ndarray) -> np.ndarray:
    """Map a chain (steps, walkers, free + 1) from unconstrained to natural units."""
    out = np.array(chain_u, copy=True)
    i = 0
    for p in layout.free:
        out[..., i : i + p.size] = np.asarray(
            p.to_natural(jnp.asarray(chain_u[..., i : i + p.size]))
        )
        i += p.size
    return out
