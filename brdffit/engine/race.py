"""The starts' race: descents of :mod:`brdffit.engine.lm` from many starts on the same data,
cut by successive halving (Jamieson & Talwalkar 2016; Hyperband, Li et al. 2018), so that
only the lowest runs to the end. One compiled call."""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array

from brdffit.engine.lm import Descent, LeastSquares, Reason, Tolerances, init, step
from brdffit.util.programs import program

RUNG_STEPS = 8
"""Tried steps every start of :func:`race` takes before the first cut. From a screened
start with its affine parameters solved, a descent on smooth data stops in 6 to 19 steps
(walter, 20,234 samples: 13, 6, 6, 13, 9, 9, 19, 7, 18, 6), so after 8 most have found
their basin and the cut ranks basins, not starting points. The price, measured on the
stress suite (``benchmarks/results/stress.md``, 364 cases): Brady with 1% outliers and
no robust loss went from 80 to 70% of seeds under both metrics (a first rung of 16 steps:
75%); no other case changed."""

RUNG_GROWTH = 3
"""Successive halving's ``eta``: a rung keeps the cheapest third of the starts and gives
them three times the steps (the value Li et al. 2018 recommend for Hyperband)."""


def rungs(n_starts: int, max_steps: int) -> tuple[tuple[int, int], ...]:
    """Successive halving's schedule for :func:`race`: per rung, (starts still descending,
    tried steps each may have reached by the rung's end).

    ``n_starts`` get ``RUNG_STEPS`` steps; then the cheapest ``1 / RUNG_GROWTH`` of them
    (rounded up) go on with ``RUNG_GROWTH`` times the steps, until one is left or the
    budget reaches ``max_steps``; the last rung's starts descend until they stop.
    """
    out = []
    for keep, budget in _halving(n_starts):
        if budget is None or budget >= max_steps:
            return (*out, (keep, max_steps))
        out.append((keep, budget))
    raise AssertionError("the last rung of _halving has no budget")


def _halving(n_starts: int) -> tuple[tuple[int, int | None], ...]:
    """:func:`rungs` before the step budget: one start left at the end (``None``: until it
    stops). The rungs after the one whose budget reaches ``max_steps`` change nothing (each
    start they keep has stopped), so :func:`race` runs these, with the budgets capped by a
    ``max_steps`` that is an input of the program, not a constant of it."""
    out, keep, budget = [], n_starts, RUNG_STEPS
    while keep > 1:
        out.append((keep, budget))
        keep, budget = -(-keep // RUNG_GROWTH), budget * RUNG_GROWTH
    return (*out, (keep, None))


def race(
    obj: LeastSquares, z0: Array, prep: Any, lo: Array, hi: Array, tol: Tolerances, batch
) -> Descent:
    """Descents from the rows of ``z0`` (S, k) on the same data, raced by successive
    halving (Jamieson & Talwalkar 2016; Hyperband, Li et al. 2018): every start takes
    ``RUNG_STEPS`` steps, the cheapest third go on for three times as many, and so on
    (:func:`rungs`); the last one left descends until it stops. Traceable.

    Only the lowest descent is wanted (its basin), and LM lowers the cost at every
    accepted step, so a start dropped at a rung ends above every start kept there: the
    lowest row of the result is always a finished descent. The others are returned as
    they were left (``reason`` ``RUNNING``; ``steps`` counts what they cost). Starts
    advance ``batch`` at a time (:func:`batch_size`); a dropped one costs nothing on
    the CPU (one after another) and is masked in a vmapped batch.
    """
    schedule = _halving(z0.shape[0])
    keeps = jnp.asarray([k for k, _ in schedule])
    cap = jnp.asarray(tol.max_steps)
    budgets = jnp.asarray([cap if b is None else jnp.minimum(b, cap) for _, b in schedule])
    size = None if batch is None else min(batch, z0.shape[0])

    def advance(s: Descent, go: Array, budget: Array) -> Descent:
        def running(s: Descent) -> Array:
            return go & (s.reason == Reason.RUNNING) & (s.steps < budget)

        return lax.while_loop(running, lambda s: step(obj, s, prep, lo, hi, tol), s)

    def rung(j: Array, states: Descent) -> Descent:
        cost = jnp.where(jnp.isfinite(states.cost), states.cost, jnp.inf)
        rank = jnp.argsort(jnp.argsort(cost, stable=True), stable=True)
        go = rank < keeps[j]
        return lax.map(lambda a: advance(a[0], a[1], budgets[j]), (states, go), batch_size=size)

    states = lax.map(lambda z: init(obj, z, prep, lo, hi, tol), z0, batch_size=size)
    return lax.fori_loop(0, len(schedule), rung, states)


race_one = program(race)
""":func:`race` compiled for one problem."""
