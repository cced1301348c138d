"""Time reading a MERL file and evaluating an NBRDF on the full MERL grid (run on demand).

    python3 benchmarks/read_merl.py [--nbrdf PATH_STEM]

1. ``read_merl`` of a full synthetic 35 MB file: the first call in the process (cold:
   it also builds the cached grid geometry, the same for every file) and the best of 5
   warm calls, against a plain ``np.fromfile`` of the same bytes; ``write_merl`` too.
2. NBRDF on the full MERL grid (1,458,000 cells): ``to_measurements("merl")`` (numpy,
   separable first layer), the generic ``eval_halfdiff`` path, and a jitted JAX float64
   forward pass of the same network for comparison. Uses the published alum-bronze
   network when ``../shared/data/merl_nbrdf`` is there, a random 6-21-21-3 one otherwise.

Latest numbers (2026-11-22): Intel Xeon (x86_64), 2 CPUs shared with other jobs at a
load average of 8-10, so every number is inflated about 2-4x and noisy; Python 3.11.7,
numpy 2.4.6 (OpenBLAS 0.3.31), jax 0.10.2, h5py 3.16.0. Two runs, and in brackets an
earlier one at a lighter moment:

    read_merl, cold (grid geometry built)    0.60 / 0.76 s
    read_merl, warm best of 5                0.105 / 0.161 s  (0.041 s at a lighter moment)
    np.fromfile, warm best of 5              0.022 / 0.052 s  (0.014 s)
    ratio read_merl / np.fromfile            4.7x / 3.1x      (2.9x)
    write_merl, best of 3                    0.46 / 0.56 s
    NBRDF to_measurements("merl"), best of 3 1.03 / 1.36 s    (0.78 s)
    NBRDF eval_halfdiff (generic), best of 3 1.31 / 1.29 s    (0.88 s)
    JAX jit float64 forward, cold / warm     2.67 / 2.44 s and 2.59 / 1.87 s

numpy beats JAX because the blocks of 2,048 rows keep each small matrix product on one
OpenBLAS thread; blocks of >= 4,096 rows turn on OpenBLAS threading, which on these two
busy cores was 3-10x slower (1.5-6 s for the forward pass alone). Before the grid
geometry used a separable closed form, the cold read took 2.1-2.3 s under the same load.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from brdffit.io.keras_file import DenseLayer  # noqa: E402
from brdffit.io.merl import read_merl, write_merl  # noqa: E402
from brdffit.io.merl_grid import MERL_N_CELLS, merl_grid  # noqa: E402
from brdffit.io.nbrdf import NBRDF, read_nbrdf  # noqa: E402

DEFAULT_NBRDF = ROOT.parent / "shared" / "data" / "merl_nbrdf" / "alum-bronze"


def best_of(fn: Callable[[], object], repeats: int) -> float:
    """Smallest wall time of ``repeats`` calls, seconds."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def once(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def bench_read(folder: Path) -> None:
    rng = np.random.default_rng(0)
    raw = rng.lognormal(2.0, 2.0, 3 * MERL_N_CELLS)
    raw[rng.random(3 * MERL_N_CELLS) < 0.01] = -1.0
    path = folder / "synthetic.binary"
    with open(path, "wb") as f:
        f.write(np.array([90, 90, 180], "<i4").tobytes())
        raw.astype("<f8").tofile(f)
    print(f"file: {path.stat().st_size:,} bytes")

    cold = once(lambda: read_merl(path))
    warm = best_of(lambda: read_merl(path), 5)
    base = best_of(lambda: np.fromfile(path, dtype="<f8", offset=12), 5)
    data = read_merl(path)
    write = best_of(lambda: write_merl(folder / "out.binary", data), 3)
    print(f"read_merl    cold {cold:.3f} s   warm (best of 5) {warm:.4f} s")
    print(
        f"np.fromfile  warm (best of 5) {base:.4f} s   ratio read_merl/fromfile {warm / base:.1f}x"
    )
    print(f"write_merl   best of 3 {write:.3f} s")


def random_network(seed: int = 0) -> NBRDF:
    rng = np.random.default_rng(seed)
    sizes, acts = (6, 21, 21, 3), ("relu", "relu", "linear")
    layers = tuple(
        DenseLayer(
            f"dense_{i + 1}",
            rng.normal(0, 0.5, (a, b)).astype(np.float32),
            rng.normal(0, 0.1, b).astype(np.float32),
            act,
        )
        for i, (a, b, act) in enumerate(zip(sizes[:-1], sizes[1:], acts, strict=True))
    )
    return NBRDF(name="random", source="random weights", layers=layers, output="exp(x) - 1")


def jax_forward(net: NBRDF) -> Callable[[np.ndarray, np.ndarray, np.ndarray], object]:
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    params = [(jnp.asarray(lay.kernel, float), jnp.asarray(lay.bias, float)) for lay in net.layers]

    @jax.jit
    def f(th, td, pd, params):
        sd = jnp.sin(td)
        h = jnp.stack(
            [jnp.sin(th), jnp.zeros_like(th), jnp.cos(th), sd * jnp.cos(pd), sd * jnp.sin(pd),
             jnp.cos(td)],
            axis=1,
        )  # fmt: skip
        for i, (k, b) in enumerate(params):
            h = h @ k + b
            if i < len(params) - 1:
                h = jnp.maximum(h, 0.0)
        return jnp.maximum(jnp.expm1(h), 0.0)

    return lambda th, td, pd: f(th, td, pd, params).block_until_ready()


def bench_nbrdf(stem: Path) -> None:
    net = read_nbrdf(stem) if stem.with_suffix(".h5").exists() else random_network()
    print(f"network: {net.name} ({net.source})")
    g = merl_grid()
    cold = once(lambda: net.to_measurements("merl"))
    warm = best_of(lambda: net.to_measurements("merl"), 3)
    generic = best_of(lambda: net.eval_halfdiff(g.theta_h, g.theta_d, g.phi_d), 3)
    print(f"NBRDF to_measurements('merl')  cold {cold:.3f} s   best of 3 {warm:.3f} s")
    print(f"NBRDF eval_halfdiff (generic)  best of 3 {generic:.3f} s")
    try:
        f = jax_forward(net)
    except ImportError:
        return
    jcold = once(lambda: f(g.theta_h, g.theta_d, g.phi_d))
    jwarm = best_of(lambda: f(g.theta_h, g.theta_d, g.phi_d), 3)
    print(f"JAX jit float64 forward        cold {jcold:.3f} s   best of 3 {jwarm:.3f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nbrdf", type=Path, default=DEFAULT_NBRDF, help="NBRDF stem")
    args = parser.parse_args()
    import jax

    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"load {os.getloadavg()[0]:.1f}; Python {platform.python_version()}, "
        f"numpy {np.__version__}, jax {jax.__version__}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        bench_read(Path(tmp))
    bench_nbrdf(args.nbrdf)


if __name__ == "__main__":
    main()
