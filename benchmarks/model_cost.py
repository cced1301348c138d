"""Evaluation cost of every model, ns per sample, float64 and float32 (jit, warm, CPU).

For each registered model with default options (and each row of ``tests/cases.py``
with ``--all``): ``jax.jit(model.eval)`` on 100,000 random direction pairs, first call
(compile) timed apart, then the best of 5 warm calls with ``block_until_ready``.

Run: python3 benchmarks/model_cost.py [--all] [--n 100000] [--markdown]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import brdffit
from brdffit import models
from brdffit.core.geometry import uniform_hemisphere

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def cost(model, params, wi, wo, dtype, repeats: int = 5) -> tuple[float, float]:
    """(compile seconds, best warm ns per sample)."""
    wi, wo = jnp.asarray(wi, dtype), jnp.asarray(wo, dtype)
    p = {k: jnp.asarray(v, dtype) for k, v in params.items()}
    f = jax.jit(model.eval)
    t = time.perf_counter()
    f(p, wi, wo).block_until_ready()
    first = time.perf_counter() - t
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        f(p, wi, wo).block_until_ready()
        best = min(best, time.perf_counter() - t)
    return first, best / wi.shape[0] * 1e9


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--all", action="store_true", help="every row of tests/cases.py")
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--markdown", action="store_true")
    args = ap.parse_args()
    brdffit.enable_compilation_cache()
    rng = np.random.default_rng(0)
    wi, wo = uniform_hemisphere(rng, args.n), uniform_hemisphere(rng, args.n)
    if args.all:
        from tests.cases import CASES

        rows = [(c.id, *c.build()) for c in CASES]
    else:
        rows = [(n, models.get(n), models.get(n).defaults()) for n in models.available()]
    print(f"# jax {jax.__version__} on {jax.devices()[0]}, n = {args.n}")
    head = ("model", "params", "ns/sample f64", "ns/sample f32", "compile f64 (s)")
    if args.markdown:
        print("| " + " | ".join(head) + " |\n|" + "---|" * len(head))
    else:
        print(f"{head[0]:<56} {head[1]:>6} {head[2]:>14} {head[3]:>14} {head[4]:>16}")
    for name, model, params in rows:
        c64, t64 = cost(model, params, wi, wo, jnp.float64)
        _, t32 = cost(model, params, wi, wo, jnp.float32)
        k = sum(p.size for p in model.parameters)
        if args.markdown:
            print(f"| {name} | {k} | {t64:.1f} | {t32:.1f} | {c64:.2f} |")
        else:
            print(f"{name:<56} {k:>6} {t64:>14.1f} {t32:>14.1f} {c64:>16.2f}")


if __name__ == "__main__":
    main()
