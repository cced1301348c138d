"""``fit_many`` against one ``fit`` call per material: throughput and equal answers.

Walter/GGX + Lambert, ``--n`` synthetic materials (random albedos, F0 and roughness,
3% log-normal noise) on a MERL sub-grid (``--stride``), fitted with the default
settings under ``--metric``. Both paths are timed warm (each is run once first on the
same data to compile). Prints fits per second, the ratio, and the largest relative
loss difference between the two answers of one material.

Run: python3 benchmarks/fit_many.py [--n 256] [--stride 9 9 9] [--metric low_e2]
     [--keep-freed-memory]

``--keep-freed-memory``: glibc set as the ``brdffit`` command sets it
(:func:`brdffit.keep_freed_memory`: one heap for all threads, so ``fit_many``'s threads
share it); without it the process's defaults.

Latest figures: benchmarks/results/fit_many.md.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

import brdffit
from brdffit import fit, fit_many, models, synthesize
from brdffit.engine.metrics import get_metric


def materials(n: int, stride: tuple[int, int, int], seed: int = 0) -> list:
    rng = np.random.default_rng(seed)
    walter = models.get("walter")
    out = []
    for i in range(n):
        truth = {
            "kd": rng.uniform(0.02, 0.6, 3),
            "f0": rng.uniform(0.02, 0.95, 3),
            "alpha": float(np.exp(rng.uniform(np.log(0.02), np.log(0.8)))),
        }
        out.append(synthesize(walter, truth, stride=stride, noise_mult=0.03, seed=i))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=256)
    ap.add_argument("--stride", type=int, nargs=3, default=(9, 9, 9))
    ap.add_argument("--metric", default="low_e2")
    ap.add_argument("--keep-freed-memory", action="store_true", help="as the command sets glibc")
    args = ap.parse_args()
    kept = args.keep_freed_memory and brdffit.keep_freed_memory()  # before JAX runs anything
    if args.n < 1:
        ap.error("--n: must be at least 1")
    get_metric(args.metric)
    import jax

    brdffit.enable_compilation_cache()
    walter = models.get("walter")
    data = materials(args.n, tuple(args.stride))
    print(
        f"# {platform.processor() or platform.machine()}, {jax.devices()[0]}, "
        f"jax {jax.__version__}; {args.n} materials x {data[0].n} cells, {args.metric}; "
        f"freed memory kept: {bool(kept)}"
    )
    fit(walter, data[0], args.metric, throw=False)  # compile
    t = time.perf_counter()
    one = [fit(walter, d, args.metric, throw=False) for d in data]
    t_one = time.perf_counter() - t
    fit_many(walter, data, args.metric, throw=False)  # compile the batched path (shape P)
    t = time.perf_counter()
    many = fit_many(walter, data, args.metric, throw=False)
    t_many = time.perf_counter() - t
    rel = max(abs(a.loss - b.loss) / abs(b.loss) for a, b in zip(many, one, strict=True))
    conv = sum(r.converged for r in many), sum(r.converged for r in one)
    print(f"sequential fit   {t_one:8.2f} s  {args.n / t_one:8.2f} fits/s  converged {conv[1]}")
    print(f"fit_many         {t_many:8.2f} s  {args.n / t_many:8.2f} fits/s  converged {conv[0]}")
    print(f"ratio {t_one / t_many:.2f}x; largest relative loss difference {rel:.2e}")


if __name__ == "__main__":
    main()
