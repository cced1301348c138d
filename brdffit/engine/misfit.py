"""The misfit of a model's values to prepared data: LM's residuals and the exact losses.

The metrics, their weights and transforms are :mod:`brdffit.engine.metrics`'s table;
this module compares ``f_model`` (N, 3) with :class:`~brdffit.engine.metrics.Prepared`
data under them.

Least squares needs ``loss = F(sum r^2)``: for the quadratic metrics ``r`` is the
weighted difference itself. ``log1p_l1`` is an L1 loss, so LM minimises a smooth
pseudo-Huber surrogate ``sum 2 delta^2 (sqrt(1 + (e/delta)^2) - 1)`` with
``delta = 1e-3`` (quadratic below delta, ``2 delta |e|`` above); the reported loss is
always the exact mean absolute difference.
"""

from __future__ import annotations

import functools
import itertools

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array

from brdffit.engine.metrics import L1_DELTA, LOG_FLOOR, METRICS, Prepared


def residuals(f_model: Array, prep: Prepared) -> Array:
    """The flat residual vector LM minimises (``0.5 sum r^2``), length 3N.

    One branch per form of metric (``prep.log1p``, ``prep.l1``), each computing the whole
    residual ``sqrt(w) rho(T(f cos) - T(f_data cos))``: XLA fuses a branch into one pass
    over the samples, where a conditional per switch writes every intermediate array
    out in full (Lambert on the full MERL grid under low_e2, best of 15 warm calls: the
    cost 27.8 ms against 39.6 ms, a linearisation 76.0 ms against 92.9 ms)."""
    form = prep.log1p.astype(jnp.int32) + 2 * prep.l1.astype(jnp.int32)
    return lax.switch(form, _RESIDUALS, f_model, prep)


def _residuals_of(log1p: bool, l1: bool):
    """:func:`residuals` of one form of metric, its switches known while tracing."""

    def residuals(f_model: Array, prep: Prepared) -> Array:
        e = _difference(f_model * prep.cos_i[:, None], prep, log1p)
        return (jnp.sqrt(prep.weight) * (_pseudo_huber(e) if l1 else e)).ravel()

    return residuals


_RESIDUALS = [_residuals_of(log1p, l1) for l1 in (False, True) for log1p in (False, True)]
"""The four forms, indexed by ``log1p + 2 l1``."""


def _log_side(x: Array) -> Array:
    return jnp.log1p(jnp.maximum(x, LOG_FLOOR))


def _pseudo_huber(e: Array) -> Array:
    """``e`` such that ``e^2`` is the pseudo-Huber loss of ``e``, written as
    ``e sqrt(2 / (sqrt(1 + x^2) + 1))`` with ``x = e / L1_DELTA``: smooth at ``e = 0``."""
    x = e / L1_DELTA
    return e * jnp.sqrt(2.0 / (jnp.sqrt(1.0 + x * x) + 1.0))


def _exact(x: Array, prep: Prepared, log1p: bool, l1: bool, root: bool) -> Array:
    """The exact scalar loss of ``x = f_model cos_i`` against ``prep``, its form known
    while tracing (the module table)."""
    return _reduce(_difference(x, prep, log1p), prep, l1, root)


def _difference(x: Array, prep: Prepared, log1p: bool) -> Array:
    """``x`` or ``ln(1 + x)`` minus the data's target: the one place it is written."""
    return (_log_side(x) if log1p else x) - prep.target


def _reduce(e: Array, prep: Prepared, l1: bool, root: bool) -> Array:
    """The loss of the differences ``e`` in ``prep``'s weights: the one place it is written."""
    total = jnp.sum(prep.weight * (jnp.abs(e) if l1 else e * e))
    return jnp.sqrt(total) if root else total


def losses(f_model: Array, cos_i: Array, sides: dict[str, Prepared]) -> dict[str, Array]:
    """Every metric's exact loss of ``f_model``, name -> loss, as :func:`loss` gives it.

    ``sides``: metric name -> the data prepared for it, on the samples whose ``cos_i``
    is given (the same geometry, as :func:`prepare_all` makes it). Each metric's
    transform and form are read from :data:`METRICS` by name while tracing, not from the
    data's switches: ``f cos`` and ``ln(1 + f cos)`` are then computed once for all
    metrics, where a conditional per metric recomputes them inside each branch. Lambert
    on the full MERL grid: the four losses with a conditional each took 0.085 s as their
    own program; this way, inside the Jacobian pass at the answer, they add 0.035 s to
    its 0.071 s. The difference from the data is taken once per transform, against the
    first of its metrics' targets, which are equal (:func:`prepare_all` shares them): the
    losses read memory more than they compute, and each (N, 3) array they skip is 22 MB
    at the full grid (as their own program, 51 -> 43 ms).
    """
    x = f_model * cos_i[:, None]
    diffs: dict[bool, Array] = {}
    out = {}
    for name, prep in sides.items():
        m = METRICS[name]
        if m.log1p not in diffs:
            diffs[m.log1p] = _difference(x, prep, m.log1p)
        out[name] = _reduce(diffs[m.log1p], prep, m.l1, m.root)
    return out


_LOSSES = [
    functools.partial(_exact, log1p=log1p, l1=l1, root=root)
    for root, l1, log1p in itertools.product((False, True), repeat=3)
]
"""The eight forms of :func:`loss`, indexed by ``log1p + 2 l1 + 4 root``."""


def loss(f_model: Array, prep: Prepared) -> Array:
    """The exact scalar loss of the metric ``prep`` was prepared for (the module table):
    one branch per form, chosen by the data's switches, so one program serves every
    metric."""
    form = (
        prep.log1p.astype(jnp.int32)
        + 2 * prep.l1.astype(jnp.int32)
        + 4 * prep.root.astype(jnp.int32)
    )
    return lax.switch(form, _LOSSES, f_model * prep.cos_i[:, None], prep)
