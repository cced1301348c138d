"""Variants of a model one move simpler, and where a parent's optimum starts them.

Used by :func:`brdffit.simplify`: every variant one move simpler (:func:`moves`: an
option, a lobe, a colour, a neutral value), several moves at once (:func:`joint_move`),
the options one move simpler (:func:`option_moves`) and the features a model has that a
move can remove (:func:`features`), parameter names
across a lobe removed (:func:`renumber`), across an axis merged (:func:`axisless`,
``alpha_x`` -> ``alpha``), and the start rows of a child model from its parent's fitted
rows (:func:`start_rows`).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Collection, Iterator, Sequence

import numpy as np

from brdffit import models
from brdffit.core.abstract_model import AbstractModel
from brdffit.errors import ParameterError
from brdffit.models._restrict import base_of, make_grey, make_neutral, restrict, restrictions

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


def lobe_name(name: str, names: Collection[str]) -> str:
    """``name`` as a model whose parameter names are ``names`` spells it: a model with one
    lobe may name it without the index (walter's ``ks``, where two lobes have ``ks_1`` and
    ``ks_2``), so ``ks_1`` becomes ``ks`` when ``names`` has ``ks`` and no ``ks_1``."""
    hit = _INDEX.match(name)
    if name in names or not hit or hit[2] != "1" or hit[1] not in names:
        return name
    return hit[1]


def start_rows(child: AbstractModel, rows: dict[str, np.ndarray], drop: int | None) -> dict:
    """Start rows of ``child`` from its parent's ``rows`` (``brdffit.simplify``); ``drop``:
    the parent's lobe removed (later lobes move down by one; a lone lobe left may drop its
    index, :func:`lobe_name`)."""
    out, r = {}, next(iter(rows.values())).shape[0]
    names = [p.name for p in child.parameters]
    back = {lobe_name(renumber(k, drop), names): k for k in rows}
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
    parameter not in ``frozen`` (``RGB kd``), a parameter with a neutral value that is
    free (``free specular``: not pinned there, not in ``frozen``)."""
    out = []
    for name, new, _ in option_moves(model):
        if isinstance(new, bool):
            out.append(name if not new else f"{name}=false")
        else:
            out.append(f"{name}={new + 1}")
    free = [p for p in model.parameters if p.name not in frozen]
    out += [f"RGB {p.name}" for p in free if p.shape == (3,)]
    out += [f"free {p.name}" for p in free if p.neutral is not None]
    return tuple(out)


Move = tuple[AbstractModel, dict, str, "int | None"]
"""A variant one move simpler: (child model, its start rows, the change as the path
writes it, the parent's lobe dropped or ``None``)."""
StartCost = Callable[[AbstractModel, dict], float]
"""The all-data cost of a child's start rows (row 0); picks which lobe to drop."""


def moves(
    model: AbstractModel, rows: dict[str, np.ndarray], frozen: Collection[str] = (),
    cost: StartCost | None = None,
) -> Iterator[Move]:  # fmt: skip
    """Every variant one move simpler than ``model`` fitted at ``rows`` (one row per fit):
    each option of :func:`option_moves` that gives fewer free scalars (``clearcoat=false``,
    ``n_lobes=1``; a lobe count lowered tries every lobe as the one dropped and keeps the
    start ``cost`` ranks cheapest, the first when ``cost`` is ``None``), each free RGB
    parameter made grey (``grey kd``) and each free parameter with a neutral value pinned
    there (``neutral specular``). Parameters in ``frozen`` (the user's) are not moved; a
    parent's grey and neutral parameters stay so in its children."""
    size = scalar_count(model)
    for name, new, child_base in option_moves(model):
        drops = range(1, new + 2) if not isinstance(new, bool) else (None,)
        child, start, drop = _option_child(child_base, model, rows, drops, cost)
        if scalar_count(child) < size:
            yield child, start, f"{name}={str(new).lower()}", drop
    for p in model.parameters:
        if p.name in frozen:
            continue
        if p.shape == (3,):
            child = make_grey(model, [p.name])
            yield child, start_rows(child, rows, None), f"grey {p.name}", None
        if p.neutral is not None:
            child = make_neutral(model, [p.name])
            yield child, start_rows(child, rows, None), f"neutral {p.name}", None


def _option_child(child_base, parent, rows, drops, cost) -> tuple[AbstractModel, dict, int | None]:
    """``child_base`` with the ``parent``'s grey and neutral parameters that it still
    has, its start rows and the lobe dropped; with several lobes to drop (``drops``),
    the drop whose all-data start ``cost`` ranks cheapest (a lobe's restrictions move
    with it)."""
    grey, neutral = restrictions(parent)
    has = {p.name for p in child_base.parameters if p.neutral is not None}
    child_names = [p.name for p in child_base.parameters]
    out = []
    for d in drops:
        g, n = ([lobe_name(renumber(x, d), child_names) for x in xs] for xs in (grey, neutral))
        g = [x for x in g if x in rgb_names(child_base)]
        child = restrict(child_base, g, [x for x in n if x in has])
        out.append((child, start_rows(child, rows, d), d))
    if len(out) == 1 or cost is None:
        return out[0]
    costs = np.array([cost(child, start) for child, start, _ in out])
    return out[int(np.argmin(np.where(np.isfinite(costs), costs, np.inf)))]


def joint_move(
    model: AbstractModel, rows: dict[str, np.ndarray], changes: Sequence[str],
    frozen: Collection[str] = (), cost: StartCost | None = None,
) -> tuple[AbstractModel, dict, str] | None:  # fmt: skip
    """The moves ``changes`` (texts of :func:`moves`) applied one after the other from
    ``model`` at ``rows``: (model, start rows, the changes joined by `` + ``), or ``None``
    when fewer than two apply. A change follows its feature: once a lobe is dropped,
    ``grey rho_2`` of the parent is ``grey rho_1`` of the child if lobe 1 went, and is
    skipped if lobe 2 went, as is a change that no longer applies (``grey ks`` once the
    specular weight is gone; ``grey f0`` once ``f0`` is pinned at its neutral value)."""
    used, todo = [], list(changes)
    while todo:
        change = todo.pop(0)
        hit = next((m for m in moves(model, rows, frozen, cost) if m[2] == change), None)
        if hit is None:
            continue
        model, rows, drop = hit[0], hit[1], hit[3]
        used.append(change)
        if drop is not None:  # later changes name lobes by the parent's numbers
            todo = [c for c in (_renumber_change(c, drop) for c in todo) if c]
    return (model, rows, " + ".join(used)) if len(used) > 1 else None


def _renumber_change(change: str, drop: int) -> str:
    """A ``grey``/``neutral`` change of a parent once its lobe ``drop`` is removed: the
    parameter renumbered (:func:`renumber`), ``""`` when it went with the lobe; option
    changes as they are."""
    kind, _, name = change.partition(" ")
    if kind not in ("grey", "neutral") or not name:
        return change
    name = renumber(name, drop)
    return f"{kind} {name}" if name else ""
