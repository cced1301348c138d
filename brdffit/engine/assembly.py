"""The :class:`~brdffit.core.result.FitResult` of a finished descent: its errors
(:mod:`brdffit.engine.uncertainty`), every metric's loss, information criteria and flags.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from brdffit.core.parameters import ParameterLayout, Params
from brdffit.core.result import FitResult, Status
from brdffit.core.result_terms import AT_BOUND_ATOL, AT_BOUND_RTOL
from brdffit.engine import objective as objective_mod
from brdffit.engine.block_errors import block_chunks
from brdffit.engine.metrics import Metric, Prepared
from brdffit.engine.objective import Objective
from brdffit.engine.uncertainty import errors_at, resolve


@dataclass(frozen=True)
class Outcome:
    """What the engine hands over for one problem.

    Fields: ``z`` the answer (solver space); ``status``; ``binding`` scalars held on a
    bound; ``start`` natural dict of the winning start; ``n_steps`` the finishing
    descents' tried steps; ``n_starts``; ``coarse`` (thinned sample count, 0 if none;
    tried steps over all starts there); ``robust_scale``; ``cost`` ``C(z)`` and ``kept``
    the block sums of the last linearisation when the descent on all samples kept them
    (:class:`~brdffit.engine.objective.WithBlockSums`; None otherwise).
    """

    z: np.ndarray
    status: Status
    binding: np.ndarray
    start: Params
    n_steps: int
    n_starts: int
    coarse: tuple[int, int]
    robust_scale: float | None
    cost: float | None = None
    kept: tuple | None = None


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
    ``errors`` a kind of :data:`~brdffit.engine.uncertainty.CHOICES`, ``synthetic``
    whether the data are a model's values).

    The covariance's moments and every metric's loss come from one pass over the data at
    the answer (:meth:`~brdffit.engine.objective.Objective.answer`); block errors from the
    sums the descent kept (``out.kept``, :func:`~brdffit.engine.objective.moved_block_moments`)
    and then the pass computes the losses only
    (:func:`~brdffit.engine.objective.losses_at`). The other metrics
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
    moments = None
    if chunks is not None and out.kept is not None:
        moments = objective_mod.moved_block_moments(obj, z, out.kept, out.cost)
    if moments is None:
        moments, losses = objective_mod.answer(obj, z, padded, chunks, sides)
    else:
        losses = objective_mod.losses_at(obj, z, padded, sides)
    losses = {k: float(v) for k, v in losses.items()}
    if ok:
        e = errors_at(obj, z, padded, out.binding, errors, method, chunks, moments, n_data)
        cond, reason, method, cov = e.cond, e.reason, e.method, e.cov
        n_blocks, fallback = e.n_blocks, e.fallback
        rss = max(e.rr, 1e-300)
        weak_names = [lab for lab, w in zip(layout.labels(), e.weak, strict=True) if w]
        if e.dof is not None:
            dof = {k: np.asarray(v) for k, v in layout.split(e.dof).items()}
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
    the scalar down. This is the test the near-null rule of
    :func:`~brdffit.engine.uncertainty.covariance` cannot
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
