"""Where a fit starts: the start policy, separate from the solver.

The candidates, in order (every one with its affine parameters solved, see
:func:`linear_start`):

1. the defaults, or the user's ``init``;
2. ``n_restarts`` seeded random draws of the nonlinear parameters near the first
   (``N(0, 1)`` in each parameter's unconstrained space);
3. the ``SCREEN_KEEP`` cheapest of ``screen`` candidates spread over the nonlinear
   parameters' whole ranges (a space-filling screen: a local descent started with a
   lobe far too wide or too narrow can end in a corner minimum; the cost over
   candidates spread across the range finds the right basin for a few dozen model
   evaluations).

:func:`brdffit.fit` descends all of them together (one batched solve) on thinned
samples and finishes the best on all samples.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from brdffit.abstract_model import linear_split
from brdffit.metrics import Prepared
from brdffit.objective import Objective
from brdffit.parameters import ParameterLayout, Params

SCREEN_KEEP = 8
"""Screened candidates kept as starts: the cheapest at the candidate is not always the
one that descends lowest (Low's model with 30% noise: the cheapest ends in a
Fresnel-saturated corner, the second cheapest at the optimum), so several go on."""

RIDGE = 1e-12
"""Tikhonov term of the affine normal equations, relative to their largest diagonal
entry: keeps a basis column the data do not see at zero instead of a division by zero,
and moves the others by about this much relative (float64 rounds at 1e-16)."""


def linear_start(obj: Objective, z: jax.Array, prep: Prepared) -> jax.Array:
    """``z`` with the affine parameters (``Parameter.linear``) solved, clipped into the box.

    Weighted linear least squares of ``f cos`` with the metric's weights; for a log1p
    metric each sample is further weighted by ``1 / (1 + f_data cos)``, the slope of
    ``ln(1 + x)``, so the solve is the linearised log-space fit. The normal equations
    (k x k, k the affine scalars) are solved by Cholesky.
    """
    layout = obj.layout
    names = tuple(p.name for p in layout.free if p.linear and not p.solver_log)
    if not names:
        return z
    f0, basis = linear_split(obj.model, obj.params(z), prep.g, names)
    w = jnp.sqrt(prep.weight) * prep.cos_i
    w = w[:, None] * jnp.ones((1, 3), w.dtype)
    if obj.metric.log1p:
        w = w / (1.0 + jnp.maximum(prep.values * prep.cos_i[:, None], 0.0))
    a = (basis * w[:, :, None]).reshape(-1, basis.shape[-1])
    b = ((prep.values - f0) * w).ravel()
    ata = a.T @ a
    ridge = RIDGE * jnp.max(jnp.diag(ata)) * jnp.eye(ata.shape[0], dtype=ata.dtype)
    x = jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(ata + ridge), True), a.T @ b)
    solved = dict(zip(names, _split(layout, names, x), strict=True))
    out = jnp.concatenate(
        [jnp.ravel(solved[p.name]) if p.name in solved else v for p, v in _pieces(layout, z)]
    )
    lo, hi = layout.solver_bounds()
    out = jnp.clip(out, lo, hi)
    return jnp.where(jnp.all(jnp.isfinite(out)), out, z)


def _pieces(layout: ParameterLayout, z: jax.Array):
    i = 0
    for p in layout.free:
        yield p, z[i : i + p.size]
        i += p.size


def _split(layout: ParameterLayout, names: tuple[str, ...], x: jax.Array):
    i = 0
    for p in layout.free:
        if p.name in names:
            yield x[i : i + p.size].reshape(p.shape)
            i += p.size


@eqx.filter_jit
def screen_costs(obj: Objective, zs: jax.Array, prep: Prepared) -> tuple[jax.Array, jax.Array]:
    """Every row of ``zs`` with its affine parameters solved, and the cost there."""

    def one(z: jax.Array) -> tuple[jax.Array, jax.Array]:
        z = linear_start(obj, z, prep)
        return z, obj.cost(z, prep)

    return jax.vmap(one)(zs)


def _near(layout: ParameterLayout, base: Params, rng: np.random.Generator) -> Params:
    """The nonlinear parameters of ``base`` moved ``N(0, 1)`` in unconstrained space."""
    out = dict(base)
    for p in layout.free:
        if not p.linear:
            u = np.asarray(p.to_unconstrained(jnp.asarray(base[p.name])))
            out[p.name] = p.to_natural(jnp.asarray(u + rng.normal(0.0, 1.0, p.shape)))
    return out


def _spread(layout: ParameterLayout, base: Params, rng: np.random.Generator) -> Params:
    """A candidate anywhere in the nonlinear parameters' ranges (affine ones as ``base``).

    A scalar whose transform saturates is drawn uniform in ``t = sigmoid(u)`` over
    [0.02, 0.98] (log-uniform over the span of a bounded log parameter); others at
    ``N(0, 2)`` in ``u`` around ``base``.
    """
    out = dict(base)
    for p in layout.free:
        if p.linear:
            continue
        if p.saturates:
            t = rng.uniform(0.02, 0.98, p.shape)
            u = np.log(t) - np.log1p(-t)
        else:
            u = np.asarray(p.to_unconstrained(jnp.asarray(base[p.name])))
            u = u + rng.normal(0.0, 2.0, p.shape)
        out[p.name] = p.to_natural(jnp.asarray(u))
    return out


def candidates(
    obj: Objective,
    first: Params,
    prep: Prepared,
    *,
    n_restarts: int,
    screen: int,
    rng: np.random.Generator,
) -> np.ndarray:
    """The start points (S, k) in solver space, affine parameters solved (module docstring)."""
    layout = obj.layout
    near = [first] + [_near(layout, first, rng) for _ in range(n_restarts)]
    zs, _ = screen_costs(obj, _stack(layout, near), prep)
    starts = [np.asarray(zs)]
    if screen and any(not p.linear for p in layout.free):
        spread = [_spread(layout, first, rng) for _ in range(screen)]
        zc, costs = screen_costs(obj, _stack(layout, spread), prep)
        costs = np.where(np.isfinite(costs), np.asarray(costs), np.inf)
        order = np.argsort(costs, kind="stable")[:SCREEN_KEEP]
        starts.append(np.asarray(zc)[order[np.isfinite(costs[order])]])
    return np.concatenate(starts)


def _stack(layout: ParameterLayout, params: list[Params]) -> jax.Array:
    return jnp.stack([layout.solver_vector(p) for p in params])
