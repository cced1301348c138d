"""Cost of Disney 2012's optional features: full model vs all features off vs hand-written.

Times the jitted ``core`` (BRDF values of 1e5 direction pairs, geometry precomputed) of
``disney`` with every option on, of ``disney`` with every option off (Burley diffuse + GGX)
and of the hand-written Burley + GGX of ``tests/models/test_disney.py``, in float64 and
float32: the first call (trace + compile) once, then the warm call, best of 5, blocking on
the output before the clock stops.

Run on demand from the repository root: ``python3 benchmarks/disney_features.py [repeats]``
(default 5 repeats; the warm calls of the three functions are interleaved round-robin).

Latest numbers: Intel Xeon, 2 vCPUs (x86-64 container shared with other jobs, load average
about 8 during the runs, so single runs scatter by 2x), CPU backend; jax/jaxlib 0.10.2,
equinox 0.13.8, numpy 2.4.6, Python 3.11.7. ns per sample, warm:

    repeats  dtype    full   minimal  hand-written  full/hand  minimal/hand
    5        float64  39.3   29.1     28.0          1.41       1.04
    5        float32  55.7   38.7     12.7          4.38       3.05   (noise: see 50)
    50       float64  24.8    9.5     11.1          2.24       0.86
    50       float32  14.3    4.6      4.0          3.53       1.14

First calls (trace + compile): full 0.6-1.7 s, minimal and hand-written 0.2-0.7 s. With every
feature off the model costs what the hand-written Burley + GGX costs (56 jaxpr equations
each, ``test_all_features_off_costs_no_more_than_hand_written``); the full model is 2-4x.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from brdffit import models  # noqa: E402
from brdffit.core.geometry import shading_geometry, uniform_hemisphere  # noqa: E402
from tests.models.test_disney import _OFF, minimal_reference  # noqa: E402

N = 100_000
REPEATS = int(sys.argv[1]) if len(sys.argv) > 1 else 5


def best_times(fns: dict, **args: tuple) -> dict[str, tuple[float, float]]:
    """name -> (first call s, best warm call s); warm calls interleaved round-robin."""
    first, best = {}, dict.fromkeys(fns, np.inf)
    for name, fn in fns.items():
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args[name]))
        first[name] = time.perf_counter() - t0
    for _ in range(REPEATS):  # interleaved, so that load on a shared machine hits all alike
        for name, fn in fns.items():
            t0 = time.perf_counter()
            jax.block_until_ready(fn(*args[name]))
            best[name] = min(best[name], time.perf_counter() - t0)
    return {k: (first[k], best[k]) for k in fns}


def main() -> None:
    rng = np.random.default_rng(0)
    wi, wo = uniform_hemisphere(rng, N), uniform_hemisphere(rng, N)
    full, minimal = models.get("disney"), models.get("disney", **_OFF)
    print(f"{jax.devices()[0].platform}, jax {jax.__version__}, {N} samples, best of {REPEATS}")
    print("dtype    full ns  minimal ns  hand ns  full/hand  minimal/hand  (first calls, s)")
    for dtype in (jnp.float64, jnp.float32):
        g = jax.jit(shading_geometry)(jnp.asarray(wi, dtype), jnp.asarray(wo, dtype))
        cast = full.cast(full.defaults(), jnp.dtype(dtype))
        small = {k: v for k, v in cast.items() if k in ("base_color", "specular", "roughness")}
        fns = {
            "full": jax.jit(full.core),
            "minimal": jax.jit(minimal.core),
            "hand": jax.jit(minimal_reference),
        }
        runs = best_times(fns, full=(cast, g), minimal=(small, g), hand=(small, g))
        ns = {k: 1e9 * v[1] / N for k, v in runs.items()}
        first = ", ".join(f"{k} {v[0]:.2f}" for k, v in runs.items())
        print(
            f"{jnp.dtype(dtype).name:<8} {ns['full']:7.2f}  {ns['minimal']:10.2f}  "
            f"{ns['hand']:7.2f}  {ns['full'] / ns['hand']:9.2f}  "
            f"{ns['minimal'] / ns['hand']:12.2f}  ({first})"
        )


if __name__ == "__main__":
    main()
