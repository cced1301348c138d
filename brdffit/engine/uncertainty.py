"""Uncertainties of a finished descent: the covariance of its free scalars.

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
the blocks' scores and Gram matrices) reach numpy. For ``"blocks"`` without a robust loss
they come from the descent itself: every linearisation of the descent on all samples
takes the normal equations as sums over the blocks and keeps those sums
(:class:`~brdffit.engine.objective.WithBlockSums`), and the ones of its last
linearisation are moved to the answer to first order
(:func:`~brdffit.engine.objective.moved_block_moments`; the descent stops when a step
is below its tolerances: on 18 models x 2 metrics, three NBRDF materials at full
resolution, the standard errors agree with a Jacobian pass at the answer to 3e-4
relative at worst and 7e-7 at the median). Otherwise they are formed on the device by
:meth:`brdffit.engine.objective.Objective.answer`, from one Jacobian pass at the answer
that also gives every metric's loss: the sandwich needs per-sample sums the descent does
not keep.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from brdffit.core.parameters import ParameterLayout
from brdffit.engine import objective as objective_mod
from brdffit.engine.block_errors import BlockChunks, block_errors
from brdffit.engine.metrics import Prepared
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
class Errors:
    """The free scalars' covariance and what came with it (:func:`_free_covariance`,
    :func:`errors_at`).

    ``cov`` None with ``reason``; ``cond`` and ``weak`` from :func:`conditioning`; ``rr``
    the plain residuals' ``r.r``; ``method`` the kind used (``"auto"`` resolved);
    ``n_blocks`` and ``dof`` (per free scalar) for ``"blocks"``, else 0 and None;
    ``fallback`` why ``"auto"`` fell back to ``"sandwich"``, or None; ``scalars``
    (:func:`errors_at`) the scalars the covariance is over: the free ones and those held
    loosely on a bound.
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
    scalars: np.ndarray | None = None


def _free_covariance(
    act: np.ndarray,
    errors: str,
    method: str,
    chunks: BlockChunks | None,
    moments: tuple,
    n_data: int,
    sandwich: Callable[[], tuple],
) -> Errors:
    """Covariance of the scalars ``act`` by ``method`` (``errors`` resolved,
    :func:`resolve`) from the ``moments`` at the answer
    (:meth:`~brdffit.engine.objective.Objective.answer`: block moments where ``chunks``
    are given, else the sandwich's); ``n_data`` the residuals not padding; ``sandwich()``
    the sandwich's moments where ``"auto"`` falls back to it from the blocks."""
    ix = np.ix_(act, act)
    fallback = None
    if chunks is not None:
        n_blocks = chunks.n_blocks
        jtj, rr, scores, grams = (np.asarray(a) for a in moments)
        cond, reason, weak = conditioning(jtj[ix])
        if reason is not None:
            return Errors(None, cond, reason, weak, float(rr), method, n_blocks)
        jtj, grams = jtj[ix], grams[:, act][:, :, act]
        cov, dof, reason = block_errors(jtj, scores[:, act], grams, LEVEL)
        if cov is not None or errors != "auto":
            return Errors(cov, cond, reason, weak, float(rr), method, n_blocks, dof)
        method, fallback = "sandwich", reason
        moments = sandwich()
    jtj, meat, ee, rr, _ = (np.asarray(a) for a in moments)
    cov, cond, reason, weak = covariance(jtj[ix], meat[ix], float(ee), n_data, method)
    return Errors(cov, cond, reason, weak, float(rr), method, fallback=fallback)


def _marginal_covariance(
    over: Callable[[np.ndarray], Errors],
    layout: ParameterLayout,
    z: np.ndarray,
    act: np.ndarray,
    moments: tuple,
    blocks: bool,
) -> tuple[Errors, np.ndarray]:
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
    firm = _firmly_held(layout, layout.from_solver(z), act, np.asarray(moments[0]), grad, e.cov)
    if not firm.any():
        return e, every
    inner = over(~firm)
    return (inner, ~firm) if inner.cov is not None else (e, every)


FIRM = 1.959963984540054
"""How far beyond its bound, in its own standard errors, the unbounded Gauss-Newton step
takes a held scalar for the errors to be conditional on it (:func:`_marginal_covariance`):
the normal 97.5% quantile, a one-sided test at 2.5% that its optimum is inside."""


def _firmly_held(
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


def errors_at(
    obj: Objective,
    z: np.ndarray,
    padded: Prepared,
    binding: np.ndarray,
    errors: str,
    method: str,
    chunks: BlockChunks | None,
    moments: tuple,
    n_data: int,
) -> Errors:
    """The errors at the answer ``z`` over every free scalar of ``obj``'s layout, those
    held on a bound (``binding``) with no error of their own: ``cov`` NaN in their rows
    and columns, ``dof`` NaN there, ``weak`` False there. Which covariance the others'
    errors come from: :func:`_marginal_covariance`; arguments as :func:`_free_covariance`
    takes them, ``method`` the kind ``errors`` resolves to (:func:`resolve`); ``padded``
    the data the ``moments`` were taken on, for the sandwich's moments where ``"auto"``
    falls back to them (one Jacobian pass, made once)."""
    act = ~np.asarray(binding, bool)
    sandwich = functools.cache(lambda: objective_mod.natural_moments(obj, z, padded))

    def over(sel: np.ndarray) -> Errors:
        return _free_covariance(sel, errors, method, chunks, moments, n_data, sandwich)

    e, sel = _marginal_covariance(over, obj.layout, z, act, moments, chunks is not None)
    k = act.size
    weak = np.zeros(k, bool)
    weak[sel] = e.weak
    cov = dof = None
    if e.cov is not None:
        cov = np.full((k, k), np.nan)
        cov[np.ix_(sel, sel)] = e.cov
        cov[~act, :] = cov[:, ~act] = np.nan
    if e.dof is not None:
        dof = np.full(k, np.nan)
        dof[sel] = e.dof
        dof[~act] = np.nan
    return dataclasses.replace(e, cov=cov, dof=dof, weak=weak & act, scalars=sel)
