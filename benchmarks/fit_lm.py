"""LM fit of Walter/GGX + Lambert on a full-resolution MERL-format synthetic material.

brdffit (optimistix LM, JAX, forward-mode Jacobian) against scipy.optimize.least_squares
('trf' with bounds, 2-point finite differences) and lmfit (MINPACK leastsq, finite
differences) on the *same* residual: the low_e2 metric over the same valid samples,
written in numpy with the geometry precomputed once. All three start from the same
point (brdffit's linear start at the default roughness) and solve in natural units
(brdffit in its unconstrained space). Times are wall seconds, best of ``--repeats``
for the warm brdffit call; the first brdffit call includes compilation.

Run: python3 benchmarks/fit_lm.py [--stride 1 1 1] [--repeats 2]

Latest numbers are in the closing note of the issue that added this file; the
machine is the project's 2-core, 24 GiB box.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

import brdffit
from brdffit import fit, models, synthesize
from brdffit.fit import _with_linear_start
from brdffit.merl import merl_subgrid
from brdffit.metrics import get_metric, keep_mask, prepare
from brdffit.parameters import ParameterLayout

TRUTH = {"kd": [0.12, 0.30, 0.55], "f0": [0.9, 0.6, 0.3], "alpha": 0.12}


def numpy_residual_factory(data, keep):
    """low_e2 residuals of GGX + Lambert in numpy, geometry precomputed once."""
    wi, wo = data.wi[keep], data.wo[keep]
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    ci, co, ch = wi[:, 2], wo[:, 2], h[:, 2]
    cd = np.clip(np.sum(wi * h, axis=1), 0, 1)
    s5 = (1 - cd) ** 5
    sin2h = h[:, 0] ** 2 + h[:, 1] ** 2
    t2i = (1 - ci**2) / ci**2
    t2o = (1 - co**2) / co**2
    root_w = np.sqrt(np.sqrt(1 - ci**2))[:, None]
    target = np.log1p(data.values[keep] * ci[:, None])

    def residual(x):
        kd, f0, a = x[0:3], x[3:6], x[6]
        d = 1.0 / (np.pi * a * a * (sin2h / (a * a) + ch * ch) ** 2)
        li = 0.5 * (a * a * t2i) / (np.sqrt(1 + a * a * t2i) + 1)
        lo = 0.5 * (a * a * t2o) / (np.sqrt(1 + a * a * t2o) + 1)
        g = 1.0 / ((1 + li) * (1 + lo))
        f = f0[None, :] * (1 - s5)[:, None] + s5[:, None]
        spec = f * (d * g / (4 * ci * co))[:, None] + kd[None, :] / np.pi
        return (root_w * (np.log1p(spec * ci[:, None]) - target)).ravel()

    return residual


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--stride", type=int, nargs=3, default=(1, 1, 1))
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    import jax
    import lmfit
    import scipy
    from scipy.optimize import least_squares

    brdffit.enable_compilation_cache()
    print(
        f"# {platform.processor() or platform.machine()}, {jax.devices()[0]}, "
        f"jax {jax.__version__}, scipy {scipy.__version__}, lmfit {lmfit.__version__}"
    )
    m = models.get("walter")
    data = synthesize(m, TRUTH, noise_mult=0.05, seed=0)
    if tuple(args.stride) != (1, 1, 1):
        data = merl_subgrid(data, tuple(args.stride))
    metric = get_metric("low_e2")
    keep = keep_mask(data, 80.0)
    print(f"# {data.n} cells, {int(keep.sum())} fitted samples x 3 channels")

    prep = prepare(data, metric, cut_deg=80.0)
    layout = ParameterLayout.build(m.parameters)
    start = _with_linear_start(m, metric, layout, m.defaults(), prep)
    x0 = np.concatenate([np.ravel(np.asarray(start[k])) for k in ("kd", "f0", "alpha")])
    lo, hi = layout.bounds_flat()

    t = time.perf_counter()
    first = fit(m, data, "low_e2", init=start, n_restarts=0, screen=0)
    t_first = time.perf_counter() - t
    warm = []
    for _ in range(args.repeats):
        t = time.perf_counter()
        r = fit(m, data, "low_e2", init=start, n_restarts=0, screen=0)
        warm.append(time.perf_counter() - t)
    t_ours = min(warm)
    print(
        f"brdffit  first {t_first:8.2f} s  warm {t_ours:8.2f} s  steps {r.n_steps:4d}  "
        f"loss {r.loss:.10g}  ({first.status.name})"
    )

    res = numpy_residual_factory(data, keep)
    t = time.perf_counter()
    sp = least_squares(
        res, x0, bounds=(lo, hi), method="trf", x_scale="jac", ftol=1e-10, xtol=1e-10, gtol=1e-10
    )
    t_sp = time.perf_counter() - t
    loss_sp = float(np.sum(res(sp.x) ** 2))
    print(
        f"scipy    {t_sp:8.2f} s  nfev {sp.nfev:4d}  loss {loss_sp:.10g}  "
        f"ratio scipy/brdffit {t_sp / t_ours:.2f}"
    )

    params = lmfit.Parameters()
    for i, name in enumerate(layout.labels()):
        params.add(name.replace("[", "_").replace("]", ""), value=x0[i], min=lo[i], max=hi[i])

    def res_lm(p):
        return res(np.array([p[k].value for k in p]))

    t = time.perf_counter()
    lm = lmfit.minimize(res_lm, params, method="leastsq", ftol=1e-10, xtol=1e-10)
    t_lm = time.perf_counter() - t
    loss_lm = float(np.sum(res_lm(lm.params) ** 2))
    print(
        f"lmfit    {t_lm:8.2f} s  nfev {lm.nfev:4d}  loss {loss_lm:.10g}  "
        f"ratio lmfit/brdffit {t_lm / t_ours:.2f}"
    )


if __name__ == "__main__":
    main()
