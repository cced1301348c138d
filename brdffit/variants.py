"""Variants of a model one move simpler, and where a parent's optimum starts them.

Used by :func:`brdffit.simplify`: parameter names across a lobe removed
(:func:`renumber`), across an axis merged (:func:`axisless`, ``alpha_x`` -> ``alpha``),
and the start rows of a child model from its parent's fitted rows (:func:`start_rows`).
"""

from __future__ import annotations

import re

import numpy as np

from brdffit.abstract_model import AbstractModel

_INDEX = re.compile(r"^(.*)_(\d+)$")
_AXIS = re.compile(r"_?(xy|x|y)(?=_|$)")


def axisless(name: str) -> str:
    """``name`` without its axis letters: ``alpha_x``, ``alpha`` -> ``alpha``; ``mx_1`` ->
    ``m_1``; ``cx_1``, ``cxy_1`` -> ``c_1``."""
    return _AXIS.sub("", name)


def renumber(name: str, drop: int | None) -> str:
    """The child's name of the parent's parameter ``name`` once lobe ``drop`` is removed
    (``rho_3`` -> ``rho_2`` for ``drop`` 1 or 2; the dropped lobe's own names vanish)."""
    hit = _INDEX.match(name)
    if drop is None or not hit or int(hit[2]) < drop:
        return name
    return "" if int(hit[2]) == drop else f"{hit[1]}_{int(hit[2]) - 1}"


def start_rows(child: AbstractModel, rows: dict[str, np.ndarray], drop: int | None) -> dict:
    """Start rows of ``child`` from its parent's ``rows`` (``brdffit.simplify``); ``drop``:
    the parent's lobe removed (later lobes move down by one)."""
    out, r = {}, next(iter(rows.values())).shape[0]
    back = {renumber(k, drop): k for k in rows}
    for p in child.parameters:
        src = back.get(p.name, p.name if drop is None else "")
        if src in rows:
            v = rows[src]
            v = v.mean(axis=-1) if p.shape == () and v.ndim == 2 else v
        else:  # a new parameter: the mean of its per-axis namesakes (alpha_x, alpha_y)
            same = [v for k, v in rows.items() if axisless(k) == axisless(p.name)]
            same = [v for v in same if v.shape[1:] == p.shape]
            if not same:
                v = np.broadcast_to(np.asarray(p.default_array()), (r,) + p.shape)
            elif p.solver_log:
                v = np.exp(np.mean([np.log(np.maximum(s, 1e-300)) for s in same], axis=0))
            else:
                v = np.mean(same, axis=0)
        out[p.name] = np.clip(v, *p.bounds)
    return out


def scalar_count(model: AbstractModel) -> int:
    """Free scalars of ``model``'s table (an RGB parameter counts 3)."""
    return sum(p.size for p in model.parameters)


def rgb_names(model: AbstractModel) -> set[str]:
    """Names of ``model``'s RGB parameters."""
    return {p.name for p in model.parameters if p.shape == (3,)}
