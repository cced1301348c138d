"""Variants of a model one move simpler, and where a parent's optimum starts them.

Used by :func:`brdffit.simplify`: the options one move simpler (:func:`option_moves`) and
the features a model has that a move can remove (:func:`features`), parameter names
across a lobe removed (:func:`renumber`), across an axis merged (:func:`axisless`,
``alpha_x`` -> ``alpha``), and the start rows of a child model from its parent's fitted
rows (:func:`start_rows`).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Collection

import numpy as np

from brdffit import models
from brdffit.abstract_model import AbstractModel
from brdffit.errors import ParameterError
from brdffit.models._restrict import base_of

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


def option_moves(model: AbstractModel):
    """The static options of ``model`` (its base, for a restricted variant) whose change gives
    strictly fewer free scalars: ``(field, new value, child base model)`` for every
    boolean flipped and every lobe count ``n_...`` lowered by one. Options the model
    refuses (a typed :class:`~brdffit.errors.ParameterError`) are skipped."""
    base = base_of(model)
    opts, size = base.options(), scalar_count(base)
    for f in dataclasses.fields(base):
        v = getattr(base, f.name)
        if isinstance(v, bool):
            new = not v
        elif isinstance(v, int) and f.name.startswith("n_") and v > 1:
            new = v - 1
        else:
            continue
        try:
            child = models.get(base.name, **{**opts, f.name: new})
        except ParameterError:
            continue
        if scalar_count(child) < size:
            yield f.name, new, child


def features(model: AbstractModel, frozen: Collection[str] = ()) -> tuple[str, ...]:
    """The features of ``model`` that one move of :func:`brdffit.simplify` can remove, in
    table order: a boolean option that is on (``clearcoat``; ``name=false`` for one
    whose off state is the richer), a lobe count above 1 (``n_lobes=2``), an RGB
    parameter not in ``frozen`` (``RGB kd``)."""
    out = []
    for name, new, _ in option_moves(model):
        if isinstance(new, bool):
            out.append(name if not new else f"{name}=false")
        else:
            out.append(f"{name}={new + 1}")
    out += [f"RGB {p.name}" for p in model.parameters if p.shape == (3,) and p.name not in frozen]
    return tuple(out)
