"""Default ``brdffit.fit`` against scipy's trf on a full-resolution MERL-format material.

The data: Walter/GGX + Lambert (``TRUTH``; ``--model`` any walter spec whose numpy
form below applies: GGX, uncorrelated exact Smith, isotropic, with or without the
specular weight ``ks``) on the full MERL grid with 3% log-normal noise (909,696 cells
under the 80-degree cut, x 3 channels). For each metric
(``low_e2``, ``ngan``) in one process:

- ``brdffit``: ``fit(model, data, metric)`` with its defaults (starts, screen, coarse
  stage, covariance), first call (compile included) and warm (best of ``--repeats``);
- ``scipy 2-point``: ``least_squares(method="trf", x_scale="jac")`` on a plain numpy
  version of the same residual, finite-difference Jacobian;
- ``scipy jax-jac``: the same, given the exact Jacobian of brdffit's JAX residual
  (jitted, forward mode) in natural units;
- ``floor``: one residual + Jacobian evaluation and one k x k Cholesky solve at full
  resolution, the least one LM iteration can cost; ``per step``: brdffit's own solver
  (:func:`brdffit.engine.lm.solve_one`) run for exactly 6 steps from the same start at full
  resolution (tolerances 0), its time over the 7 linearisations it makes at most;
- ``--disney``: the warm default fit of Disney's model (default options) on a
  full-resolution material made from it (no scipy peer: there is no numpy Disney).

Both scipy runs start from the model's defaults with the albedos solved by linear least
squares (one start); brdffit runs its own start policy. Losses are compared as the
numpy residual's sum of squares at each answer. Ratios are scipy time / brdffit warm.

Run: python3 benchmarks/fit_lm.py [--stride 1 1 1] [--repeats 2] [--metrics low_e2 ngan]
     [--model "walter[specular_weight=false]"] [--truth fit_lm|issue42]
     [--keep-freed-memory]

``--keep-freed-memory``: glibc set as the ``brdffit`` command sets it
(:func:`brdffit.keep_freed_memory`), for both brdffit and scipy; without it the
process's defaults (a script's, a notebook's).

"first" is the process's first fit: with the persistent compilation cache warm (run the
command twice; the second run's figure), that is a fresh process's first call.
     python3 benchmarks/fit_lm.py --disney

Latest figures: benchmarks/results/fit_lm.md (this project's 2-core box, CPU).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import numpy as np

import brdffit
from brdffit import fit, models, synthesize
from brdffit.core.parameters import ParameterLayout
from brdffit.engine.metrics import get_metric, keep_mask, prepare
from brdffit.engine.misfit import residuals as jax_residuals
from brdffit.io.merl_grid import merl_subgrid

TRUTH = {"kd": [0.12, 0.30, 0.55], "ks": [0.8, 0.8, 0.8], "f0": [0.9, 0.6, 0.3], "alpha": 0.12}
TRUTHS = {
    "fit_lm": TRUTH,
    # issue 42's case: GGX + Lambert without a separate ks (--model "walter[specular_weight=false]")
    "issue42": {"kd": [0.2, 0.1, 0.05], "f0": [0.6, 0.5, 0.4], "alpha": 0.08},
}


class Layout:
    """The model's free parameters in table order, as one flat natural vector."""

    def __init__(self, model):
        self.table = model.parameters
        self.names = [p.name for p in self.table]
        self.sizes = [p.size for p in self.table]
        self.lo, self.hi = ParameterLayout.build(self.table).bounds_flat()
        self.defaults = self.pack(model.defaults())

    def unpack(self, x) -> dict:
        out, i = {}, 0
        for p in self.table:
            out[p.name] = x[i] if p.shape == () else x[i : i + p.size]
            i += p.size
        return out

    def pack(self, params) -> np.ndarray:
        return np.concatenate([np.ravel(np.asarray(params[n], float)) for n in self.names])

    def index(self, name: str) -> int:
        return sum(self.sizes[: self.names.index(name)])


def geometry(data, keep):
    """Per-sample quantities of GGX + Lambert that depend on the directions only."""
    wi, wo = data.wi[keep], data.wo[keep]
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    ci, co, ch = wi[:, 2], wo[:, 2], h[:, 2]
    cd = np.clip(np.sum(wi * h, axis=1), 0, 1)
    return {
        "ci": ci,
        "co": co,
        "ch": ch,
        "s5": (1 - cd) ** 5,
        "sin2h": h[:, 0] ** 2 + h[:, 1] ** 2,
        "t2i": (1 - ci**2) / ci**2,
        "t2o": (1 - co**2) / co**2,
    }


def brdf(p, g):
    """GGX + Lambert (Walter 2007, uncorrelated exact Smith, Schlick, optional ``ks``).

    ``p``: dict of natural values (numpy); returns (N, 3).
    """
    kd, f0, a = p["kd"], p["f0"], p["alpha"]
    d = 1.0 / (np.pi * a * a * (g["sin2h"] / (a * a) + g["ch"] ** 2) ** 2)
    li = 0.5 * (a * a * g["t2i"]) / (np.sqrt(1 + a * a * g["t2i"]) + 1)
    lo = 0.5 * (a * a * g["t2o"]) / (np.sqrt(1 + a * a * g["t2o"]) + 1)
    gg = 1.0 / ((1 + li) * (1 + lo))
    f = f0[None, :] * (1 - g["s5"])[:, None] + g["s5"][:, None]
    if "ks" in p:
        f = p["ks"][None, :] * f
    return f * (d * gg / (4 * g["ci"] * g["co"]))[:, None] + kd[None, :] / np.pi


def numpy_residual(layout, metric, data, keep, weight):
    """The metric's residual vector in numpy, geometry computed once."""
    g = geometry(data, keep)
    ci = g["ci"][:, None]
    root_w = np.sqrt(weight)  # (N, 3): the metric's weight per sample and channel
    fd = data.values[keep] * ci
    target = np.log1p(np.maximum(fd, -0.999)) if metric.log1p else fd

    def residual(x):
        fm = brdf(layout.unpack(x), g) * ci
        side = np.log1p(np.maximum(fm, -0.999)) if metric.log1p else fm
        return (root_w * (side - target)).ravel()

    return residual, g


def linear_start(layout, metric, data, keep, weight, g):
    """kd and the specular scale (``ks``, else ``f0``) by weighted linear least squares.

    The other parameters stay at the model's defaults (alpha = 0.2).
    """
    x = layout.defaults.copy()
    scale = "ks" if "ks" in layout.names else "f0"
    ik, js = layout.index("kd"), layout.index(scale)
    zero = layout.unpack(x.copy())
    zero["kd"], zero[scale] = np.zeros(3), np.zeros(3)
    one = dict(zero, **{scale: np.ones(3)})
    f_zero = brdf(zero, g)
    f_one = brdf(one, g) - f_zero
    ci = g["ci"]
    w = np.sqrt(weight) * ci[:, None]
    if metric.log1p:
        w = w / (1 + np.maximum(data.values[keep] * ci[:, None], 0))
    for c in range(3):
        a = np.stack([np.full(len(ci), 1 / np.pi), f_one[:, c]], axis=1) * w[:, c : c + 1]
        b = (data.values[keep][:, c] - f_zero[:, c]) * w[:, c]
        sol = np.linalg.solve(a.T @ a, a.T @ b)
        x[ik + c], x[js + c] = sol
    return np.clip(x, layout.lo, layout.hi)


def jax_peer(layout, model, prep):
    """Jitted residual and exact forward-mode Jacobian in natural units."""
    import jax
    import jax.numpy as jnp

    def res(x):
        p = layout.unpack(x)
        return jax_residuals(model.evaluate(p, prep.g), prep)

    f, j = jax.jit(res), jax.jit(jax.jacfwd(res))
    return (lambda x: np.asarray(f(jnp.asarray(x)))), (lambda x: np.asarray(j(jnp.asarray(x))))


def floor(layout, model, prep, x0, repeats):
    """Seconds of one residual + Jacobian pass and one k x k Cholesky solve, warm."""
    import jax
    import jax.numpy as jnp

    def res(x):
        p = layout.unpack(x)
        return jax_residuals(model.evaluate(p, prep.g), prep)

    def one(x):
        r, jac = res(x), jax.jacfwd(res)(x)
        h = jac.T @ jac + 1e-3 * jnp.eye(x.size)
        return jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(h), True), jac.T @ r)

    f = jax.jit(one)
    x = jnp.asarray(x0)
    f(x).block_until_ready()
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        f(x).block_until_ready()
        best = min(best, time.perf_counter() - t)
    return best


def per_step(layout, model, prep, x0, repeats, steps: int = 6) -> float:
    """Seconds per linearisation of brdffit's LM, ``steps`` tried steps from ``x0``."""
    import jax.numpy as jnp

    from brdffit.engine import lm
    from brdffit.engine.objective import Objective

    obj = Objective.build(model)
    z0 = obj.layout.solver_vector(layout.unpack(x0))
    lo, hi = (jnp.asarray(a) for a in obj.layout.solver_bounds())
    tol = lm.Tolerances(max_steps=steps, ftol=0.0, xtol=0.0, gtol=0.0)
    lm.solve_one(obj, z0, prep, lo, hi, tol).z.block_until_ready()
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        lm.solve_one(obj, z0, prep, lo, hi, tol).z.block_until_ready()
        best = min(best, time.perf_counter() - t)
    return best / (steps + 1)


def disney(repeats: int) -> None:
    """Warm default fit of Disney (default options) at full resolution, both metrics."""
    model = models.get("disney")
    truth = {**model.defaults(), "base_color": np.array([0.7, 0.4, 0.2]), "roughness": 0.3}
    data = synthesize(model, truth, noise_mult=0.03, seed=1)
    for name in ("low_e2", "ngan"):
        fit(model, data, name, throw=False)
        best, r = np.inf, None
        for _ in range(repeats):
            t = time.perf_counter()
            r = fit(model, data, name, throw=False)
            best = min(best, time.perf_counter() - t)
        print(
            f"disney {name:7s} warm {best:7.2f} s  steps {r.n_steps} (+{r.coarse_steps} "
            f"coarse)  loss {r.loss:.10g}  ({r.status.name})",
            flush=True,
        )


def run_metric(name, model, data, repeats):
    from scipy.optimize import least_squares

    metric = get_metric(name)
    keep = np.flatnonzero(keep_mask(data, 80.0))
    prep = prepare(data, metric, cut_deg=80.0)
    weight = np.asarray(prep.weight)
    layout = Layout(model)
    res, g = numpy_residual(layout, metric, data, keep, weight)
    x0 = linear_start(layout, metric, data, keep, weight, g)

    t = time.perf_counter()
    first = fit(model, data, name, throw=False)
    t_first = time.perf_counter() - t
    warm = []
    for _ in range(repeats):
        t = time.perf_counter()
        ours = fit(model, data, name, throw=False)
        warm.append(time.perf_counter() - t)
    t_ours = min(warm)
    loss_ours = float(np.sum(res(layout.pack(ours.params)) ** 2))
    print(
        f"{name:7s} brdffit   first {t_first:7.2f} s  warm {t_ours:7.2f} s  "
        f"steps {ours.n_steps:3d} (+{ours.coarse_steps} coarse)  loss {loss_ours:.12g}  "
        f"({first.status.name})",
        flush=True,
    )
    tol = {"ftol": 1e-10, "xtol": 1e-10, "gtol": 1e-10}
    t = time.perf_counter()
    sp = least_squares(res, x0, bounds=(layout.lo, layout.hi), method="trf", x_scale="jac", **tol)
    t_sp = time.perf_counter() - t
    loss_sp = float(np.sum(res(sp.x) ** 2))
    print(
        f"{name:7s} scipy 2-point     {t_sp:7.2f} s  nfev {sp.nfev:3d}  loss {loss_sp:.12g}  "
        f"ratio {t_sp / t_ours:5.2f}x (first call {t_sp / t_first:5.2f}x)  "
        f"loss rel. diff {(loss_ours - loss_sp) / loss_sp:+.2e}",
        flush=True,
    )
    f_jax, j_jax = jax_peer(layout, model, prep)
    f_jax(x0), j_jax(x0)  # compile outside the clock
    t = time.perf_counter()
    box = (layout.lo, layout.hi)
    sj = least_squares(f_jax, x0, jac=j_jax, bounds=box, method="trf", x_scale="jac", **tol)
    t_sj = time.perf_counter() - t
    loss_sj = float(np.sum(res(sj.x) ** 2))
    print(
        f"{name:7s} scipy jax-jac     {t_sj:7.2f} s  nfev {sj.nfev:3d}  loss {loss_sj:.12g}  "
        f"ratio {t_sj / t_ours:5.2f}x  loss rel. diff {(loss_ours - loss_sj) / loss_sj:+.2e}",
        flush=True,
    )
    t_floor = floor(layout, model, prep, x0, repeats + 1)
    t_step = per_step(layout, model, prep, x0, repeats + 1)
    print(
        f"{name:7s} floor (r + J + solve, full grid) {t_floor:6.3f} s; brdffit per step "
        f"{t_step:6.3f} s ({t_step / t_floor:4.2f}x the floor)",
        flush=True,
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--stride", type=int, nargs=3, default=(1, 1, 1))
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--metrics", nargs="+", default=["low_e2", "ngan"])
    ap.add_argument("--disney", action="store_true", help="time Disney's default fit instead")
    ap.add_argument("--model", default="walter", help="a walter spec (GGX, isotropic)")
    ap.add_argument("--truth", choices=sorted(TRUTHS), default="fit_lm", help="the material")
    ap.add_argument("--keep-freed-memory", action="store_true", help="as the command sets glibc")
    args = ap.parse_args()
    kept = args.keep_freed_memory and brdffit.keep_freed_memory()  # before JAX runs anything
    import jax
    import scipy

    brdffit.enable_compilation_cache()
    for name in args.metrics:
        get_metric(name)  # a bad name exits here with the metric's error
    print(
        f"# {platform.processor() or platform.machine()}, {jax.devices()[0]}, "
        f"jax {jax.__version__}, scipy {scipy.__version__}, python {sys.version.split()[0]}, "
        f"freed memory kept: {bool(kept)}"
    )
    if args.disney:
        disney(args.repeats)
        return
    model = models.from_spec(args.model)
    truth = {k: v for k, v in TRUTHS[args.truth].items() if k in {p.name for p in model.parameters}}
    data = synthesize(model, truth, noise_mult=0.03, seed=0)
    print(f"# {models.label(model)}, truth {truth}")
    if tuple(args.stride) != (1, 1, 1):
        data = merl_subgrid(data, tuple(args.stride))
    print(f"# {data.n} cells, {int(keep_mask(data, 80.0).sum())} fitted samples x 3 channels")
    for name in args.metrics:
        run_metric(name, model, data, args.repeats)


if __name__ == "__main__":
    main()
