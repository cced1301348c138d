"""A hand-made sweep folder (no fits): known losses, times and statuses for ranking tests."""

from __future__ import annotations

import json
import math
from pathlib import Path

# material -> model -> (loss, wall_time s, eval ns/sample, converged)
TABLE = {
    "gold-metallic-paint": {"a": (1.0, 0.5, 10.0, True), "b": (2.0, 0.2, 5.0, True)},
    "red-plastic": {"a": (3.0, 0.6, 10.0, True), "b": (1.5, 0.2, 5.0, True)},
    "steel": {"a": (0.5, 0.4, 10.0, True), "b": (0.6, 0.3, 5.0, True)},
    "blue-fabric": {"a": (2.0, 0.5, 10.0, True), "b": (9.0, 0.2, 5.0, False)},
}
N_DATA = 300


def record(material: str, model: str, metric: str, loss, wall, ns, ok) -> dict:
    """The fields a sweep result file carries that the ranking reads."""
    aic = N_DATA * math.log(loss) + 2 * (3 if model == "a" else 7)
    return {
        "material": material,
        "model": model,
        "metric": metric,
        "options": {},
        "loss": loss,
        "losses": {metric: loss},
        "aic": aic,
        "bic": aic + 1.0,
        "n_free": 3 if model == "a" else 7,
        "converged": ok,
        "status": "CONVERGED" if ok else "MAX_STEPS",
        "wall_time": wall,
        "eval_ns_per_sample": ns,
    }


def make_sweep(root: Path, metric: str = "low_e2", table: dict | None = None) -> Path:
    """Write ``sweep.json`` and one result file per entry of ``table`` (:data:`TABLE`)."""
    table = TABLE if table is None else table
    root.mkdir(parents=True, exist_ok=True)
    models = dict.fromkeys(model for row in table.values() for model in row)
    manifest = {
        "materials": {m: {"name": m, "kind": "merl", "path": None, "spec": None} for m in table},
        "models": {model: {} for model in models},
        "metrics": [metric],
        "settings": {
            "stride": [15, 15, 15],
            "cut_deg": 80.0,
            "n_restarts": 0,
            "seed": 0,
            "max_steps": 256,
            "eval_n": 1024,
        },
    }
    (root / "sweep.json").write_text(json.dumps(manifest))
    for mat, row in table.items():
        (root / mat).mkdir(exist_ok=True)
        for model, vals in row.items():
            path = root / mat / f"{model}__{metric}.json"
            path.write_text(json.dumps(record(mat, model, metric, *vals)))
    return root
