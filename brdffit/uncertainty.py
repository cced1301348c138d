"""Uncertainties and the :class:`~brdffit.result.FitResult` of a finished descent.

Uncertainties come from the Jacobian ``J`` of the residuals with respect to the free
natural parameters at the optimum. ``errors="sandwich"`` (default) is the
heteroscedasticity-consistent ``(J^T J)^-1 J^T diag(r^2) J (J^T J)^-1``;
``errors="classic"`` is ``s^2 (J^T J)^-1`` with ``s^2 = sum r^2 / (n - k)``. Both
assume independent residuals: neighbouring cells of measured data share model error,
so on measured data they are a lower bound (see DESIGN.md). ``errors="blocks"`` admits
that error: the cluster-robust sandwich (Liang and Zeger 1986; the analytic form of a
block bootstrap) with the scores ``J_i^T e_i`` summed over blocks of
:data:`BLOCK_DEG` x :data:`BLOCK_DEG` degrees in (theta_h, theta_d) before their outer
product, ``(J^T J)^-1 [sum_b s_b s_b^T] (J^T J)^-1`` times the small-sample factor
``G/(G-1) (n-1)/(n-k)`` for ``G`` blocks. It assumes residuals correlated within a
block (any way) and independent between blocks; it needs many blocks (it counts them
and says so, :func:`describe`). The sandwich form stays right when the
residual scale varies over the samples (e.g. multiplicative noise on a linear metric),
where the classic form was 9-12x too narrow in DESIGN's experiment. Scalars held on a
bound by the solver's active set are left out (standard error NaN). With a robust loss,
``r`` and ``J`` are the robust residuals and their Jacobian (the Gauss-Newton form of
the M-estimator sandwich); AIC, BIC and ``cost`` always use the plain residuals.

Only k x k matrices (``J^T J`` and ``J^T diag(r^2) J``, formed on the device by
:meth:`brdffit.objective.Objective.natural_moments`) reach numpy.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from brdffit import objective as objective_mod
from brdffit.metrics import Prepared
from brdffit.objective import Objective
from brdffit.parameters import ParameterLayout, Params
from brdffit.result import FitResult, Status

NULL_EIGEN = 1e-10
"""Eigenvalue of the column-scaled ``J^T J``, relative to the largest, under which its
direction counts as not identified (the square root, 1e-5, is the relative change of
the residuals along it that float64 still resolves against the data's noise)."""

SINGULAR = 1e15
"""Condition number of the column-scaled ``J^T J`` past which it is singular to
working precision (float64 resolves 1 in 4.5e15)."""


ERRORS = ("sandwich", "classic", "blocks")
"""The kinds of standard errors :func:`brdffit.fit` reports (module docstring)."""

BLOCK_DEG = 10.0
"""Side of the (theta_h, theta_d) blocks of ``errors="blocks"``, degrees. Model error is
a smooth function of (theta_h, theta_d): the residuals of a fit to measured data change
sign over a few degrees (specular peak, Fresnel rise), so a 10-degree block holds a
stretch of correlated error while the 80-degree cut keeps 50-70 occupied blocks, enough
for the cluster sum (Cameron and Miller 2015 advise some 50)."""

MIN_BLOCKS = 20
"""Fewer occupied blocks than this and ``errors="blocks"`` gives no errors (the cluster
sum of ``G`` scores has rank ``< G`` and is unreliable for small ``G``)."""


def block_index(prep: Prepared, block_deg: float = BLOCK_DEG) -> tuple[np.ndarray, int]:
    """Each sample's (theta_h, theta_d) block, numbered 0..G-1 over occupied blocks; G."""
    th = np.degrees(np.arccos(np.clip(np.asarray(prep.g.cos_h), -1.0, 1.0)))
    td = np.degrees(np.arccos(np.clip(np.asarray(prep.g.cos_d), -1.0, 1.0)))
    per_row = int(np.ceil(90.0 / block_deg)) + 1
    raw = np.floor(th / block_deg).astype(int) * per_row + np.floor(td / block_deg).astype(int)
    occupied, ids = np.unique(raw, return_inverse=True)
    return ids.astype(np.int32), int(occupied.size)


def describe(method: str, n_blocks: int = 0) -> str:
    """What the standard errors of ``method`` assume, for reports."""
    if method == "classic":
        return "residuals independent, one variance; errors by classic (s^2 (J^T J)^-1)"
    if method == "blocks":
        return (
            f"residuals correlated within {BLOCK_DEG:g}-degree (theta_h, theta_d) blocks, "
            f"independent between them; errors by block sandwich over {n_blocks} blocks"
        )
    return "residuals independent, any variance; errors by sandwich"


@dataclass(frozen=True)
class Outcome:
    """What the engine hands over for one problem.

    Fields: ``z`` the answer (solver space); ``status``; ``binding`` scalars held on a
    bound; ``start`` natural dict of the winning start; ``n_steps`` the finishing
    descents' tried steps; ``n_starts``; ``coarse`` (thinned sample count, 0 if none;
    tried steps over all starts there); ``robust_scale``.
    """

    z: np.ndarray
    status: Status
    binding: np.ndarray
    start: Params
    n_steps: int
    n_starts: int
    coarse: tuple[int, int]
    robust_scale: float | None


def covariance(
    jtj: np.ndarray, meat: np.ndarray, ee: float, n_data: int, method: str
) -> tuple[np.ndarray | None, float, str | None, np.ndarray]:
    """Covariance of the scalars from ``J^T J``, the sandwich's meat and ``e.e``.

    ``meat`` is ``J^T diag(e^2) J`` or, for ``errors="blocks"``, the corrected sum of the
    blocks' score products (module docstring); ``method`` as :data:`ERRORS`.

    Returns (cov, condition, reason, weak): ``weak`` flags the scalars that carry the
    near-null directions of the column-scaled ``J^T J`` (eigenvalues below
    :data:`NULL_EIGEN` of the largest; a component above 0.3 of the unit eigenvector),
    i.e. the parameters the data do not identify on their own.
    """
    k = jtj.shape[0]
    weak = np.zeros(k, bool)
    if k == 0:
        return None, float("nan"), "no free parameter", weak
    if not np.all(np.isfinite(jtj)):
        return None, float("inf"), "J^T J is not finite", weak
    d = np.sqrt(np.diag(jtj))
    if np.any(d == 0):
        return None, float("inf"), "a parameter does not change the residuals", d == 0
    scaled = jtj / np.outer(d, d)
    ev, vec = np.linalg.eigh(scaled)
    cond = float(ev[-1] / ev[0]) if ev[0] > 0 else float("inf")
    small = ev < NULL_EIGEN * ev[-1]
    weak = np.any(np.abs(vec[:, small]) > 0.3, axis=1) if small.any() else weak
    if not np.isfinite(cond) or cond > SINGULAR:
        return None, cond, f"J^T J is singular to working precision (condition {cond:.3g})", weak
    bread = np.linalg.inv(scaled) / np.outer(d, d)
    if method == "classic":
        cov = bread * ee / max(n_data - k, 1)
    else:
        cov = bread @ meat @ bread
    return 0.5 * (cov + cov.T), cond, None, weak


def assemble(
    obj: Objective,
    out: Outcome,
    preps: dict[str, Prepared],
    *,
    errors: str,
    cut: float | None,
    source: str,
    t0: float,
) -> FitResult:
    """Uncertainties, information criteria, every metric and flags -> :class:`FitResult`."""
    layout, model, m = obj.layout, obj.model, obj.metric
    prep = preps[m.name]
    z = jnp.asarray(out.z)
    params = {k: np.asarray(v) for k, v in obj.params(z).items()}
    cov = corr = stderr = None
    cond, reason, weak_names, rss = float("nan"), None, [], float("nan")
    n_data, n_blocks = 3 * prep.n, 0
    if out.status is not Status.NONFINITE:
        jtj, meat, ee, rr = (np.asarray(a) for a in objective_mod.natural_moments(obj, z, prep))
        if errors == "blocks":
            meat, n_blocks = _block_meat(obj, z, prep, n_data)
        rss = max(float(rr), 1e-300)
        act = ~out.binding
        cov_a, cond, reason, weak = covariance(
            jtj[np.ix_(act, act)], meat[np.ix_(act, act)], float(ee), n_data, errors
        )
        if errors == "blocks" and n_blocks < MIN_BLOCKS and cov_a is not None:
            cov_a, reason = None, f"{n_blocks} blocks for errors='blocks', fewer than {MIN_BLOCKS}"
        labels_act = [lab for lab, a in zip(layout.labels(), act, strict=True) if a]
        weak_names = [lab for lab, w in zip(labels_act, weak, strict=True) if w]
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
        stderr.update({k: np.zeros(np.shape(v)) for k, v in obj.frozen.items()})
        stderr = {p.name: stderr[p.name] for p in model.parameters}

    k = layout.size + 1  # + the noise variance
    finite = math.isfinite(rss)
    aic = n_data * math.log(rss / n_data) + 2 * k if finite else float("nan")
    bic = n_data * math.log(rss / n_data) + k * math.log(n_data) if finite else float("nan")
    losses = {name: float(v) for name, v in objective_mod.all_losses(model, params, preps).items()}
    at_bound = _at_bound(layout, params, out.binding)
    return FitResult(
        model=model.name,
        options=model.options(),
        metric=m.name,
        params={p.name: params[p.name] for p in model.parameters},
        init_params={k: np.asarray(v) for k, v in out.start.items()},
        stderr=stderr,
        covariance=cov,
        correlation=corr,
        labels=tuple(layout.labels()),
        frozen=tuple(obj.frozen),
        errors_method=errors,
        errors_reason=reason,
        error_blocks=n_blocks,
        loss=losses[m.name],
        losses=losses,
        cost=0.5 * rss if finite else float("nan"),
        n_samples=prep.n,
        n_data=n_data,
        n_free=layout.size,
        aic=aic,
        bic=bic,
        condition_number=cond,
        status=out.status,
        n_steps=out.n_steps,
        n_starts=out.n_starts,
        wall_time=time.perf_counter() - t0,
        cut_deg=cut,
        source=source,
        at_bound=at_bound,
        warnings=_warnings(at_bound, reason, out.status, cond, weak_names),
        not_identified=tuple(weak_names),
        coarse_samples=out.coarse[0],
        coarse_steps=out.coarse[1],
        robust=obj.robust,
        robust_scale=out.robust_scale,
    )


def _block_meat(obj: Objective, z, prep: Prepared, n_data: int) -> tuple[np.ndarray, int]:
    """The cluster-robust meat over (theta_h, theta_d) blocks, corrected; block count."""
    ids, g = block_index(prep)
    s = np.asarray(objective_mod.block_scores(obj, z, prep, jnp.asarray(ids), g))
    k = s.shape[1]
    factor = g / max(g - 1, 1) * (n_data - 1) / max(n_data - k, 1)
    return factor * (s.T @ s), g


def _warnings(at_bound, reason, status, cond, weak_names) -> tuple[str, ...]:
    out = []
    if at_bound:
        out.append(
            f"parameters at a bound: {', '.join(at_bound)}; the best fit lies on the bound, "
            "their errors are unreliable (NaN where held on it)"
        )
    named = f" ({', '.join(weak_names)})" if weak_names else ""
    if reason and status is not Status.NONFINITE:
        out.append(f"no uncertainties: {reason}; not identified{named or ' (none named)'}")
    elif math.isfinite(cond) and cond > 1e10:
        out.append(
            f"J^T J is ill-conditioned ({cond:.3g}): poorly identified{named or ' (none named)'}"
        )
    return tuple(out)


def _at_bound(
    layout: ParameterLayout, params: dict[str, np.ndarray], binding: np.ndarray
) -> tuple[str, ...]:
    """Names of free parameters within 1e-6 of a bound or held on it by the active set."""
    held = {lab.split("[")[0] for lab, b in zip(layout.labels(), binding, strict=True) if b}
    return tuple(
        p.name
        for p in layout.free
        if p.name in held
        or np.any(np.isclose(params[p.name], p.bounds[0], rtol=1e-6, atol=1e-9))
        or np.any(np.isclose(params[p.name], p.bounds[1], rtol=1e-6, atol=1e-9))
    )
