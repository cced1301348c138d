"""Uncertainties and the :class:`~brdffit.core.result.FitResult` of a finished descent.

Uncertainties come from the Jacobian ``J`` of the residuals with respect to the free
natural parameters at the optimum. ``errors="sandwich"`` (default) is the
heteroscedasticity-consistent ``(J^T J)^-1 J^T diag(r^2) J (J^T J)^-1``;
``errors="classic"`` is ``s^2 (J^T J)^-1`` with ``s^2 = sum r^2 / (n - k)``. Both
assume independent residuals: neighbouring cells of measured data share model error,
so on measured data they are a lower bound (see DESIGN.md). ``errors="blocks"`` admits
that error: residuals are grouped in blocks of :data:`BLOCK_DEG` x :data:`BLOCK_DEG`
degrees in (theta_h, theta_d), correlated any way within a block and independent
between blocks. Its covariance is the bias-reduced cluster sandwich (CR2; Bell and
McCaffrey 2002): with ``A = J^T J``, ``A_b = J_b^T J_b`` and ``s_b = J_b^T e_b`` the Gram
matrix and score of block ``b``, each score is divided by the square root of its
block's leverage, ``u_b = A^-1/2 (I - A^-1/2 A_b A^-1/2)^-1/2 A^-1/2 s_b``, and
``cov = sum_b u_b u_b^T``. The plain cluster sandwich (``A^-1 [sum s_b s_b^T] A^-1``, Liang
and Zeger 1986, CR1) shrinks the blocks that carry most of the information (the
specular peak, the grazing rise), whose own residuals the fit has pulled towards zero;
CR2 undoes that shrinkage exactly for a linear model with independent errors.

A few blocks carry the specular parameters, so their variance is estimated from a few
numbers and the normal quantile 1.96 is too small. Each scalar's effective degrees of
freedom ``nu`` are Bell and McCaffrey's Satterthwaite approximation
(:func:`~brdffit.engine.block_errors.effective_dof`, as Imbens and Kolesar 2016 and
Pustejovsky and Tipton 2018 recommend for few or unequal clusters), and the 95% interval
is ``t_0.975(nu)`` CR2 errors wide: the reported standard error is the CR2 error times
``t_0.975(nu) / 1.96`` (:func:`~brdffit.engine.block_errors.coverage_factor`, the
coverage factor of the GUM's expanded uncertainty), so that ``value +/- 1.96 stderr`` is
that interval everywhere brdffit draws one, and
``nu`` is kept in :attr:`~brdffit.core.result.FitResult.error_dof`.

Which estimator, by measurement (``benchmarks/split_halves.py``: walter fitted to two
disjoint checkerboard halves of 100 NBRDF materials, 891 scalars under ``low_e2``; the
factor by which the stated 95% intervals would have to be scaled to hold 95% of the half
differences, 1 if calibrated; ``benchmarks/results/split_halves.md``): sandwich 18.8,
CR1 3.43, CR2 with normal quantiles 1.85, CR3 (the previous default) 0.60, CR2 with the
t widening 1.05 (its half differences judged by Welch's t). The last is the default, the
only one within 1.25x of calibrated there; with other models and metrics it gives 1.28
(walter, ngan), 0.87 (cook_torrance) and 0.70 (disney), the same file. It needs many
blocks (it counts them, :func:`brdffit.core.result_terms.errors_assumed`) and none that
alone identifies a parameter.

``errors="auto"`` (the default of :func:`brdffit.fit`) is ``"blocks"`` for measured data
and ``"sandwich"`` for synthetic data (:attr:`~brdffit.core.measurements.Measurements.synthetic`:
a model's own values plus independent noise have no model error to admit), and
``"sandwich"`` where the data have too few blocks for ``"blocks"`` (the result says so).

A scalar held on a bound gets no error of its own. Unless the data hold it there firmly,
the other scalars' errors are their block of the covariance over every scalar, as if it
were free (:func:`_marginal_covariance` says why and when). On the split halves this took
walter's ``ks`` under ``ngan`` from 3.31 to 1.61 and the pooled factor from 1.74 to 1.28;
it made disney's, whose scalars trade off against a loosely held ``subsurface`` or
``specular``, conservative (0.98 to 0.70). The synthetic coverage of
``benchmarks/results/calibration_lm100.md`` is unchanged, scalar for scalar.

Only k x k matrices (``J^T J`` and ``J^T diag(r^2) J``; for ``"blocks"``, ``J^T J`` and
the blocks' scores and Gram matrices) reach numpy. They are formed on the device by
:meth:`brdffit.engine.objective.Objective.answer`, from one Jacobian pass at the answer
that also gives every metric's loss: the descent's last linearisation is not at the
answer (a descent that stops after an accepted step does not linearise there again), and
the sandwich and the blocks need sums the descent does not keep.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from brdffit.core.parameters import ParameterLayout, Params
from brdffit.core.result import FitResult, Status
from brdffit.core.result_terms import AT_BOUND_ATOL, AT_BOUND_RTOL
from brdffit.engine import objective as objective_mod
from brdffit.engine.block_errors import BlockChunks, block_chunks, block_errors
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

CHOICES = ("auto", *ERRORS)
"""What ``errors=`` accepts: a kind of :data:`ERRORS`, or ``"auto"`` (module docstring)."""

LEVEL = 0.95
"""The interval the ``"blocks"`` errors are widened for
(:func:`~brdffit.engine.block_errors.coverage_factor`)."""


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
    (:data:`ERRORS`; ``"blocks"`` is :func:`~brdffit.engine.block_errors.block_errors`).

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


def resolve(errors: str, synthetic: bool) -> str:
    """The kind ``errors`` (:data:`CHOICES`) stands for on measured or ``synthetic`` data."""
    if errors != "auto":
        return errors
    return "sandwich" if synthetic else "blocks"


@dataclass(frozen=True)
class _Errors:
    """The free scalars' covariance and what came with it (:func:`_free_covariance`).

    ``cov`` None with ``reason``; ``cond`` and ``weak`` from :func:`conditioning`; ``rr``
    the plain residuals' ``r.r``; ``method`` the kind used (``"auto"`` resolved);
    ``n_blocks`` and ``dof`` (per free scalar) for ``"blocks"``, else 0 and None;
    ``fallback`` why ``"auto"`` fell back to ``"sandwich"``, or None.
    """

    cov: np.ndarray | None
    cond: float
    reason: str | None
    weak: np.ndarray
    rr: float
    method: str
    n_blocks: int = 0
    dof: np.ndarray | None = None
    fallback: str | None = None


def _free_covariance(
    obj: Objective,
    z: np.ndarray,
    padded: Prepared,
    act: np.ndarray,
    errors: str,
    method: str,
    chunks: BlockChunks | None,
    moments: tuple,
    n_data: int,
) -> _Errors:
    """Covariance of the scalars not held on a bound (``act``) by ``method`` (``errors``
    resolved, :func:`resolve`) from the ``moments`` at the answer ``z``
    (:meth:`~brdffit.engine.objective.Objective.answer` on ``padded``: block moments where
    ``chunks`` are given, else the sandwich's); ``n_data`` the residuals not padding."""
    ix = np.ix_(act, act)
    fallback = None
    if chunks is not None:
        n_blocks = chunks.n_blocks
        jtj, rr, scores, grams = (np.asarray(a) for a in moments)
        cond, reason, weak = conditioning(jtj[ix])
        if reason is not None:
            return _Errors(None, cond, reason, weak, float(rr), method, n_blocks)
        jtj, grams = jtj[ix], grams[:, act][:, :, act]
        cov, dof, reason = block_errors(jtj, scores[:, act], grams, LEVEL)
        if cov is not None or errors != "auto":
            return _Errors(cov, cond, reason, weak, float(rr), method, n_blocks, dof)
        method, fallback = "sandwich", reason
        moments = objective_mod.natural_moments(obj, z, padded)
    jtj, meat, ee, rr, _ = (np.asarray(a) for a in moments)
    cov, cond, reason, weak = covariance(jtj[ix], meat[ix], float(ee), n_data, method)
    return _Errors(cov, cond, reason, weak, float(rr), method, fallback=fallback)


def _marginal_covariance(
    over: Callable[[np.ndarray], _Errors],
    layout: ParameterLayout,
    z: np.ndarray,
    act: np.ndarray,
    moments: tuple,
    blocks: bool,
) -> tuple[_Errors, np.ndarray]:
    """The covariance the free scalars' errors come from, and the scalars it is over.

    ``over(sel)``: the covariance over the scalars ``sel`` (:func:`_free_covariance`);
    ``act`` the scalars not held on a bound; ``moments`` those at the answer ``z``, block
    moments where ``blocks``.

    A scalar held on a bound may still be uncertain towards the inside. The free
    scalars' estimate is then distributed as a mixture: of the fit with that scalar held
    (the covariance of the free scalars alone, conditional on it) and the fit without
    (their block of the covariance over all, the wider; Andrews 1999, "Estimation when a
    parameter is on a boundary", Econometrica 67(6)). Which one applies depends on how
    firmly the data hold it there: the Gauss-Newton step from the answer with no bounds,
    ``-(J^T J)^-1 J^T e``, moves a held scalar beyond its bound, and where it moves it
    further than :data:`FIRM` of its own standard errors, the data reject an optimum
    inside (one-sided, at 2.5%) and the covariance is conditional on the bound; otherwise
    the scalar counts as free for the covariance, the least favourable case of the
    mixture. Conditioning on every held scalar understates a free scalar that trades off
    against one the data hold loosely: on measured data a lobe whose Fresnel ``f0`` is
    held at 1 states ``ks`` to within 10%, while the fit to the other half of the same
    material, with ``f0`` free, moves along the ``ks f0`` ridge by 10x
    (``benchmarks/split_halves.py``). Over the free scalars only where the covariance
    over more has no inverse.
    """
    if act.all():
        return over(act), act
    every = np.ones_like(act)
    e = over(every)
    if e.cov is None:
        return over(act), act
    grad = np.asarray(moments[2]).sum(axis=0) if blocks else np.asarray(moments[4])
    firm = firmly_held(layout, layout.from_solver(z), act, np.asarray(moments[0]), grad, e.cov)
    if not firm.any():
        return e, every
    inner = over(~firm)
    return (inner, ~firm) if inner.cov is not None else (e, every)


FIRM = 1.959963984540054
"""How far beyond its bound, in its own standard errors, the unbounded Gauss-Newton step
takes a held scalar for the errors to be conditional on it (:func:`_marginal_covariance`):
the normal 97.5% quantile, a one-sided test at 2.5% that its optimum is inside."""


def firmly_held(
    layout: ParameterLayout,
    x: np.ndarray,
    act: np.ndarray,
    jtj: np.ndarray,
    grad: np.ndarray,
    cov: np.ndarray,
) -> np.ndarray:
    """The held scalars (``~act``) that the unbounded Gauss-Newton step from the natural
    answer ``x``, ``-(J^T J)^-1 J^T e`` (``jtj``, ``grad``), takes beyond their bound by
    more than :data:`FIRM` standard errors (``cov`` over every scalar)."""
    d = np.sqrt(np.diag(jtj))
    step = -np.linalg.solve(jtj / np.outer(d, d), grad / d) / d
    lo, hi = layout.bounds_flat()
    x = np.asarray(x, float)
    outward = np.where(np.abs(x - lo) <= np.abs(x - hi), -step, step)
    return ~act & (outward > FIRM * np.sqrt(np.clip(np.diag(cov), 0.0, None)))


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
    synthetic: bool = False,
) -> FitResult:
    """Uncertainties, information criteria, every metric and flags -> :class:`FitResult`
    of a fit under ``m`` (``preps``: the data prepared for every metric; ``padded``:
    ``preps[m.name]`` :meth:`~brdffit.engine.metrics.Prepared.padded`, made here if not given;
    ``errors`` a kind of :data:`CHOICES`, ``synthetic`` whether the data are a model's values).

    The covariance's moments and every metric's loss come from one pass over the data at
    the answer (:meth:`~brdffit.engine.objective.Objective.answer`). The other metrics
    are padded only for their losses, at the end, sharing ``padded``'s geometry: padding
    every metric at the start of a fit held 3 more copies of the data side through the
    descent (SGD at full resolution: 4.3 GB peak, 3.8 GB without them)."""
    layout, model = obj.layout, obj.model
    prep = preps[m.name]
    padded = prep.padded() if padded is None else padded
    z = np.asarray(out.z)
    params = {k: np.asarray(v) for k, v in obj.params(z).items()}
    cov = corr = stderr = dof = None
    cond, reason, weak_names, rss = float("nan"), None, [], float("nan")
    n_data, n_blocks, fallback = 3 * prep.n, 0, None
    method = resolve(errors, synthetic)
    ok = out.status is not Status.NONFINITE
    chunks = block_chunks(prep) if ok and method == "blocks" else None
    # the other metrics as padded as ``padded`` (from prepare_all they are; data padded
    # here are let go: kept, their copies would be held through every later descent)
    sides = {k: padded if k == m.name else p.pad(padded.rows, padded) for k, p in preps.items()}
    moments, losses = objective_mod.answer(obj, z, padded, chunks, sides)
    losses = {k: float(v) for k, v in losses.items()}
    if ok:
        act = ~out.binding

        def over(sel: np.ndarray) -> _Errors:
            return _free_covariance(obj, z, padded, sel, errors, method, chunks, moments, n_data)

        e, sel = _marginal_covariance(over, layout, z, act, moments, chunks is not None)
        cond, reason, method = e.cond, e.reason, e.method
        n_blocks, fallback = e.n_blocks, e.fallback
        rss = max(e.rr, 1e-300)
        labels_sel = [lab for lab, a in zip(layout.labels(), sel, strict=True) if a]
        weak = zip(labels_sel, e.weak, act[sel], strict=True)
        weak_names = [lab for lab, w, a in weak if w and a]
        if e.cov is not None:
            cov = np.full((layout.size, layout.size), np.nan)
            cov[np.ix_(sel, sel)] = e.cov
            cov[~act, :] = cov[:, ~act] = np.nan  # held on a bound: no error of its own
        if e.dof is not None:
            nu = np.full(layout.size, np.nan)
            nu[sel] = e.dof
            nu[~act] = np.nan
            dof = {k: np.asarray(v) for k, v in layout.split(nu).items()}
            dof = {p.name: dof.get(p.name, np.full(np.shape(params[p.name]), np.nan))
                   for p in model.parameters}  # fmt: skip
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
        errors_method=method,
        errors_reason=reason,
        error_blocks=n_blocks,
        error_dof=dof,
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
        warnings=_warnings(at_bound, reason, out.status, cond, weak_names)
        + ((f"errors by sandwich, not blocks: {fallback}",) if fallback else ()),
        not_identified=tuple(weak_names),
        coarse_samples=out.coarse[0],
        coarse_steps=out.coarse[1],
        robust=obj.robust,
        robust_scale=out.robust_scale,
    )


def _warnings(at_bound, reason, status, cond, weak_names) -> tuple[str, ...]:
    out = []
    if at_bound:
        out.append(
            f"parameters at a bound: {', '.join(at_bound)}; the best fit lies on the bound, "
            "their errors are unreliable (NaN where held on it; the other errors allow a "
            "held scalar to move inside unless the data hold it there firmly)"
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
