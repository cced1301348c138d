"""Which features survive model reduction, per material of a sweep (``sweep --simplify``).

:func:`sweep_reduction` runs :func:`brdffit.simplify` after a sweep task's fit and
returns the record the task's JSON stores under ``"simplify"``
(:meth:`brdffit.selection.reduction.Reduction.summary` plus the path); :func:`has_reduction` tells a
resumed sweep whether a task file already holds one for the criterion asked;
:func:`survival_table` reads a sweep folder and writes, per material, the chosen
variant of each model with its parameter count, its loss against the full model's and
the features kept and removed, then per model how many materials keep each feature.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from brdffit import models
from brdffit.core.result import nan_to_none
from brdffit.errors import SweepError
from brdffit.selection.simplify import simplify
from brdffit.selection.variants import features
from brdffit.util.text_table import render


def sweep_reduction(model, data, metric: str, fitted, settings: Mapping[str, object]) -> dict:
    """The ``"simplify"`` record of one sweep task: :func:`brdffit.simplify` of ``model``
    on ``data`` under ``metric``, started from the task's fit ``fitted``, with the
    sweep's ``settings`` (``simplify``: the criterion; ``cut_deg``, ``seed``,
    ``max_steps``, ``screen``, ``n_restarts``). A fit whose loss is not finite is not
    reduced: the record then says so under ``"skipped"``. JSON-safe (NaN as null)."""
    criterion = str(settings["simplify"])
    if not math.isfinite(fitted.loss):
        return {"criterion": criterion, "skipped": "the full model's fit has no finite loss"}
    r = simplify(
        model, data, metric, criterion=criterion, cut_deg=settings["cut_deg"],
        seed=int(settings["seed"]), full=fitted, max_steps=int(settings["max_steps"]),
    )  # fmt: skip
    out = {**r.summary(), "folds": r.folds, "n_se": r.n_se}
    out["path"] = [dataclasses.asdict(row) for row in r.path]
    return nan_to_none(out)


def has_reduction(path: str | os.PathLike[str], criterion: str) -> bool:
    """True when the task file ``path`` parses, has a loss and a ``"simplify"`` record
    made with ``criterion``."""
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return False
    red = d.get("simplify") if isinstance(d, dict) else None
    return "loss" in d and isinstance(red, dict) and red.get("criterion") == criterion


@dataclass(frozen=True)
class Survival:
    """One reduced sweep task: ``material``, ``family``, ``metric``, ``start`` (the full
    model's label), ``chosen``, ``n_free`` / ``n_free_full``, ``loss_ratio`` (chosen
    over full, in-sample), ``kept`` and ``removed`` (feature names, changes), ``note``
    (why there is no reduction, else empty)."""

    material: str
    family: str
    metric: str
    start: str
    chosen: str
    n_free: int
    n_free_full: int
    loss_ratio: float
    kept: tuple[str, ...]
    removed: tuple[str, ...]
    note: str = ""


def load_survival(sweep_dir: str | os.PathLike[str]) -> list[Survival]:
    """Every task of ``sweep_dir`` whose file holds a ``"simplify"`` record, sorted by
    material, start model and metric. Raises :class:`~brdffit.errors.SweepError` when
    the folder has no ``sweep.json``."""
    root = Path(sweep_dir)
    if not (root / "sweep.json").is_file():
        raise SweepError(f"{root}: not a sweep folder (no sweep.json)")
    out = []
    for p in sorted(root.glob("*/*.json")):
        if p.name.endswith(".error.json"):
            continue
        try:
            d = json.loads(p.read_text())
        except (OSError, ValueError):
            continue  # listed by the report as unreadable (sweep_results.load_sweep)
        red = d.get("simplify") if isinstance(d, dict) else None
        if not isinstance(red, dict):
            continue
        start = red.get("start") or d.get("label") or d.get("model", "?")
        num = red.get("loss_ratio")
        out.append(
            Survival(
                d.get("material", p.parent.name), str(d.get("family", "")), d.get("metric", "?"),
                start, red.get("chosen", start), int(red.get("n_free") or d.get("n_free", 0)),
                int(red.get("n_free_full") or d.get("n_free", 0)),
                math.nan if num is None else float(num), tuple(red.get("kept", ())),
                tuple(red.get("removed", ())), str(red.get("skipped", "")),
            )
        )  # fmt: skip
    return sorted(out, key=lambda s: (s.material, s.start, s.metric))


def survival_table(sweep_dir: str | os.PathLike[str], fmt: str = "markdown") -> str:
    """The features that survive, as text (``fmt``: ``"markdown"`` or ``"text"``).

    Per material (a heading, then a table): start model, metric, chosen variant,
    parameters ``k of full``, loss of the chosen over the full model (in-sample, same
    metric and samples: >= 1), the features kept (:func:`brdffit.selection.variants.features` of
    the chosen variant: ``clearcoat``, ``n_lobes=2``, ``RGB kd``) and the changes that
    removed the others. Then per start model and metric, each feature of the start and
    the share of materials that keep it. An empty string when no task was reduced.
    """
    rows = load_survival(sweep_dir)
    if not rows:
        return ""
    head = ["model", "metric", "chosen", "k", "loss vs full", "kept", "removed"]
    parts = []
    for material in dict.fromkeys(r.material for r in rows):
        mine = [r for r in rows if r.material == material]
        body = [
            [r.start, r.metric, "(not reduced)" if r.note else r.chosen,
             f"{r.n_free} of {r.n_free_full}", f"{r.loss_ratio:.4g}",
             ", ".join(r.kept) or "-", "; ".join(r.removed) or r.note or "-"]
            for r in mine
        ]  # fmt: skip
        family = f" ({mine[0].family})" if mine[0].family else ""
        title = f"### {material}{family}" if fmt == "markdown" else f"{material}{family}"
        parts.append(f"{title}\n\n{render(head, body, fmt)}")
    parts.append(_feature_counts(rows, fmt))
    return "\n".join(parts)


def _feature_counts(rows: list[Survival], fmt: str) -> str:
    """Per start model and metric: each feature of the start, and in how many of the
    reduced materials the chosen variant keeps it."""
    body = []
    for start, metric in dict.fromkeys((r.start, r.metric) for r in rows):
        mine = [r for r in rows if (r.start, r.metric) == (start, metric) and not r.note]
        for feat in features(models.from_spec(start)):
            name = feat.split("=")[0]
            n = sum(any(k.split("=")[0] == name for k in r.kept) for r in mine)
            body.append([start, metric, feat, f"{n} of {len(mine)}"])
    title = "### Features that survive" if fmt == "markdown" else "Features that survive"
    return f"{title}\n\n{render(['model', 'metric', 'feature', 'kept in'], body, fmt)}"
