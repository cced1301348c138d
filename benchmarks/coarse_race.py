"""The starts' sample count on real data: ``fit(..., coarse=K)`` for several values of K on
NBRDF materials.

For each model given, each metric and each material, a warm fit (the first of a model
and metric includes its compilation) with ``coarse`` at each value of ``--coarse``; one
JSON line per (model, metric, material) with each value's loss, seconds, status and LM
steps of the final descent. By default the materials are the four full-resolution NBRDF
materials of :mod:`benchmarks.full_resolution`; ``--stride`` evaluates them on a
sub-grid instead, and ``--every K`` takes every K-th of the NBRDF folder's materials in
name order. Used to move :data:`brdffit.engine.settings.COARSE` from 25,000 to 8,000,
and :data:`brdffit.engine.batch.COARSE_SHARE` (``benchmarks/results/fit_lm.md``).

    python -m benchmarks.coarse_race walter cook_torrance ... [--coarse 25000 8000]
    python -m benchmarks.coarse_race walter ... --stride 3 3 5 --every 4 --coarse 5058 2000
"""

from __future__ import annotations

import argparse
import json
import pickle
import time

import brdffit
from benchmarks.full_resolution import MATERIALS, METRICS, NBRDF, cached
from benchmarks.published_record import measurements
from brdffit import fit, models


def _materials(args: argparse.Namespace) -> dict:
    """The data sets, by name: the full-resolution pickles, or the materials evaluated on
    ``args.stride`` (pickled once per stride, as the published-record benchmark keeps them)."""
    if args.every is None and args.stride is None:
        return {m: pickle.loads(cached(m).read_bytes()) for m in MATERIALS}
    names = sorted(p.stem for p in NBRDF.glob("*.json"))
    names = names[:: args.every] if args.every else list(MATERIALS)
    stride = tuple(args.stride) if args.stride else (1, 1, 1)
    return {m: measurements(m, stride) for m in names}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("models", nargs="+")
    ap.add_argument("--coarse", type=int, nargs="+", default=[25_000, 8_000])
    ap.add_argument("--stride", type=int, nargs=3, default=None)
    ap.add_argument("--every", type=int, default=None, help="every K-th NBRDF material")
    args = ap.parse_args()
    brdffit.enable_compilation_cache()
    data = _materials(args)
    for name in args.models:
        model = models.get(name)
        for metric in METRICS:
            for material, d in data.items():
                row: dict = {"model": name, "metric": metric, "material": material}
                for k in args.coarse:
                    t = time.perf_counter()
                    r = fit(model, d, metric, coarse=k, throw=False)
                    row[str(k)] = [r.loss, time.perf_counter() - t, r.status.name, r.n_steps]
                print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
