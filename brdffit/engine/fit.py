"""Fit a model to measurements: starts, one batched bounded LM solve, the result.

:func:`fit` and :func:`fit_many` run the same engine:

1. the candidates of :mod:`brdffit.engine.starts` (the cross-metric start among them) are
   descended by the bounded Levenberg-Marquardt of :mod:`brdffit.engine.lm`, raced by
   successive halving in one compiled call (:func:`brdffit.engine.lm.race`), on evenly
   thinned samples when the data are large (:func:`coarse_size`);
2. the lowest is finished on all samples;
3. with a robust loss, its scale is set from the plain optimum's residuals, and the
   plain optimum and every candidate are descended again under the robust loss (outliers
   can drag the plain optimum into a corner whose robust descent stays there); the
   lowest robust objective is finished on all samples;
4. :mod:`brdffit.engine.uncertainty` turns the answer into a :class:`FitResult`.

:func:`fit_many` stacks problems of equal shape (materials, texels) and batches every
solve over them as well.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.measurements import Measurements
from brdffit.core.result import FitResult, Status
from brdffit.engine import lm, starts
from brdffit.engine import metrics as metrics_mod
from brdffit.engine import objective as objective_mod
from brdffit.engine.objective import Objective, freeze_map, start_params
from brdffit.engine.uncertainty import ERRORS, Outcome, assemble
from brdffit.errors import FitError, ParameterError

Freeze = Mapping[str, object] | Sequence[str] | None

COARSE = 25_000
"""Default largest number of thinned samples the starts descend on. The starts only rank
basins (the stress suite recovers every identifiable case from 2,000 random samples);
evenly thinned MERL data keep every theta_h row (its order is theta_h-major and a
stride below 180 keeps every row: 36 for the full grid's 909,696 cells), so a
near-mirror peak stays sampled. 50,000 (the old fitter's) spent 0.45 s more of a 2.4 s
full-resolution walter fit under ngan, with the same answer."""

COARSE_FLOOR = 2_000
"""Fewest thinned samples the starts descend on: the stress suite (2,000 random samples
per case) recovers every identifiable case from that many."""

COARSE_SHARE = 4
"""Below ``COARSE`` the starts see one sample in ``COARSE_SHARE`` (at least
``COARSE_FLOOR``): some twenty start descents cost a descent on all samples or more, so
on mid-sized data (a strided MERL grid, 5,000 to 100,000 samples) they, not the answer's
descent, set the fit's time. Walter at 20,234 samples, warm: 1.36 s with the starts on
all samples, 0.46 s on a quarter, 0.31 s on 2,000; the same final loss to 4e-16 in all
three (``benchmarks/results/fit_lm.md``)."""

_STATUS = {
    lm.Reason.GTOL: Status.CONVERGED,
    lm.Reason.FTOL: Status.CONVERGED,
    lm.Reason.XTOL: Status.CONVERGED,
    lm.Reason.MAX_STEPS: Status.MAX_STEPS,
    lm.Reason.NONFINITE: Status.NONFINITE,
    lm.Reason.RUNNING: Status.SOLVER_FAILED,
}


def fit(
    model: AbstractModel,
    data: Measurements,
    metric: str = "low_e2",
    *,
    init: Mapping[str, object] | None = None,
    freeze: Freeze = None,
    cut_deg: float | None = 80.0,
    n_restarts: int = 1,
    screen: int = 32,
    seed: int = 0,
    max_steps: int = 512,
    ftol: float = 1e-10,
    xtol: float = 1e-10,
    gtol: float = 1e-10,
    errors: str = "sandwich",
    robust: str | None = None,
    robust_scale: float | None = None,
    coarse: int | None = COARSE,
    throw: bool = True,
) -> FitResult:
    """Fit ``model`` to ``data`` by bounded Levenberg-Marquardt on the residuals of ``metric``.

    Arguments:
    - ``model``: a model from :func:`brdffit.models.get`.
    - ``data``: measurements; only valid samples inside the angle cut are used.
    - ``metric``: ``"ngan"``, ``"low_e1"``, ``"low_e2"`` or ``"log1p_l1"``.
    - ``init``: start values (natural units) for some parameters; others use defaults.
    - ``freeze``: names (frozen at their start value) or name -> value; frozen
      parameters leave the fit and get zero standard error.
    - ``cut_deg``: zenith-angle cut for both directions, degrees (``None``: none).
    - ``n_restarts``: seeded random starts near the first one (:mod:`brdffit.engine.starts`).
    - ``screen``: candidates spread over the nonlinear parameters' ranges; the cheapest
      few become starts. 0 turns the screen off.
    - ``max_steps``: tried LM steps per descent. ``ftol``, ``xtol``, ``gtol``: relative
      stopping tolerances (:mod:`brdffit.engine.lm`).
    - ``errors``: ``"sandwich"``, ``"classic"`` or ``"blocks"`` (model error shared by
      neighbouring cells, for measured data; :mod:`brdffit.engine.uncertainty`).
    - ``robust``: ``None``, ``"huber"`` or ``"cauchy"``: a robust loss on the metric's
      residuals against outliers; ``robust_scale`` (residual units) defaults to the
      tuning constant (1.345 Huber, 2.385 Cauchy) times 1.4826 MAD of the plain
      optimum's residuals. The reported ``loss`` stays the metric's own value.
    - ``coarse``: the starts run on every k-th sample, at most ``coarse`` of them (and
      at most a ``COARSE_SHARE``-th of the samples, but not under ``COARSE_FLOOR``), and
      the best one is then finished on all samples (``None``: starts on all samples).
      Data are thinned only when that at least halves them (:func:`coarse_size`).
    - ``throw``: raise :class:`FitError` (carrying the result) if the fit did not converge.

    Returns a :class:`FitResult`; a non-finite or unfinished fit is never marked converged.
    """
    kwargs = dict(
        init=init, freeze=freeze, cut_deg=cut_deg, n_restarts=n_restarts, screen=screen,
        seed=seed, max_steps=max_steps, ftol=ftol, xtol=xtol, gtol=gtol, errors=errors,
        robust=robust, robust_scale=robust_scale, coarse=coarse, throw=throw,
    )  # fmt: skip
    return fit_many(model, [data], metric, **kwargs)[0]


def fit_many(
    model: AbstractModel,
    datasets: Sequence[Measurements],
    metric: str = "low_e2",
    **kwargs,
) -> list[FitResult]:
    """:func:`fit` of one model to many data sets of equal shape, batched; one result each.

    Takes the keyword arguments of :func:`fit`, applied to every data set (``init``,
    ``freeze``, ``seed``: each problem gets the same start policy, so a result equals
    that of :func:`fit` on its data). Every data set must keep the same number of
    samples after the cut (e.g. texels or materials on one MERL grid); their directions
    may differ. ``throw=True`` raises on the first problem that did not converge. Each
    result's ``wall_time`` is the batch's time up to that result.
    """
    t0 = time.perf_counter()
    unknown = sorted(set(kwargs) - {f.name for f in dataclasses.fields(_Settings)})
    if unknown:
        raise ParameterError(f"fit_many: unknown keyword(s) {unknown}; see brdffit.fit")
    s = _Settings(**kwargs)
    if not datasets:
        raise ParameterError("fit_many: no data set given")
    for d in datasets:
        require_measurements(d)
    m = metrics_mod.get_metric(metric)
    first = start_params(model, s.init)
    obj = Objective.build(model, freeze_map(model, s.freeze, first))
    per = [metrics_mod.prepare_all(d, cut_deg=s.cut_deg) for d in datasets]
    sizes = {p[m.name].n for p in per}
    if len(sizes) > 1:
        names = ", ".join(f"{d.source}: {p[m.name].n}" for d, p in zip(datasets, per, strict=True))
        raise ParameterError(f"fit_many: data sets keep different sample counts ({names})")
    other = starts.OTHER_METRIC[m.log1p]
    padded = [p[m.name].padded() for p in per]
    engine = _Engine(obj, s, [p[other] for p in per])
    outcomes = engine.run([p[m.name] for p in per], padded, first | obj.frozen)
    results = []
    for data, out, mine, q in zip(datasets, outcomes, per, padded, strict=True):
        o = obj if out.robust_scale is None else obj.with_robust(s.robust, out.robust_scale)
        r = assemble(
            o, m, out, mine, padded=q, errors=s.errors, cut=s.cut_deg, source=data.source, t0=t0
        )
        if s.throw and not r.converged:
            raise FitError(f"fit of {model.name} to {data.source}: {r.status.value}", r)
        results.append(r)
    return results


def require_measurements(data: object) -> None:
    """Raise :class:`ParameterError` unless ``data`` is :class:`Measurements`, naming the
    NBRDF reader when ``data`` is the network ``read_nbrdf`` returns."""
    if isinstance(data, Measurements):
        return
    hint = (
        " (an NBRDF network: evaluate it with brdffit.io.nbrdf.read_nbrdf_measurements)"
        if type(data).__name__ == "NBRDF"
        else ""
    )
    raise ParameterError(
        f"fit takes Measurements (from a reader or synthesize); got {type(data).__name__}{hint}"
    )


@dataclass(frozen=True)
class _Settings:
    """The keyword arguments of :func:`fit`, checked."""

    init: Mapping[str, object] | None = None
    freeze: Freeze = None
    cut_deg: float | None = 80.0
    n_restarts: int = 1
    screen: int = 32
    seed: int = 0
    max_steps: int = lm.Tolerances.max_steps
    ftol: float = lm.Tolerances.ftol
    xtol: float = lm.Tolerances.xtol
    gtol: float = lm.Tolerances.gtol
    errors: str = "sandwich"
    robust: str | None = None
    robust_scale: float | None = None
    coarse: int | None = COARSE
    throw: bool = True

    def __post_init__(self) -> None:
        if self.errors not in ERRORS:
            raise ParameterError(f"errors={self.errors!r}: use one of {', '.join(ERRORS)}")
        if self.robust is not None and self.robust not in metrics_mod.ROBUST_TUNING:
            raise ParameterError(f"robust={self.robust!r}: use None, 'huber' or 'cauchy'")
        rs = self.robust_scale
        if rs is not None and not (math.isfinite(rs) and rs > 0):
            raise ParameterError(f"robust_scale={rs!r}: must be a positive number")
        if self.screen < 0 or self.n_restarts < 0:
            raise ParameterError(
                f"screen={self.screen!r}, n_restarts={self.n_restarts!r}: must be >= 0"
            )
        ms = self.max_steps
        if isinstance(ms, bool) or not (isinstance(ms, int | np.integer) and ms >= 1):
            raise ParameterError(f"max_steps={ms!r}: must be an integer >= 1")
        if self.coarse is not None and self.coarse < 100:
            raise ParameterError(f"coarse={self.coarse!r}: use None or at least 100 samples")
        for name in ("ftol", "xtol", "gtol"):
            v = getattr(self, name)
            if not (isinstance(v, float | int) and 0 <= v < 1):
                raise ParameterError(f"{name}={v!r}: use a number in [0, 1)")

    @property
    def tolerances(self) -> lm.Tolerances:
        return lm.Tolerances(int(self.max_steps), self.ftol, self.xtol, self.gtol)


@dataclass(frozen=True)
class _Stage:
    """One stage's answer per problem: point, tried steps, reason, binding scalars, the
    index of the winning start, and the steps spent on the thinned samples."""

    z: np.ndarray
    steps: np.ndarray
    reason: np.ndarray
    binding: np.ndarray
    pick: np.ndarray
    coarse_steps: np.ndarray


class _Engine:
    """Steps 1-3 of the module docstring for a stack of problems (leading axis P)."""

    def __init__(self, obj: Objective, s: _Settings, others: list[metrics_mod.Prepared]):
        self.obj, self.s, self.tol, self.others = obj, s, s.tolerances, others
        lo, hi = obj.layout.solver_bounds()
        self.lo, self.hi = jnp.asarray(lo), jnp.asarray(hi)

    def run(self, preps: list, padded: list, first: dict) -> list[Outcome]:
        """Each problem's outcome from its data ``preps`` (the fit's metric) and the same
        :meth:`~brdffit.engine.metrics.Prepared.padded`; ``first`` the first start (natural)."""
        s, obj = self.s, self.obj
        n_problems = len(preps)
        n_coarse = coarse_size(preps[0].n, s.coarse)
        small = [_subset(p, n_coarse) for p in preps]
        osmall = [_subset(o, n_coarse, like=sm) for o, sm in zip(self.others, small, strict=True)]
        thinned, n_small = small[0] is not preps[0], small[0].n
        small = [p.padded() for p in small]
        osmall = [o.padded(geometry=sp) for o, sp in zip(osmall, small, strict=True)]
        near, spread = starts.draws(
            obj.layout, first, n_restarts=s.n_restarts, screen=s.screen,
            rng=np.random.default_rng(s.seed),
        )  # fmt: skip
        zs = np.asarray(self._select(obj, near, spread, small))  # (P, S, k)
        extra = np.zeros(n_problems, int)
        if len(spread):
            cross, extra = self._cross_metric_start(near, spread, small, osmall)
            zs = np.concatenate([zs, cross[:, None, :]], axis=1)
        problems = _Problems(padded, small, thinned)
        rows = np.arange(n_problems)
        st = self._stage(obj, zs, problems)
        origin, steps = zs[rows, st.pick], st.steps
        coarse_steps = st.coarse_steps + (extra if thinned else 0)
        scales: list[float | None] = [None] * n_problems
        if s.robust is not None:
            scale = self._robust_scales(st.z, preps)
            scales = [float(v) for v in scale]
            robj = obj.with_robust(s.robust, jnp.asarray(scale))
            rzs = np.concatenate([st.z[:, None, :], zs], axis=1)
            plain, st = st, self._stage(robj, rzs, problems)
            origin = np.where((st.pick == 0)[:, None], origin, rzs[rows, st.pick])
            steps, coarse_steps = plain.steps + st.steps, coarse_steps + st.coarse_steps
        out = []
        for i in range(n_problems):
            finite = bool(np.all(np.isfinite(st.z[i])))
            status = _STATUS[lm.Reason(int(st.reason[i]))] if finite else Status.NONFINITE
            out.append(
                Outcome(
                    z=st.z[i], status=status, binding=st.binding[i],
                    start=obj.params(jnp.asarray(origin[i])), n_steps=int(steps[i]),
                    n_starts=zs.shape[1],
                    coarse=(n_small, int(coarse_steps[i])) if thinned else (0, 0),
                    robust_scale=scales[i],
                )
            )  # fmt: skip
        return out

    def _cross_metric_start(self, near, spread, small, osmall) -> tuple[np.ndarray, np.ndarray]:
        """Step 4 of :mod:`brdffit.engine.starts`: per problem, the lowest descent of the
        candidates under the other kind of metric (on ``osmall``, its thinned data
        prepared for that metric), affine parameters solved again under the fit's own;
        and the steps spent on it.

        The metric is data (:class:`brdffit.engine.metrics.Prepared`), so this race is the
        fit's own race's compiled program when it has as many starts: the fit's own
        gets this one's winner as an extra start, so one start of NaN is added here
        (it stops at once, :attr:`brdffit.engine.lm.Reason.NONFINITE`, and is never picked)."""
        obj = self.obj
        zs = self._select(obj, near, spread, osmall)
        zs = jnp.concatenate([zs, jnp.full_like(zs[:, :1], jnp.nan)], axis=1)
        d = self._descend(obj, zs, osmall)
        cost = np.asarray(d.cost)
        pick = np.argmin(np.where(np.isfinite(cost), cost, np.inf), axis=1)
        best = np.asarray(d.z)[np.arange(len(pick)), pick]
        if len(small) == 1:
            solved = starts.linear_start_one(self.obj, jnp.asarray(best[0]), small[0])[None]
        else:
            solved = _linear_many(self.obj, jnp.asarray(best), _stack(small))
        return np.asarray(solved), np.asarray(d.steps).sum(axis=1)

    @staticmethod
    def _select(obj, near, spread, small):
        """Each problem's starts (same draws, its own affine solves), (P, S, k)."""
        near, spread = jnp.asarray(near), jnp.asarray(spread)
        if len(small) == 1:
            return starts.select_one(obj, near, spread, small[0])[None]
        return _select_many(obj, near, spread, _stack(small))

    def _stage(self, obj, zs, problems: _Problems) -> _Stage:
        """Descend every start of every problem on the thinned samples; finish the lowest
        of each on all samples."""
        d = self._descend(obj, zs, problems.small)
        cost = np.asarray(d.cost)
        pick = np.argmin(np.where(np.isfinite(cost), cost, np.inf), axis=1)
        rows = np.arange(zs.shape[0])
        best = [np.asarray(a)[rows, pick] for a in (d.z, d.steps, d.reason, d.binding)]
        if not problems.thinned:
            return _Stage(*best, pick, np.zeros(len(rows), int))
        f = self._descend(obj, best[0], problems.full)
        fin = [np.asarray(a) for a in (f.z, f.steps, f.reason, f.binding)]
        return _Stage(*fin, pick, np.asarray(d.steps).sum(axis=1))

    def _descend(self, obj, z, preps) -> lm.Descent:
        """Descents from ``z`` ((P, k), or (P, S, k) for many starts) on ``preps`` (one per
        problem), with a leading problem axis; P = 1 runs unstacked."""
        z, batch = jnp.asarray(z), lm.batch_size()
        if z.shape[0] == 1:
            o = obj.with_robust(obj.robust, obj.scale[0]) if obj.scale.ndim else obj
            if z.ndim == 3:
                d = lm.race_one(o, z[0], preps[0], self.lo, self.hi, self.tol, batch)
            else:
                d = lm.solve_one(o, z[0], preps[0], self.lo, self.hi, self.tol)
            return jax.tree.map(lambda a: a[None], d)
        return _solve_many(obj, z, _stack(preps), self.lo, self.hi, self.tol, batch)

    def _robust_scales(self, z: np.ndarray, preps) -> np.ndarray:
        """Per problem: ``robust_scale``, or the tuning constant x 1.4826 MAD of the plain
        residuals at ``z``."""
        if self.s.robust_scale is not None:
            return np.full(z.shape[0], float(self.s.robust_scale))
        out = []
        for i in range(z.shape[0]):
            zi = jnp.asarray(z[i])
            r = np.asarray(objective_mod.plain_residuals(self.obj, zi, preps[i]))
            mad = 1.4826 * float(np.median(np.abs(r - np.median(r))))
            spread = mad if mad > 0 else float(np.sqrt(np.mean(r * r)))
            out.append(metrics_mod.ROBUST_TUNING[self.s.robust] * max(spread, 1e-300))
        return np.asarray(out)


@eqx.filter_jit
def _select_many(obj, near, spread, prep):
    return lax.map(lambda p: starts.select(obj, near, spread, p), prep)


@eqx.filter_jit
def _linear_many(obj, z, prep):
    return lax.map(lambda args: starts.linear_start(obj, *args), (z, prep))


class _Problems:
    """Each problem's prepared data: all samples and the thinned ones of the starts
    (``thinned``: whether those are fewer), both :meth:`~brdffit.engine.metrics.Prepared.padded`."""

    def __init__(self, full: list, small: list, thinned: bool):
        self.full, self.small, self.thinned = full, small, thinned


@eqx.filter_jit
def _solve_many(obj, z, prep, lo, hi, tol, batch):
    """:func:`brdffit.engine.lm.solve` over stacked problems (and over starts when ``z`` is 3-d),
    ``batch`` at a time (:func:`brdffit.engine.lm.batch_size`); one robust scale per problem
    when ``obj.scale`` is a vector."""
    per_scale = obj.scale.ndim == 1

    def per_problem(args):
        scale, zz, p = args
        o = obj.with_robust(obj.robust, scale) if per_scale else obj
        if zz.ndim == 2:
            return lm.race(o, zz, p, lo, hi, tol, batch)
        return lm.solve(o, zz, p, lo, hi, tol)

    scales = obj.scale if per_scale else jnp.zeros(z.shape[0])
    size = None if batch is None else min(batch, z.shape[0])
    return lax.map(per_problem, (scales, z, prep), batch_size=size)


def _stack(preps: list[metrics_mod.Prepared]) -> metrics_mod.Prepared:
    return jax.tree.map(lambda *a: jnp.stack(a), *preps)


def coarse_size(n: int, coarse: int | None) -> int | None:
    """How many of ``n`` samples the starts descend on; ``None``: all of them.

    ``min(coarse, max(COARSE_FLOOR, n // COARSE_SHARE))``, and ``None`` when that would
    not halve the data (thinning then saves less than the extra finishing descent costs).
    ``coarse=None`` turns thinning off.
    """
    if coarse is None:
        return None
    k = min(coarse, max(COARSE_FLOOR, n // COARSE_SHARE))
    return k if n > 2 * k else None


def _subset(
    prep: metrics_mod.Prepared, n: int | None, like: metrics_mod.Prepared | None = None
) -> metrics_mod.Prepared:
    """``n`` kept samples evenly spaced (``prep`` itself when ``n`` is ``None``).

    ``like``: the same data thinned already under another metric; its geometry and
    cosines are shared (target, weight and values are the metric's own: a log metric
    leaves out channels a linear one fits, :func:`brdffit.engine.metrics.channels_used`).
    """
    if n is None:
        return prep
    idx = np.linspace(0, prep.n - 1, n).round().astype(np.int64)
    if like is None:
        return prep.take(idx)
    keys = ("target", "weight", "values")
    own = {k: jnp.asarray(np.asarray(getattr(prep, k))[idx]) for k in keys}
    return dataclasses.replace(like, **own, log1p=prep.log1p, l1=prep.l1, root=prep.root)
