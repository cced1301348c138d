"""Uncertainties and the :class:`~brdffit.core.result.FitResult` of a finished descent.

Uncertainties come from the Jacobian ``J`` of the residuals with respect to the free
natural parameters at the optimum. ``errors="sandwich"`` (default) is the
heteroscedasticity-consistent ``(J^T J)^-1 J^T diag(r^2) J (J^T J)^-1``;
``errors="classic"`` is ``s^2 (J^T J)^-1`` with ``s^2 = sum r^2 / (n - k)``. Both
assume independent residuals: neighbouring cells of measured data share model error,
so on measured data they are a lower bound (see DESIGN.md). ``errors="blocks"`` admits
that error: residuals are grouped in blocks of :data:`BLOCK_DEG` x :data:`BLOCK_DEG`
degrees in (theta_h, theta_d), correlated any way within a block and independent
between blocks, and the covariance is the cluster jackknife (CR3; MacKinnon and White
1985, Bell and McCaffrey 2002, MacKinnon, Nielsen and Webb 2023) in its one-step form:
with ``A = J^T J``, ``A_b = J_b^T J_b`` and ``s_b = J_b^T e_b`` the Gram matrix and score
of block ``b``, leaving block ``b`` out moves the estimate by ``d_b = (A - A_b)^-1 s_b``,
and ``cov = (G-1)/G sum_b d_b d_b^T`` over the ``G`` blocks (exact for a model linear
in its parameters: ``tests/engine/test_block_errors.py`` checks it against real refits).
Unlike the plain cluster sandwich (``A^-1 [sum s_b s_b^T] A^-1``, Liang and Zeger 1986,
CR1) it does not shrink the blocks that carry most of the information (the specular
peak, the grazing rise), whose own residuals the fit has pulled towards zero. Which
correction, by measurement (``benchmarks/split_halves.py``: walter fitted to two
disjoint checkerboard halves of 24 NBRDF materials; the share of scalars whose two
estimates agree within their stated 95%): CR1 58.5%, CR2 (half the leverage
correction, :func:`block_covariance` with ``power=0.5``) 86.6%, CR3 100% (median
``|z|`` 0.28 where 0.67 would be exact). CR3 is the only one not overconfident there,
so it is the default of ``"blocks"``; its intervals are wider than needed on these
halves. It needs many blocks (it counts them, :func:`brdffit.core.result_terms.errors_assumed`)
and none that alone identifies a parameter.

Only k x k matrices (``J^T J`` and ``J^T diag(r^2) J``, formed on the device by
:meth:`brdffit.engine.objective.Objective.natural_moments`; for ``"blocks"``, ``J^T J`` and
the blocks' scores and Gram matrices, from one Jacobian by
:meth:`~brdffit.engine.objective.Objective.natural_block_moments`) reach numpy.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from brdffit.core.parameters import ParameterLayout, Params
from brdffit.core.result import FitResult, Status
from brdffit.core.result_terms import AT_BOUND_ATOL, AT_BOUND_RTOL, BLOCK_DEG
from brdffit.engine import objective as objective_mod
from brdffit.engine.metrics import Metric, Prepared
from brdffit.engine.objective import Objective

NULL_EIGEN = 1e-10
"""Eigenvalue of the column-scaled ``J^T J``, relative to the largest, under which its
direction counts as not identified (the square root, 1e-5, is the relative change of
the residuals along it that float64 still resolves against the data's noise)."""

SINGULAR = 1e15
"""Condition number of the column-scaled ``J^T J`` past which it is singular to
working precision (float64 resolves 1 in 4.5e15)."""


ERRORS = ("sandwich", "classic", "blocks")
"""The kinds of standard errors :func:`brdffit.fit` reports (module docstring)."""

"""Side of the (theta_h, theta_d) blocks of ``errors="blocks"``, degrees. Model error is
a smooth function of (theta_h, theta_d): the residuals of a fit to measured data change
sign over a few degrees (specular peak, Fresnel rise), so a 10-degree block holds a
stretch of correlated error while the 80-degree cut keeps 50-70 occupied blocks, enough
for the cluster sum (Cameron and Miller 2015 advise some 50)."""

MIN_BLOCKS = 20
"""Fewer occupied blocks than this and ``errors="blocks"`` gives no errors (the cluster
sum of ``G`` scores has rank ``< G`` and is unreliable for small ``G``)."""


def block_cells(prep: Prepared, block_deg: float = BLOCK_DEG) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's block coordinates ``(floor(theta_h / deg), floor(theta_d / deg))``."""
    th = np.degrees(np.arccos(np.clip(np.asarray(prep.g.cos_h), -1.0, 1.0)))
    td = np.degrees(np.arccos(np.clip(np.asarray(prep.g.cos_d), -1.0, 1.0)))
    return np.floor(th / block_deg).astype(int), np.floor(td / block_deg).astype(int)


def block_index(prep: Prepared, block_deg: float = BLOCK_DEG) -> tuple[np.ndarray, int]:
    """Each sample's (theta_h, theta_d) block, numbered 0..G-1 over occupied blocks; G."""
    i, j = block_cells(prep, block_deg)
    per_row = int(np.ceil(90.0 / block_deg)) + 1
    occupied, ids = np.unique(i * per_row + j, return_inverse=True)
    return ids.astype(np.int32), int(occupied.size)


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


def conditioning(jtj: np.ndarray) -> tuple[float, str | None, np.ndarray]:
    """Condition of the column-scaled ``J^T J``, why it has no inverse, and weak scalars.

    Returns (condition, reason, weak): ``reason`` is None when ``J^T J`` can be inverted;
    ``weak`` flags the scalars that carry the near-null directions of the column-scaled
    ``J^T J`` (eigenvalues below :data:`NULL_EIGEN` of the largest), i.e. the parameters
    the data do not identify on their own: those with more than half of their variance
    on those directions (Belsley, Kuh & Welsch 1980, "Regression Diagnostics", ch. 3,
    variance-decomposition proportions). A scalar that moves along a null direction
    has its variance there however small its share of the unit eigenvector.
    """
    k = jtj.shape[0]
    weak = np.zeros(k, bool)
    if k == 0:
        return float("nan"), "no free parameter", weak
    if not np.all(np.isfinite(jtj)):
        return float("inf"), "J^T J is not finite", weak
    d = np.sqrt(np.diag(jtj))
    if np.any(d == 0):
        return float("inf"), "a parameter does not change the residuals", d == 0
    ev, vec = np.linalg.eigh(jtj / np.outer(d, d))
    cond = float(ev[-1] / ev[0]) if ev[0] > 0 else float("inf")
    small = ev < NULL_EIGEN * ev[-1]
    if small.any():  # var(z_j) = sum_i v_ji^2 / ev_i, an eigenvalue no smaller than eps
        phi = vec**2 / np.maximum(ev, np.finfo(float).eps * ev[-1])
        weak = phi[:, small].sum(axis=1) > 0.5 * phi.sum(axis=1)
    if not np.isfinite(cond) or cond > SINGULAR:
        return cond, f"J^T J is singular to working precision (condition {cond:.3g})", weak
    return cond, None, weak


def covariance(
    jtj: np.ndarray, meat: np.ndarray, ee: float, n_data: int, method: str
) -> tuple[np.ndarray | None, float, str | None, np.ndarray]:
    """Covariance of the scalars from ``J^T J``, the sandwich's meat and ``e.e``.

    ``meat`` is ``J^T diag(e^2) J``; ``method`` ``"sandwich"`` or ``"classic"``
    (:data:`ERRORS`; ``"blocks"`` is :func:`block_covariance`).

    Returns (cov, condition, reason, weak): cov None with a reason where
    :func:`conditioning` gives one, which also gives condition and weak.
    """
    cond, reason, weak = conditioning(jtj)
    if reason is not None:
        return None, cond, reason, weak
    d = np.sqrt(np.diag(jtj))
    bread = np.linalg.inv(jtj / np.outer(d, d)) / np.outer(d, d)
    if method == "classic":
        cov = bread * ee / max(n_data - jtj.shape[0], 1)
    else:
        cov = bread @ meat @ bread
    return 0.5 * (cov + cov.T), cond, None, weak


def _free_covariance(
    obj: Objective, z: np.ndarray, prep: Prepared, padded: Prepared, act: np.ndarray, errors: str
) -> tuple[np.ndarray | None, float, str | None, np.ndarray, float, int]:
    """Covariance of the scalars not held on a bound (``act``) by ``errors`` (``padded``:
    ``prep`` padded, for the sums that padding leaves unchanged).

    Returns (cov, condition, reason, weak) as :func:`covariance`, then the plain
    residuals' ``r.r`` and the number of blocks (0 unless ``errors="blocks"``).
    """
    ix = np.ix_(act, act)
    if errors != "blocks":
        moments = objective_mod.natural_moments(obj, z, padded)
        jtj, meat, ee, rr = (np.asarray(a) for a in moments)
        cov, cond, reason, weak = covariance(jtj[ix], meat[ix], float(ee), 3 * prep.n, errors)
        return cov, cond, reason, weak, float(rr), 0
    ids, n_blocks = block_index(prep)
    moments = objective_mod.natural_block_moments(obj, z, prep, np.asarray(ids), n_blocks)
    jtj, rr, scores, grams = (np.asarray(a) for a in moments)
    cond, reason, weak = conditioning(jtj[ix])
    cov = None
    if reason is None:
        cov, reason = block_covariance(jtj[ix], scores[:, act], grams[:, act][:, :, act])
    return cov, cond, reason, weak, float(rr), n_blocks


def assemble(
    obj: Objective,
    m: Metric,
    out: Outcome,
    preps: dict[str, Prepared],
    *,
    padded: Prepared | None = None,
    errors: str,
    cut: float | None,
    source: str,
    t0: float,
) -> FitResult:
    """Uncertainties, information criteria, every metric and flags -> :class:`FitResult`
    of a fit under ``m`` (``preps``: the data prepared for every metric; ``padded``:
    ``preps[m.name]`` :meth:`~brdffit.engine.metrics.Prepared.padded`, made here if not given).

    The other metrics are padded only for their losses, at the end, sharing ``padded``'s
    geometry: padding every metric at the start of a fit held 3 more copies of the data
    side through the descent (SGD at full resolution: 4.3 GB peak, 3.8 GB without them)."""
    layout, model = obj.layout, obj.model
    prep = preps[m.name]
    padded = prep.padded() if padded is None else padded
    z = np.asarray(out.z)
    params = {k: np.asarray(v) for k, v in obj.params(z).items()}
    cov = corr = stderr = None
    cond, reason, weak_names, rss = float("nan"), None, [], float("nan")
    n_data, n_blocks = 3 * prep.n, 0
    if out.status is not Status.NONFINITE:
        act = ~out.binding
        cov_a, cond, reason, weak, rr, n_blocks = _free_covariance(
            obj, z, prep, padded, act, errors
        )
        rss = max(rr, 1e-300)
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
        stderr = {k: np.asarray(v) for k, v in layout.split(sd).items()}
        stderr.update({k: np.zeros(np.shape(v)) for k, v in obj.frozen.items()})
        stderr = {p.name: stderr[p.name] for p in model.parameters}
        weak_names += [lab for lab in unidentified(layout, params, sd) if lab not in weak_names]

    k = layout.size + 1  # + the noise variance
    finite = math.isfinite(rss)
    aic = n_data * math.log(rss / n_data) + 2 * k if finite else float("nan")
    bic = n_data * math.log(rss / n_data) + k * math.log(n_data) if finite else float("nan")
    # padded here and let go (pad, not the kept ``padded``): kept, the other metrics'
    # copies would be held through every later descent on these data
    every = {k: padded if k == m.name else p.pad(padded.n, padded) for k, p in preps.items()}
    losses = {k: float(v) for k, v in objective_mod.all_losses(model, params, every).items()}
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


def block_covariance(
    jtj: np.ndarray, scores: np.ndarray, grams: np.ndarray, power: float = 1.0
) -> tuple[np.ndarray | None, str | None]:
    """The leverage-corrected cluster covariance (module docstring) and why not, if not.

    ``jtj`` (k, k); ``scores`` (G, k) the blocks' ``J_b^T e_b``; ``grams`` (G, k, k) their
    ``J_b^T J_b``. With ``M_b = A^-1/2 A_b A^-1/2 = V diag(l) V^T`` each block's
    contribution is ``u_b = A^-1/2 V diag((1 - l)^-power) V^T A^-1/2 s_b``: ``power`` 1/2
    is CR2 (Bell and McCaffrey), ``cov = sum u_b u_b^T``; 1 is the one-step jackknife CR3
    (``u_b = (A - A_b)^-1 s_b``), ``cov = (G-1)/G sum u_b u_b^T``. None with a reason below
    :data:`MIN_BLOCKS` blocks or when one block alone identifies a direction (``l`` -> 1).
    """
    g = scores.shape[0]
    if g < MIN_BLOCKS:
        return None, f"{g} blocks for errors='blocks', fewer than {MIN_BLOCKS}"
    d = np.sqrt(np.diag(jtj))
    ev, vec = np.linalg.eigh(jtj / np.outer(d, d))  # column-scaled, as in conditioning()
    inv_half = vec @ np.diag(ev**-0.5) @ vec.T
    u = np.empty_like(scores)
    for b in range(g):
        lev, v = np.linalg.eigh(inv_half @ (grams[b] / np.outer(d, d)) @ inv_half)
        if not np.all(np.isfinite(lev)) or np.max(lev) > 1.0 - 1.0 / SINGULAR:
            return None, f"block {b} alone identifies a direction of J^T J (errors='blocks')"
        factor = v @ np.diag((1.0 - np.clip(lev, 0.0, None)) ** -power) @ v.T
        u[b] = inv_half @ factor @ inv_half @ (scores[b] / d) / d
    cov = u.T @ u * ((g - 1) / g if power == 1.0 else 1.0)
    return 0.5 * (cov + cov.T), None


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
    elif weak_names:
        out.append(
            f"not identified by the data: {', '.join(weak_names)}; the standard error exceeds "
            "the range the bounds allow (for a scale fitted in ln x: the value itself), so "
            "the value is arbitrary: freeze it or leave its feature out (brdffit simplify)"
        )
    return tuple(out)


def unidentified(
    layout: ParameterLayout, params: dict[str, np.ndarray], sd: np.ndarray
) -> list[str]:
    """Labels of the free scalars whose standard error ``sd`` exceeds their width.

    The width is the span of the bounds, or ``|x|`` for a scale the solver fits in
    ``ln x`` (:attr:`~brdffit.core.parameters.Parameter.solver_log`) or a half-open range: a
    one-sigma interval wider than every value the model allows (for a scale: a relative
    error over 100%, not even the order of magnitude known) means the data do not pin
    the scalar down. This is the test the near-null rule of :func:`covariance` cannot
    make: it looks at ``J^T J`` scaled by its own columns, which hides a scalar whose
    column is tiny but not zero (a tint of a lobe whose weight sits at 4e-18), while
    its variance, ``1 / |J_j|^2`` times a well-conditioned factor, explodes (errors of
    1e15 on a [0, 1] tint). Identified scalars have errors orders of magnitude below
    their width, so the threshold 1 needs no tuning. ``sd`` NaN (held on a bound) is
    left to the at-bound flag.
    """
    lo, hi = layout.bounds_flat()
    x = layout.natural_vector(params)
    span = np.isfinite(lo) & np.isfinite(hi) & ~layout.solver_log_mask()
    with np.errstate(invalid="ignore"):
        width = np.where(span, hi - lo, np.abs(x))
        bad = np.isfinite(sd) & (sd > width)
    return [lab for lab, b in zip(layout.labels(), bad, strict=True) if b]


def _at_bound(
    layout: ParameterLayout, params: dict[str, np.ndarray], binding: np.ndarray
) -> tuple[str, ...]:
    """Labels of the free scalars (``kd[b]``, ``alpha``) within :data:`AT_BOUND_RTOL` /
    :data:`AT_BOUND_ATOL` of a bound, or held on it by the active set."""
    lo, hi = layout.bounds_flat()
    x = layout.natural_vector(params)
    tol = dict(rtol=AT_BOUND_RTOL, atol=AT_BOUND_ATOL)
    near = np.asarray(binding, bool) | np.isclose(x, lo, **tol) | np.isclose(x, hi, **tol)
    return tuple(lab for lab, n in zip(layout.labels(), near, strict=True) if n)
