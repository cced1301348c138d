"""Levenberg-Marquardt fit of a model to measurements (optimistix), with uncertainties.

The fit runs in the unconstrained space of each parameter's transform
(:mod:`brdffit.parameters`) on the residual vector of the chosen metric
(:mod:`brdffit.metrics`). Each start solves the parameters the model is affine in
(``Parameter.linear``: albedos, F0) by weighted linear least squares with the
other parameters fixed; the first start is the defaults (or ``init``), the others are
seeded random draws of the nonlinear parameters; the lowest loss wins.

Uncertainties come from the Jacobian ``J`` of the residuals with respect to the free
natural parameters at the optimum (the delta method applied to the unconstrained
covariance gives the same matrix). ``errors="sandwich"`` (default) is the
heteroscedasticity-consistent ``(J^T J)^-1 J^T diag(r^2) J (J^T J)^-1``;
``errors="classic"`` is ``s^2 (J^T J)^-1`` with ``s^2 = sum r^2 / (n - k)``. Both
assume independent residuals: neighbouring cells of measured data share model error,
so read them as a lower bound (see DESIGN.md). The sandwich form stays right when the
residual scale varies over the samples (e.g. multiplicative noise on a linear metric),
where the classic form was 9-12x too narrow in DESIGN's experiment.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from brdffit import metrics as metrics_mod
from brdffit.abstract_model import AbstractModel, linear_split
from brdffit.errors import FitError, ParameterError
from brdffit.measurements import Measurements
from brdffit.parameters import Parameter, ParameterLayout, Params
from brdffit.result import FitResult, Status

Freeze = Mapping[str, object] | Sequence[str] | None


def _natural(free: tuple[Parameter, ...], u: jax.Array, frozen: Params) -> Params:
    out, i = dict(frozen), 0
    for p in free:
        out[p.name] = p.to_natural(u[i : i + p.size].reshape(p.shape))
        i += p.size
    return out


def _merge(free: tuple[Parameter, ...], x: jax.Array, frozen: Params) -> Params:
    out, i = dict(frozen), 0
    for p in free:
        out[p.name] = x[i : i + p.size].reshape(p.shape)
        i += p.size
    return out


@eqx.filter_jit
def _solve(model, free, metric, solver, u0, prep, frozen, active, max_steps):
    """LM in unconstrained space; scalars with ``active == False`` stay at ``u0``."""

    def fn(u, args):
        prep, frozen = args
        u = jnp.where(active, u, u0)
        return metrics_mod.residuals(
            metric, model.evaluate(_natural(free, u, frozen), prep.g), prep
        )

    sol = optx.least_squares(fn, solver, u0, args=(prep, frozen), max_steps=max_steps, throw=False)
    u = jnp.where(active, sol.value, u0)
    f = model.evaluate(_natural(free, u, frozen), prep.g)
    return u, sol.result, sol.stats["num_steps"], metrics_mod.loss(metric, f, prep)


@eqx.filter_jit
def _all_losses(model, params, preps):
    """Every metric's loss at ``params``; the model is evaluated once (shared geometry)."""
    f = model.evaluate(params, next(iter(preps.values())).g)
    return {k: metrics_mod.loss(metrics_mod.METRICS[k], f, p) for k, p in preps.items()}


@eqx.filter_jit
def _jacobian(model, free, metric, x, prep, frozen):
    def fn(x):
        return metrics_mod.residuals(metric, model.evaluate(_merge(free, x, frozen), prep.g), prep)

    return fn(x), jax.jacfwd(fn)(x)


@eqx.filter_jit
def _linear_solve(model, metric, params, names, prep):
    """Weighted least squares for the affine parameters ``names``; returns their flat vector.

    Compares ``f cos`` in f-space with the metric's weights; for log1p metrics each
    sample is further weighted by ``1 / (1 + f_data cos)``, the first-order slope of
    ``ln(1 + x)``.
    """
    f0, basis = linear_split(model, params, prep.g, names)
    w = jnp.sqrt(prep.weight) * prep.cos_i
    w = w[:, None] * jnp.ones((1, 3), w.dtype)
    if metric.log1p:
        w = w / (1.0 + jnp.maximum(prep.values * prep.cos_i[:, None], 0.0))
    a = (basis * w[:, :, None]).reshape(-1, basis.shape[-1])
    b = ((prep.values - f0) * w).ravel()
    return jnp.linalg.lstsq(a, b)[0]


def _freeze_map(model: AbstractModel, freeze: Freeze, start: Params) -> dict[str, object]:
    if freeze is None:
        return {}
    if isinstance(freeze, Mapping):
        return dict(freeze)
    if isinstance(freeze, str):
        freeze = [freeze]
    for name in freeze:
        model.parameter(name)
    return {name: np.asarray(start[name]) for name in freeze}


def _start_params(model: AbstractModel, init: Mapping[str, object] | None) -> Params:
    params = model.defaults()
    for name, value in (init or {}).items():
        params[name] = model.parameter(name).check_value(value)
    return params


def _with_linear_start(
    model: AbstractModel, metric, layout: ParameterLayout, params: Params, prep
) -> Params:
    lin = tuple(p for p in layout.free if p.linear)
    if not lin:
        return params
    x = np.asarray(_linear_solve(model, metric, params, tuple(p.name for p in lin), prep))
    out, i = dict(params), 0
    if not np.all(np.isfinite(x)):
        return params
    for p in lin:
        lo, hi = p.bounds
        span = (hi - lo) if math.isfinite(hi - lo) else max(abs(lo), 1.0)
        v = np.clip(x[i : i + p.size], lo + 1e-3 * span, hi - 1e-3 * span)
        out[p.name] = jnp.asarray(v.reshape(p.shape))
        i += p.size
    return out


def _random_start(layout: ParameterLayout, base: Params, rng: np.random.Generator) -> Params:
    out = dict(base)
    for p in layout.free:
        if p.linear:
            continue
        u = np.asarray(p.to_unconstrained(jnp.asarray(base[p.name])))
        out[p.name] = p.to_natural(jnp.asarray(u + rng.normal(0.0, 1.0, p.shape)))
    return out


def _covariance(
    j: np.ndarray, r: np.ndarray, method: str, n_free: int
) -> tuple[np.ndarray | None, float, str | None]:
    """Covariance of the free scalars from ``J`` and ``r``; (cov, condition, reason)."""
    jtj = j.T @ j
    d = np.sqrt(np.diag(jtj))
    if n_free == 0:
        return None, float("nan"), "no free parameter"
    if np.any(d == 0) or not np.all(np.isfinite(jtj)):
        return None, float("inf"), "a parameter does not change the residuals (J^T J singular)"
    scaled = jtj / np.outer(d, d)
    cond = float(np.linalg.cond(scaled))
    if not np.isfinite(cond) or cond > 1e15:
        return None, cond, f"J^T J is singular to working precision (condition {cond:.3g})"
    bread = np.linalg.inv(scaled) / np.outer(d, d)
    if method == "classic":
        dof = max(j.shape[0] - n_free, 1)
        cov = bread * float(r @ r) / dof
    else:
        meat = (j * (r**2)[:, None]).T @ j
        cov = bread @ meat @ bread
    return 0.5 * (cov + cov.T), cond, None


def fit(
    model: AbstractModel,
    data: Measurements,
    metric: str = "low_e2",
    *,
    init: Mapping[str, object] | None = None,
    freeze: Freeze = None,
    cut_deg: float | None = 80.0,
    n_restarts: int = 2,
    seed: int = 0,
    max_steps: int = 256,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    errors: str = "sandwich",
    throw: bool = True,
) -> FitResult:
    """Fit ``model`` to ``data`` by Levenberg-Marquardt on the residuals of ``metric``.

    Arguments:
    - ``model``: a model from :func:`brdffit.models.get`.
    - ``data``: measurements; only valid samples inside the angle cut are used.
    - ``metric``: ``"ngan"``, ``"low_e1"``, ``"low_e2"`` or ``"log1p_l1"``.
    - ``init``: start values (natural units) for some parameters; others use defaults.
    - ``freeze``: names (frozen at their start value) or name -> value; frozen
      parameters leave the fit and get zero standard error.
    - ``cut_deg``: zenith-angle cut for both directions, degrees (``None``: none).
    - ``n_restarts``: seeded random starts in addition to the first one.
    - ``max_steps``, ``rtol``, ``atol``: LM limits and tolerances (optimistix).
    - ``errors``: ``"sandwich"`` or ``"classic"`` (module docstring).
    - ``throw``: raise :class:`FitError` (carrying the result) if the fit did not converge.

    Returns a :class:`FitResult`; a non-finite or unfinished fit is never marked converged.
    """
    t0 = time.perf_counter()
    m = metrics_mod.get_metric(metric)
    if errors not in ("sandwich", "classic"):
        raise ParameterError(f"errors={errors!r}: use 'sandwich' or 'classic'")
    start = _start_params(model, init)
    layout = ParameterLayout.build(model.parameters, _freeze_map(model, freeze, start))
    frozen = {k: jnp.asarray(v, jnp.float64) for k, v in layout.frozen.items()}
    preps = metrics_mod.prepare_all(data, cut_deg=cut_deg)
    prep = preps[m.name]
    # Normal equations (Cholesky of J^T J + lambda I, p x p) instead of the default QR
    # of the tall (3N + p) x p damped system: a quarter of the linear algebra per step on
    # MERL-size data (1.07 s -> 0.27 s at 2.7M residuals). The damping keeps the system
    # positive definite; it squares the condition number, which float64 absorbs here.
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))
    rng = np.random.default_rng(seed)

    best = None
    first = {**start, **frozen}
    starts = [first] + [_random_start(layout, first, rng) for _ in range(n_restarts)]
    everywhere = jnp.ones(layout.size, bool)
    for s in starts:
        s = _with_linear_start(model, m, layout, s, prep)
        u0 = layout.unconstrained(s)
        out = _solve(model, layout.free, m, solver, u0, prep, frozen, everywhere, max_steps)
        loss = float(out[3])
        cand = (loss if math.isfinite(loss) else math.inf, out[0], out[1], int(out[2]), s)
        if best is None or cand[0] < best[0]:
            best = cand
    loss, u, res, steps, s0 = best
    pinned = np.zeros(layout.size, bool)
    if res == optx.RESULTS.nonlinear_max_steps_reached:
        # Active set: scalars that ran into a bound (sigmoid saturated) are pinned
        # there and LM finishes the others; the best fit then lies on the bound.
        pinned = _saturated(layout, np.asarray(u))
        if pinned.any():
            u_pin = jnp.where(pinned, jnp.sign(u) * 40.0, u)
            out = _solve(
                model, layout.free, m, solver, u_pin, prep, frozen, jnp.asarray(~pinned), max_steps
            )
            if math.isfinite(float(out[3])) and float(out[3]) <= loss * (1 + 1e-9):
                loss, u, res, steps = float(out[3]), out[0], out[1], steps + int(out[2])

    params = {k: np.asarray(v) for k, v in _natural(layout.free, u, frozen).items()}
    finite = math.isfinite(loss) and all(np.all(np.isfinite(v)) for v in params.values())
    if not finite:
        status = Status.NONFINITE
    elif res == optx.RESULTS.successful:
        status = Status.CONVERGED
    elif res == optx.RESULTS.nonlinear_max_steps_reached:
        status = Status.MAX_STEPS
    else:
        status = Status.SOLVER_FAILED

    result = _assemble(
        model,
        m,
        layout,
        params,
        s0,
        preps,
        status,
        steps,
        len(starts),
        errors,
        cut_deg,
        data.source,
        t0,
        pinned,
    )
    if throw and not result.converged:
        raise FitError(f"fit of {model.name} to {data.source}: {status.value}", result)
    return result


def _saturated(layout: ParameterLayout, u: np.ndarray) -> np.ndarray:
    """Free scalars whose bounded transform is saturated (|u| > 12: within 6e-6 of a bound)."""
    bounded = np.concatenate(
        [
            np.full(
                p.size,
                p.transform == "logit" or (p.transform == "log" and math.isfinite(p.bounds[1])),
            )
            for p in layout.free
        ]
        or [np.zeros(0, bool)]
    )
    return bounded & (np.abs(u) > 12.0)


def _assemble(
    model,
    m,
    layout,
    params,
    start,
    preps,
    status,
    steps,
    n_starts,
    errors,
    cut,
    source,
    t0,
    pinned,
):
    """Uncertainties, information criteria, every metric, flags -> FitResult.

    Scalars ``pinned`` at a bound by the active-set pass are left out of the
    covariance; their standard error is NaN.
    """
    x = layout.join({k: jnp.asarray(v) for k, v in params.items()})
    frozen = dict(layout.frozen)
    prep = preps[m.name]
    cov = corr = stderr = None
    cond, reason = float("nan"), None
    r = np.zeros(0)
    if status is not Status.NONFINITE:
        r, j = (np.asarray(a) for a in _jacobian(model, layout.free, m, x, prep, frozen))
        act = ~pinned
        cov_a, cond, reason = _covariance(j[:, act], r, errors, int(act.sum()))
        if cov_a is not None:
            cov = np.full((layout.size, layout.size), np.nan)
            cov[np.ix_(act, act)] = cov_a
    else:
        reason = "the fit is not finite"
    if cov is not None:
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        with np.errstate(invalid="ignore"):
            corr = cov / np.outer(np.where(sd > 0, sd, 1), np.where(sd > 0, sd, 1))
        stderr = {k: np.asarray(v) for k, v in layout.split(jnp.asarray(sd)).items()}
        stderr.update({k: np.zeros(np.shape(v)) for k, v in frozen.items()})
        stderr = {p.name: stderr[p.name] for p in model.parameters}

    n_data = 3 * prep.n
    k = layout.size + 1  # + the noise variance
    rss = max(float(r @ r), 1e-300) if r.size else float("nan")
    aic = n_data * math.log(rss / n_data) + 2 * k if r.size else float("nan")
    bic = n_data * math.log(rss / n_data) + k * math.log(n_data) if r.size else float("nan")
    losses = {k: float(v) for k, v in _all_losses(model, params, preps).items()}
    labels = layout.labels()
    at_bound = tuple(
        p.name
        for p in layout.free
        if np.any(np.isclose(params[p.name], p.bounds[0], rtol=1e-6, atol=1e-9))
        or np.any(np.isclose(params[p.name], p.bounds[1], rtol=1e-6, atol=1e-9))
        or any(pinned[i] for i, lab in enumerate(labels) if lab.split("[")[0] == p.name)
    )
    warnings = []
    if at_bound:
        warnings.append(
            f"parameters at a bound: {', '.join(at_bound)}; the best fit lies on the bound, "
            "their errors are unreliable (NaN where pinned)"
        )
    if reason and status is not Status.NONFINITE:
        warnings.append(f"no uncertainties: {reason}")
    elif math.isfinite(cond) and cond > 1e10:
        warnings.append(
            f"J^T J is ill-conditioned ({cond:.3g}): some parameters are poorly identified"
        )
    return FitResult(
        model=model.name,
        options=model.options(),
        metric=m.name,
        params={p.name: params[p.name] for p in model.parameters},
        init_params={k: np.asarray(v) for k, v in start.items()},
        stderr=stderr,
        covariance=cov,
        correlation=corr,
        labels=tuple(layout.labels()),
        frozen=tuple(frozen),
        errors_method=errors,
        errors_reason=reason,
        loss=losses[m.name],
        losses=losses,
        cost=0.5 * rss if r.size else float("nan"),
        n_samples=prep.n,
        n_data=n_data,
        n_free=layout.size,
        aic=aic,
        bic=bic,
        condition_number=cond,
        status=status,
        n_steps=steps,
        n_starts=n_starts,
        wall_time=time.perf_counter() - t0,
        cut_deg=cut,
        source=source,
        at_bound=at_bound,
        warnings=tuple(warnings),
    )
