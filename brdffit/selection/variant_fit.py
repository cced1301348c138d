"""Fit one variant of a model on all data and on every fold at once, and score it.

:func:`fit_variant` runs one bounded LM descent per row of the start (row 0: all data;
rows 1..: each fold's training cells, :func:`brdffit.selection.folds.deal_blocks`), all
rows in one jitted map (one compile per variant), each from its row's start with the
affine parameters solved again. It returns a :class:`VariantFit`: the natural parameters
per row, the all-data loss and BIC, and the folds' held-out sums, which
:func:`brdffit.selection.folds.feature_test` compares and :func:`brdffit.simplify` (the
search, :mod:`brdffit.selection.simplify`) ranks variants by. :func:`start_cost` is the
all-data cost of a variant at its start, which picks the cheapest of several starts
(:mod:`brdffit.selection.variants`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jax import lax

from brdffit.core.abstract_model import AbstractModel
from brdffit.engine import lm, metrics, misfit, starts
from brdffit.engine.objective import Objective


@dataclass(frozen=True)
class VariantFit:
    """A fitted variant: model, natural parameters per row (row 0 all data, rows 1.. the
    folds' fits), free scalars, in-sample loss, BIC, held-out sums per fold, the
    criterion's value, and whether every fit stayed finite."""

    model: AbstractModel
    rows: dict[str, np.ndarray]
    n_free: int
    loss: float
    bic: float
    held: np.ndarray  # (folds,) held-out weighted sums
    value: float
    ok: bool


def fit_variant(
    model: AbstractModel,
    rows: dict[str, np.ndarray],
    freeze: dict[str, np.ndarray],
    prep: metrics.Prepared,
    train,
    tol: lm.Tolerances,
    *,
    robust: str | None,
    scale: float,
    criterion: str,
    root: bool,
) -> VariantFit:
    """Fit ``model`` from the starts ``rows`` on every row of ``train`` (1 where a row
    fits a cell), with the parameters ``freeze`` held; ``robust``, ``scale``: the loss of
    the start model's fit. The value is the BIC (``criterion="bic"``) or the held-out
    loss over all folds (its square root when the metric is a ``root`` one)."""
    obj = Objective.build(model, freeze, robust, scale)
    lay = obj.layout
    z0 = lay.solver_rows([{k: v[r] for k, v in rows.items()} for r in range(train.shape[0])])
    lo, hi = (jnp.asarray(b) for b in lay.solver_bounds())
    z, reason, held, rss, loss = _solve_rows(obj, jnp.asarray(z0), prep, train, lo, hi, tol)
    out = [obj.params(zr) for zr in z]
    params = {p.name: np.stack([np.asarray(o[p.name]) for o in out]) for p in model.parameters}
    n, k, rss = 3 * prep.n, lay.size + 1, max(float(rss[0]), 1e-300)
    bic = n * math.log(rss / n) + k * math.log(n)
    held = np.asarray(held[1:])
    total = float(held.sum())
    value = bic if criterion == "bic" else math.sqrt(total) if root else total
    ok = bool(np.all(np.isfinite(np.asarray(z)))) and math.isfinite(value)
    ok = ok and not np.any(np.asarray(reason) == int(lm.Reason.NONFINITE))
    return VariantFit(model, params, lay.size, float(loss[0]), bic, held, value, ok)


def start_cost(model: AbstractModel, rows: dict[str, np.ndarray], prep: metrics.Prepared) -> float:
    """The all-data cost of ``model`` at its start ``rows`` (row 0)."""
    obj = Objective.build(model)
    z = obj.layout.solver_vector({k: v[0] for k, v in rows.items()})
    return float(_cost(obj, jnp.asarray(z), prep))


@eqx.filter_jit
def _cost(obj: Objective, z, prep):
    return obj.cost(z, prep)


@eqx.filter_jit
def _solve_rows(obj: Objective, z0, prep: metrics.Prepared, train, lo, hi, tol):
    """One LM descent per row of ``z0`` on the cells ``train`` marks (one compile per
    variant); per row: answer, stop reason, held-out weighted sum, RSS and loss on all."""

    def one(args):
        z, mask = args
        p = dataclasses.replace(prep, weight=prep.weight * mask[:, None])
        lin = starts.linear_start(obj, z, p)
        z = jnp.where(obj.cost(lin, p) < obj.cost(z, p), lin, z)
        d = lm.solve(obj, z, p, lo, hi, tol)
        f = obj.model.evaluate(obj.params(d.z), prep.g)
        # the metric's weighted sum over the held-out cells, not its root: folds add up
        out = dataclasses.replace(
            prep, weight=prep.weight * (1.0 - mask)[:, None], root=jnp.zeros_like(prep.root)
        )
        held = misfit.loss(f, out)
        r = misfit.residuals(f, prep)
        return d.z, d.reason, held, jnp.sum(r * r), misfit.loss(f, prep)

    return lax.map(one, (z0, train), batch_size=lm.batch_size())
