"""Case files: one JSON per case, written atomically; the finished ones read back."""

from __future__ import annotations

import json
import os
from pathlib import Path

from brdffit.core.result import nan_to_none
from brdffit.util.atomic import write_text

from .regimes import REGIMES


def case_path(out: str | os.PathLike[str], model: str, metric: str, regime: str) -> Path:
    """``<out>/<model>__<metric>__<regime>.json``."""
    return Path(out) / f"{model}__{metric}__{regime}.json"


def write_case(path: str | os.PathLike[str], result: dict) -> None:
    """Write one case's JSON atomically (NaN and Inf as null)."""

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(nan_to_none(result), indent=1, allow_nan=False))


def is_finished(path: Path) -> bool:
    """True when ``path`` parses and holds a finished case."""
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return False
    return "applicable" in d and (not d["applicable"] or "recovery" in d)


def load_results(out: str | os.PathLike[str]) -> list[dict]:
    """Every finished case of folder ``out``, sorted by model, metric and regime order."""
    order = {name: i for i, name in enumerate(REGIMES)}
    rows = []
    for p in sorted(Path(out).glob("*__*__*.json")):
        if is_finished(p):
            rows.append(json.loads(p.read_text()))
    return sorted(rows, key=lambda d: (d["model"], d["metric"], order.get(d["regime"], 99)))
