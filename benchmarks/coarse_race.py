"""The starts' sample count on real data: ``fit(..., coarse=K)`` for two values of K on
the full-resolution NBRDF materials of :mod:`benchmarks.full_resolution`.

For each model given, each metric and each material, a warm fit (the first of a model
and metric includes its compilation) with ``coarse`` at each value of ``--coarse``; one
JSON line per (model, metric, material) with each value's loss, seconds, status and LM
steps of the final descent. Used to move :data:`brdffit.engine.settings.COARSE` from
25,000 to 8,000 (``benchmarks/results/fit_lm.md``).

    python -m benchmarks.coarse_race walter cook_torrance ... [--coarse 25000 8000]
"""

from __future__ import annotations

import argparse
import json
import pickle
import time

import brdffit
from benchmarks.full_resolution import MATERIALS, METRICS, cached
from brdffit import fit, models


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("models", nargs="+")
    ap.add_argument("--coarse", type=int, nargs="+", default=[25_000, 8_000])
    args = ap.parse_args()
    brdffit.enable_compilation_cache()
    data = {m: pickle.loads(cached(m).read_bytes()) for m in MATERIALS}
    for name in args.models:
        model = models.get(name)
        for metric in METRICS:
            for material in MATERIALS:
                row: dict = {"model": name, "metric": metric, "material": material}
                for k in args.coarse:
                    t = time.perf_counter()
                    r = fit(model, data[material], metric, coarse=k, throw=False)
                    row[str(k)] = [r.loss, time.perf_counter() - t, r.status.name, r.n_steps]
                print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
