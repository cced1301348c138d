"""The batched descents of a fit: its starts raced, the best finished, for many problems at once.

:class:`Engine` runs steps 1-3 of :mod:`brdffit.engine.fit` (the start race, the finishing
descent on all samples, the race again under a robust loss) for a stack of problems of
equal shape, every solve batched over them (:func:`brdffit.engine.fit.fit` is a stack of
one). The starts descend on evenly thinned samples when the data are large
(:func:`coarse_size`), and on large data the winner is refined on more of them before
the descent on all (:func:`refine_size`): coarse to fine.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from brdffit.core.result import Status
from brdffit.engine import lm, race, starts
from brdffit.engine import metrics as metrics_mod
from brdffit.engine import objective as objective_mod
from brdffit.engine import robust as robust_mod
from brdffit.engine.assembly import Outcome
from brdffit.engine.block_errors import BlockChunks
from brdffit.engine.objective import Objective
from brdffit.engine.settings import Settings
from brdffit.util.memo import per_object
from brdffit.util.programs import program

COARSE_FLOOR = 2_000
"""Fewest thinned samples the starts descend on: the stress suite (2,000 random samples
per case) recovers every identifiable case from that many."""

COARSE_SHARE = 32
"""Below ``COARSE`` the starts see one sample in ``COARSE_SHARE`` (at least
``COARSE_FLOOR``), so that the start races cost about what the descent on all samples
does: the two races take some 150 tried steps in all, the finishing descent 4 to 8
(walter at 20,234 samples: 149 and 4), and a step's cost is about linear in the samples.
At a quarter (the share before) the races set the fit's time on a strided MERL grid.
On 25 NBRDF materials at stride 3 3 5 (20,234 samples: the starts on 2,000 instead of
5,058), 18 models x 2 metrics, 900 fits (``benchmarks/coarse_race.py``,
``benchmarks/results/fit_lm.md``): all converged both ways; 892 at the same minimum (to
2.5e-7 relative), 6 lower (by up to 5.4%) and 2 higher (SGD on two fabrics under low_e2,
by 2.4e-5 and 1.9e-4): another start won the race, as either way can happen on a
landscape with several minima. The fits took 1.59x less time (most models 1.8-2.1x,
SGD 1.25x)."""

REFINE_RATIO = 4
"""Least ratio of sample counts between consecutive stages for :func:`refine_size` to add
a stage between the starts' thinned samples and all of them: a step there then costs a
quarter of a step on all samples or less (a linearisation's cost is linear in the
samples), so the stage pays for itself when it saves the last descent one step in four
of its own."""

_STATUS = {
    lm.Reason.GTOL: Status.CONVERGED,
    lm.Reason.FTOL: Status.CONVERGED,
    lm.Reason.XTOL: Status.CONVERGED,
    lm.Reason.MAX_STEPS: Status.MAX_STEPS,
    lm.Reason.NONFINITE: Status.NONFINITE,
    lm.Reason.RUNNING: Status.SOLVER_FAILED,
}


@dataclass(frozen=True)
class _Stage:
    """One stage's answer per problem: point, tried steps, reason, binding scalars, the
    index of the winning start, the steps spent on the thinned samples, and the cost and
    block sums the descent on all samples kept (``kept`` None when it kept none,
    :class:`~brdffit.engine.objective.WithBlockSums`)."""

    z: np.ndarray
    steps: np.ndarray
    reason: np.ndarray
    binding: np.ndarray
    pick: np.ndarray
    coarse_steps: np.ndarray
    cost: np.ndarray | None = None
    kept: tuple | None = None


class Engine:
    """Steps 1-3 of :mod:`brdffit.engine.fit` for a stack of problems (leading axis P)."""

    def __init__(self, obj: Objective, s: Settings, others: list[metrics_mod.Prepared]):
        self.obj, self.s, self.tol, self.others = obj, s, s.tolerances, others
        lo, hi = obj.layout.solver_bounds()
        self.lo, self.hi = np.asarray(lo), np.asarray(hi)

    def run(
        self, preps: list, padded: list, first: dict, chunks: BlockChunks | None = None
    ) -> list[Outcome]:
        """Each problem's outcome from its data ``preps`` (the fit's metric) and the same
        :meth:`~brdffit.engine.metrics.Prepared.padded`; ``first`` the first start (natural).
        ``chunks``: one problem's error blocks of ``padded``, for a fit that reports block
        errors: its descent on all samples keeps their sums
        (:class:`~brdffit.engine.objective.WithBlockSums`)."""
        s, obj = self.s, self.obj
        n_problems = len(preps)
        n_coarse = coarse_size(preps[0].n, s.coarse)
        small = [_subset(p, n_coarse) for p in preps]
        osmall = [_subset(o, n_coarse, like=sm) for o, sm in zip(self.others, small, strict=True)]
        thinned, n_small = small[0] is not preps[0], small[0].n
        small = [p.padded() for p in small]
        osmall = [o.padded(geometry=sp) for o, sp in zip(osmall, small, strict=True)]
        near, spread, cube = starts.draws(
            obj.layout, first, n_restarts=s.n_restarts, screen=s.screen,
            rng=np.random.default_rng(s.seed),
        )  # fmt: skip
        zs = np.asarray(self._select(obj, near, spread, cube, small))  # (P, S, k)
        extra = np.zeros(n_problems, int)
        if len(spread):
            cross, extra = self._cross_metric_start(near, spread, cube, small, osmall)
            zs = np.concatenate([zs, cross[:, None, :]], axis=1)
        n_mid = refine_size(preps[0].n, n_small) if thinned else None
        mid = None if n_mid is None else [_subset(p, n_mid).padded() for p in preps]
        problems = _Problems(padded, small, thinned, mid, chunks)
        rows = np.arange(n_problems)
        st = self._stage(obj, zs, problems)
        origin, steps = zs[rows, st.pick], st.steps
        coarse_steps = st.coarse_steps + (extra if thinned else 0)
        scales: list[float | None] = [None] * n_problems
        if s.robust is not None:
            scale = self._robust_scales(st.z, preps)
            scales = [float(v) for v in scale]
            robj = obj.with_robust(s.robust, np.asarray(scale))
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
                    start=obj.params(origin[i]), n_steps=int(steps[i]),
                    n_starts=int(np.all(np.isfinite(zs[i]), axis=1).sum()),
                    coarse=(n_small, int(coarse_steps[i])) if thinned else (0, 0),
                    robust_scale=scales[i],
                    cost=None if st.kept is None else float(st.cost[i]),
                    kept=None if st.kept is None else tuple(a[i] for a in st.kept),
                )
            )  # fmt: skip
        return out

    def _cross_metric_start(
        self, near, spread, cube, small, osmall
    ) -> tuple[np.ndarray, np.ndarray]:
        """Step 4 of :mod:`brdffit.engine.starts`: per problem, the lowest descent of the
        candidates under the other kind of metric (on ``osmall``, its thinned data
        prepared for that metric), affine parameters solved again under the fit's own;
        and the steps spent on it.

        The metric is data (:class:`brdffit.engine.metrics.Prepared`), so this race is the
        fit's own race's compiled program when it has as many starts: the fit's own
        gets this one's winner as an extra start, so one start of NaN is added here
        (it stops before any step, :func:`brdffit.engine.lm.init`, and is never picked)."""
        obj = self.obj
        zs = self._select(obj, near, spread, cube, osmall)
        zs = np.concatenate([zs, np.full_like(zs[:, :1], np.nan)], axis=1)
        d = self._descend(obj, zs, osmall)
        cost = np.asarray(d.cost)
        pick = np.argmin(np.where(np.isfinite(cost), cost, np.inf), axis=1)
        best = np.asarray(d.z)[np.arange(len(pick)), pick]
        if len(small) == 1:
            solved = np.asarray(starts.linear_start_one(self.obj, best[0], small[0]))[None]
        else:
            solved = _linear_many(self.obj, best, _stack(small))
        return np.asarray(solved), np.asarray(d.steps).sum(axis=1)

    @staticmethod
    def _select(obj, near, spread, cube, small):
        """Each problem's starts (same draws, its own affine solves and screen), (P, S, k);
        rows the screen leaves out are NaN (:func:`brdffit.engine.starts.select`)."""
        if len(small) == 1:
            return np.asarray(starts.select_one(obj, near, spread, cube, small[0]))[None]
        return _select_many(obj, near, spread, cube, _stack(small))

    def _stage(self, obj, zs, problems: _Problems) -> _Stage:
        """Descend every start of every problem on the thinned samples; finish the lowest
        of each on all samples, refined first on the intermediate ones where there are
        (their steps count with the thinned ones)."""
        d = self._descend(obj, zs, problems.small)
        cost = np.asarray(d.cost)
        pick = np.argmin(np.where(np.isfinite(cost), cost, np.inf), axis=1)
        rows = np.arange(zs.shape[0])
        best = [np.asarray(a)[rows, pick] for a in (d.z, d.steps, d.reason, d.binding)]
        if not problems.thinned:
            return _Stage(*best, pick, np.zeros(len(rows), int))
        thin_steps = np.asarray(d.steps).sum(axis=1)
        z = best[0]
        if problems.mid is not None:
            m = self._descend(obj, z, problems.mid)
            z, thin_steps = np.asarray(m.z), thin_steps + np.asarray(m.steps)
        f = self._descend(obj, z, problems.full, problems.chunks)
        fin = [np.asarray(a) for a in (f.z, f.steps, f.reason, f.binding)]
        kept = None if problems.chunks is None else tuple(np.asarray(a) for a in f.kept)
        return _Stage(*fin, pick, thin_steps, np.asarray(f.cost), kept)

    def _descend(self, obj, z, preps, chunks: BlockChunks | None = None) -> lm.Descent:
        """Descents from ``z`` ((P, k), or (P, S, k) for many starts) on ``preps`` (one per
        problem), with a leading problem axis; P = 1 runs unstacked. ``chunks``: one
        problem's error blocks, whose sums its descent keeps (``z`` (1, k) only)."""
        z, batch = np.asarray(z), lm.batch_size()
        if z.shape[0] == 1:
            o = obj.with_robust(obj.robust, np.asarray(obj.scale)[0]) if obj.scale.ndim else obj
            if chunks is not None:
                o = objective_mod.WithBlockSums(o, chunks)
            if z.ndim == 3:
                d = race.race_one(o, z[0], preps[0], self.lo, self.hi, self.tol, batch)
            else:
                d = lm.solve_one(o, z[0], preps[0], self.lo, self.hi, self.tol)
            return jax.tree.map(lambda a: np.asarray(a)[None], d)
        return _solve_many(obj, z, _stack(preps), self.lo, self.hi, self.tol, batch)

    def _robust_scales(self, z: np.ndarray, preps) -> np.ndarray:
        """Per problem: ``robust_scale``, or :func:`brdffit.engine.robust.default_scale` of
        the plain residuals at ``z``."""
        if self.s.robust_scale is not None:
            return np.full(z.shape[0], float(self.s.robust_scale))
        out = []
        for i in range(z.shape[0]):
            r = np.asarray(objective_mod.plain_residuals(self.obj, z[i], preps[i]))
            r = r[: 3 * preps[i].n]  # not the padding's
            out.append(robust_mod.default_scale(self.s.robust, r))
        return np.asarray(out)


@program
def _select_many(obj, near, spread, cube, prep):
    return lax.map(lambda p: starts.select(obj, near, spread, cube, p), prep)


@program
def _linear_many(obj, z, prep):
    return lax.map(lambda args: starts.linear_start(obj, *args), (z, prep))


class _Problems:
    """Each problem's prepared data: all samples, the thinned ones of the starts
    (``thinned``: whether those are fewer) and the intermediate ones of the refining
    stage (``mid``, ``None`` without one, :func:`refine_size`), all
    :meth:`~brdffit.engine.metrics.Prepared.padded`; ``chunks`` the error blocks of one
    problem whose descent on all samples keeps their sums (:meth:`Engine.run`)."""

    def __init__(
        self, full: list, small: list, thinned: bool, mid: list | None = None, chunks=None
    ):
        self.full, self.small, self.thinned, self.mid = full, small, thinned, mid
        self.chunks = chunks


@program
def _solve_many(obj, z, prep, lo, hi, tol, batch):
    """:func:`brdffit.engine.lm.solve` over stacked problems (and over starts when ``z`` is 3-d),
    ``batch`` at a time (:func:`brdffit.engine.lm.batch_size`); one robust scale per problem
    when ``obj.scale`` is a vector."""
    per_scale = obj.scale.ndim == 1

    def per_problem(args):
        scale, zz, p = args
        o = obj.with_robust(obj.robust, scale) if per_scale else obj
        if zz.ndim == 2:
            return race.race(o, zz, p, lo, hi, tol, batch)
        return lm.solve(o, zz, p, lo, hi, tol)

    scales = obj.scale if per_scale else jnp.zeros(z.shape[0])
    size = None if batch is None else min(batch, z.shape[0])
    return lax.map(per_problem, (scales, z, prep), batch_size=size)


def _stack(preps: list[metrics_mod.Prepared]) -> metrics_mod.Prepared:
    return jax.tree.map(lambda *a: metrics_mod.to_device(np.stack(a)), *preps)


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


def refine_size(n: int, n_small: int) -> int | None:
    """Samples of the stage between the starts' ``n_small`` and all ``n``; ``None``: none.

    The geometric mean ``sqrt(n_small n)``, so that both steps of the continuation grow
    the data by the same factor, when that factor is at least :data:`REFINE_RATIO` (a
    MERL grid at full resolution, 909,696 samples after the 80-degree cut: 85,308
    between 8,000 and all, a factor 10.7; a stride 3 3 5 grid, 20,234 samples raced on
    2,000: none, 6,361 would be a factor 3.2). Started from the winner on the thinned
    samples, the descent on all samples closes the gap between two optima of the same
    model on different samples.
    On three NBRDF materials at full resolution, 18 models x 2 metrics, the descents on
    all samples took 560 tried steps without this stage and 451 with it (STD on
    blue-metallic-paint under low_e2: 5 -> 3), each of its own steps costing a tenth
    (``benchmarks/results/fit_lm.md``).
    """
    mid = math.isqrt(n_small * n)
    return mid if mid >= REFINE_RATIO * n_small and n >= REFINE_RATIO * mid else None


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
    return per_object(prep, ("thinned", n), lambda: _thin(prep, n, like))


def _thin(prep: metrics_mod.Prepared, n: int, like: metrics_mod.Prepared | None):
    """:func:`_subset`, computed (once per ``prep`` and ``n``: the thinned data and their
    padded copy live as long as the data set's prepared arrays)."""
    idx = np.linspace(0, prep.n - 1, n).round().astype(np.int64)
    if like is None:
        return prep.take(idx)
    keys = ("target", "weight", "values")
    own = {k: metrics_mod.to_device(np.asarray(getattr(prep, k))[idx]) for k in keys}
    return dataclasses.replace(like, **own, log1p=prep.log1p, l1=prep.l1, root=prep.root)
