"""Coverage of brdffit's nominal 95% intervals, by simulation with known truth and noise.

For each setting (model x data noise x metric) the script draws ``--n-datasets``
synthetic data sets from one fixed truth, fits each by LM and samples its posterior,
and counts, per parameter scalar and interval kind, the fraction of data sets whose
interval holds the truth, with a Clopper-Pearson 95% interval on that fraction.

Data (one fixed design, only the noise changes between data sets): the strided MERL
grid ``STRIDE`` = (5, 9, 9) (18 theta_h x 10 theta_d x 20 phi_d bin centres, 3,600
cells; 2,266 inside the 80-degree cut, x 3 channels), solid-angle weights from
:func:`brdffit.io.merl_grid.merl_grid`. theta_h is sampled densely near the mirror direction
(the MERL sqrt spacing), so the sharp lobes are resolved with few cells. Noise per cell
and channel, ``eps ~ N(0, 1)``, independent:

* ``mult``: ``f (1 + 0.05 eps)``;
* ``add``: ``f + s eps`` with ``s = 0.02 x median(f cos_i)`` of the noise-free data
  over the cells inside the cut (all channels pooled; one number per setting, printed
  in the results): about 1/6 of the diffuse floor ``kd / pi`` of the darkest channel.
  Negative values are masked (marked invalid, the MERL convention), never clipped; the
  count of masked cells is reported. It is 0 for these truths: the smallest
  noise-free value inside the cut is over 6 s, so neither truncation bias nor a
  changing sample count (which would also recompile every data set) enters.

Interval kinds: ``lm_sandwich``, ``lm_classic`` and ``lm_blocks`` (value +/- 1.96 stderr
of ``brdffit.fit(..., errors=...)``; ``blocks`` is the default for measured data, checked
here on data without model error), and ``post_<noise>`` (2.5-97.5% quantiles of
``brdffit.sample(..., noise=<noise>)`` started at the sandwich fit). The sandwich fit
starts at the truth with the screen off and no restarts (``--start truth``, the
default): the intervals are judged at the optimum of the truth's basin, so a start
policy that misses it cannot pass for miscalibration (``--start default`` uses
brdffit's own starts; on the few data sets checked both reached the same loss, at
20-50 s per Lafortune fit under load instead of 0.1 s). The classic fit restarts from
the sandwich answer, so the two differ only in the covariance. Posteriors are sampled
for the settings and noise models of :data:`POSTERIOR_PLAN` (``--posteriors plan``,
the CPU budget) or for all (``--posteriors all``).

Which kinds match which data (the "matched" column of the tables), from
``brdffit/engine/uncertainty.py`` and the noise models in ``brdffit/engine/sample.py``; ``r_i`` is
the metric's residual, ``w_i`` its weight (solid angle for ngan, ``sin theta_i`` for
low_e2):

* ``lm_sandwich`` assumes independent residuals of any variance: matched everywhere.
* ``lm_blocks`` assumes residuals independent between 10-degree (theta_h, theta_d)
  blocks and anything within one: independent noise is a case of it, so it is matched
  everywhere (and, with its Student-t widening, a little conservative by design).
* ``lm_classic`` and ``post_constant`` assume one variance for every residual. None of
  these settings has it: ``sd(r_i)`` is ``sqrt(w_i) f cos_i s`` (ngan, mult),
  ``sqrt(w_i) cos_i s`` (ngan, add; ``w_i`` spans orders of magnitude on the MERL
  grid), ``sqrt(w_i) s f cos_i / (1 + f cos_i)`` (low_e2, mult) and
  ``sqrt(w_i) s cos_i / (1 + f cos_i)`` (low_e2, add). Not matched anywhere.
* ``post_multiplicative`` scales each residual by ``|d r_i / d ln f_i|``: to first
  order in ``s`` that is exactly ``sd(r_i) / s`` for ``f (1 + s eps)`` noise under
  either metric (low_e2 is a log metric but of ``1 + f cos``, not of ``f``, so a
  constant scale does not match multiplicative noise under low_e2 either; the
  ``f cos / (1 + f cos)`` factor is what ``s_i`` supplies). Matched on ``mult``.
* ``post_additive`` scales by ``|d r_i / d f_i|``: exact for ngan, first order for
  low_e2 (delta method through ``ln(1 + f cos)``; the noise there,
  ``s cos_i / (1 + f cos_i)``, is at most ``s`` = 0.006, so the second-order term is
  below 2e-5). Matched on ``add``. Both heteroscedastic models are first-order matches:
  ``f (1 + s eps)`` is log-normal only to first order, and under low_e2 its log is
  biased by up to ``-s^2/2`` on the peak (the results file shows what that does).
* ``post_mixed`` (``sample()``'s default) has both scales, ``a_i`` and ``m_i`` above,
  each sampled: it contains both of the previous two, so it is matched on either.

Posterior convergence: a chain counts as converged when
``Posterior.require_converged(multiple=10)`` passes (kept steps >= 10 integrated
autocorrelation times, the largest over the scalars) and the smallest effective sample
size is >= 400 (enough for a 2.5% quantile: its tail probability then has a Monte
Carlo sd of about 0.8%); the fraction passing brdffit's default warning multiple (50
tau) is reported too. The budget (1,200 steps, 400 burn-in, default walkers) was set
by the CPU time, not by convergence: by each chain's own estimate about 13 tau and an
ESS near 600, but 4x longer chains put tau at about twice that (``--chain-check``),
while their 95% widths agree with the short chains' within a few percent. Coverage
counts every chain, converged or not; the summary also gives the median coverage over
converged chains only. LM fits that did not converge are dropped and counted; a
scalar without a standard error (held on a bound, singular J^T J) counts as "no
interval" and is left out of its fraction. Multi-lobe models are put in a canonical
lobe order before comparing with the truth (lobes sorted by ``ModelCase.lobe_key``,
per LM answer and per posterior sample), so a swapped pair of lobes is not counted as
a miss; the number of swaps is reported.

Each setting's results live in one JSON file (``--out``/<setting>.json), one record per
data set, written atomically as each data set finishes (:mod:`benchmarks.jobs`); a killed
run resumes where it stopped. The tables are rebuilt from those files on every run.

Model cases (:data:`MODEL_CASES`): ``walter`` (GGX + Lambert, RGB ks, 10 scalars),
``lafortune2`` (two lobes, 13), ``disney`` (isotropic, no sheen or clearcoat, no specular
tint: 7) and ``sgd`` (one lobe for the three channels, 14).

Run (from the repository root):
     python -m benchmarks.calibration --quick                 # smoke test, 4 data sets
     python -m benchmarks.calibration [--n-datasets 50] [--settings 'walter_*']
         [--posteriors plan|all|matched|none] [--jobs 1] [--md benchmarks/results/calibration.md]
     python -m benchmarks.calibration --tables-only --md ...   # tables from the cache
     python -m benchmarks.calibration --chain-check 4 --settings ...  # 4x longer chains

Cost on this project's 2-core box (shared; wall under a load of ~10): per data set,
walter LM 0.2-0.5 s and a 1,200-step posterior 7-12 s; lafortune2 LM 0.1-1 s and a
posterior 13-30 s. The whole plan at 50 data sets: 69 min wall, 54 min of CPU.

Latest figures: benchmarks/results/calibration.md (this project's 2-core box, CPU).
"""

from __future__ import annotations

import argparse
import datetime
import fnmatch
import functools
import hashlib
import inspect
import json
import os
import platform
import re
import sys
import time
import traceback
import warnings
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from scipy import stats

import brdffit
from benchmarks.jobs import run_jobs
from brdffit import fit, models, sample
from brdffit.errors import ChainTooShortError
from brdffit.io.merl_grid import merl_grid, merl_grid_measurements
from brdffit.util.atomic import has_key, write_json, write_text
from brdffit.util.text_table import render

STRIDE = (5, 9, 9)
CUT_DEG = 80.0
NOISE_LEVEL = {"mult": 0.05, "add": 0.02}
"""``mult``: relative sd; ``add``: sd as a share of the median noise-free ``f cos_i``."""
METRICS = ("low_e2", "ngan")
POSTERIOR_NOISES = ("constant", "multiplicative", "additive", "mixed")
MATCHED_POSTERIOR = {"mult": "multiplicative", "add": "additive"}
Z95 = 1.959963984540054
CONVERGED_MULTIPLE = 10.0
CONVERGED_ESS = 400.0
DEFAULT_MULTIPLE = 50.0
TARGET = (0.90, 0.98)


@dataclass(frozen=True)
class ModelCase:
    """A model, its options, the truth (natural units) and its MCMC budget.

    ``truth`` names parameters; a parameter the model has but ``truth`` lacks takes its
    default (flagged in the results); a scalar truth broadcasts to an RGB parameter.
    ``lobe_key``: parameter stem (``n`` for ``n_1``, ``n_2``) the lobes are sorted by.
    """

    name: str
    options: dict
    truth: dict
    n_steps: int
    burn: int
    lobe_key: str | None


MODEL_CASES = {
    "walter": ModelCase(
        "walter",
        {},
        # ``ks`` (RGB specular weight) is used if the model has it; ignored otherwise.
        {"kd": [0.12, 0.30, 0.55], "f0": [0.7, 0.5, 0.3], "alpha": 0.15, "ks": [0.8, 0.7, 0.6]},
        n_steps=1200,
        burn=400,
        lobe_key=None,
    ),
    "lafortune2": ModelCase(
        "lafortune",
        {"n_lobes": 2},
        # A broad, slightly off-specular lobe and a sharp one: exponents 15x apart.
        {
            "kd": [0.10, 0.20, 0.35],
            "rho_1": [0.30, 0.25, 0.20],
            "cxy_1": -0.85,
            "n_1": 4.0,
            "rho_2": [0.50, 0.45, 0.40],
            "cxy_2": -1.0,
            "n_2": 60.0,
        },
        n_steps=1200,
        burn=400,
        lobe_key="n",
    ),
}

MODEL_CASES |= {
    # Disney 2012 without the features isotropic MERL-grid data cannot fix (anisotropy, and
    # the specular tint once metallic is on: tests/cases_c.py) and without the two lobes
    # that are off for most materials (sheen, clearcoat): 7 scalars.
    "disney": ModelCase(
        "disney",
        {"anisotropic": False, "sheen": False, "clearcoat": False, "specular_tint": False},
        {
            "base_color": [0.6, 0.4, 0.2],
            "metallic": 0.3,
            "subsurface": 0.4,
            "specular": 0.5,
            "roughness": 0.35,
        },
        n_steps=1200,
        burn=400,
        lobe_key=None,
    ),
    # Bagher et al.'s SGD with one lobe for the three channels: 14 scalars.
    "sgd": ModelCase(
        "sgd",
        {},
        {
            "kd": [0.10, 0.20, 0.30],
            "ks": [0.6, 0.5, 0.4],
            "f0": [0.5, 0.4, 0.3],
            "f1": [0.1, 0.1, 0.1],
            "alpha": 0.05,
            "p": 0.6,
        },
        n_steps=1200,
        burn=400,
        lobe_key=None,
    ),
}

SETTINGS = {
    f"{mc}_{noise}_{metric}": (mc, noise, metric)
    for mc in MODEL_CASES
    for noise in NOISE_LEVEL
    for metric in METRICS
}


POSTERIOR_PLAN = {
    "walter_mult_low_e2": ("matched", "constant", "other"),
    "walter_add_ngan": ("matched", "constant", "other"),
    "walter_mult_ngan": ("matched",),
    "walter_add_low_e2": ("matched",),
    "lafortune2_mult_low_e2": ("matched",),
    "lafortune2_add_ngan": ("matched",),
}
"""Posterior noise models per setting under ``--posteriors plan`` (the CPU budget, set
for about 45 min of one core; the run took 54). ``matched``: the noise model of the
data; ``other``: the heteroscedastic one that is not. Settings not listed: LM only."""


@dataclass(frozen=True)
class Config:
    """Run settings that must agree between a cache file and the run that extends it."""

    start: str
    n_restarts: int
    steps_scale: float
    n_walkers: int | None

    def steps(self, mc: ModelCase) -> tuple[int, int]:
        return int(round(mc.n_steps * self.steps_scale)), int(round(mc.burn * self.steps_scale))


# ----------------------------------------------------------------------------- data


@functools.cache
def _model(case: str):
    mc = MODEL_CASES[case]
    return models.get(mc.name, **mc.options)


def labels_of(model) -> list[str]:
    """One label per scalar of every parameter: ``name`` or ``name[c]``."""
    out = []
    for p in model.parameters:
        out += [p.name] if p.shape == () else [f"{p.name}[{c}]" for c in "rgb"]
    return out


def flat(model, values: dict) -> np.ndarray:
    """Name -> array dict as one vector in :func:`labels_of` order."""
    return np.concatenate(
        [
            np.broadcast_to(np.asarray(values[p.name], float), p.shape).ravel()
            for p in model.parameters
        ]
    )


def truth_of(case: str) -> tuple[dict, list[str]]:
    """The full truth dict of ``case`` and the names that fell back to defaults."""
    mc, model = MODEL_CASES[case], _model(case)
    full, defaulted = {}, []
    for p in model.parameters:
        if p.name in mc.truth:
            full[p.name] = np.broadcast_to(np.asarray(mc.truth[p.name], float), p.shape).copy()
        else:
            full[p.name] = np.asarray(p.default_array(), float)
            defaulted.append(p.name)
    return full, defaulted


def near_bound(case: str) -> list[str]:
    """Truth scalars within 5% of their span from a bound (log span for log parameters)."""
    model = _model(case)
    full, _ = truth_of(case)
    out = []
    for p in model.parameters:
        lo, hi = p.bounds
        for j, x in enumerate(np.ravel(full[p.name])):
            if not (np.isfinite(lo) and np.isfinite(hi)):
                continue
            if p.transform == "log" and lo > 0:
                t = np.log(x / lo) / np.log(hi / lo)
            else:
                t = (x - lo) / (hi - lo)
            if min(t, 1 - t) < 0.05:
                out.append(p.name if p.shape == () else f"{p.name}[{'rgb'[j]}]")
    return out


@functools.cache
def _clean(case: str) -> tuple[np.ndarray, float]:
    """Noise-free values (N, 3) on the grid and the additive noise sd of ``case``."""
    model = _model(case)
    g = merl_grid(STRIDE)
    full, _ = truth_of(case)
    f = np.asarray(model.eval(full, jnp.asarray(g.wi), jnp.asarray(g.wo)), float)
    c = np.cos(np.deg2rad(CUT_DEG))
    inside = g.above & (g.wi[:, 2] > c) & (g.wo[:, 2] > c)
    s_add = NOISE_LEVEL["add"] * float(np.median(f[inside] * g.wi[inside, 2:3]))
    return f, s_add


def make_data(setting: str, i: int):
    """Data set ``i`` of ``setting``: Measurements and the count of masked negative cells."""
    case, noise, _ = SETTINGS[setting]
    f, s_add = _clean(case)
    rng = np.random.default_rng([zlib.crc32(setting.encode()), i])
    eps = rng.standard_normal(f.shape)
    fd = f * (1.0 + NOISE_LEVEL["mult"] * eps) if noise == "mult" else f + s_add * eps
    g = merl_grid(STRIDE)
    n_neg = int(np.sum(np.any(fd < 0, axis=1) & g.above))
    data = merl_grid_measurements(
        fd.T.reshape(3, *g.shape), source=f"calibration {setting} #{i}", stride=STRIDE
    ).replace(synthetic=True)  # a model's values plus independent noise
    return data, n_neg


# ----------------------------------------------------------------------------- lobes


def _lobe_columns(model, key: str | None) -> tuple[np.ndarray, np.ndarray] | None:
    """Columns of each lobe's scalars (L, c) in one stem order, and of each lobe's key (L,).

    Lobes are the parameters named ``<stem>_<l>``; None for a single-lobe model.
    """
    if key is None:
        return None
    labs = labels_of(model)
    lobes: dict[int, dict[str, list[int]]] = {}
    for j, lab in enumerate(labs):
        m = re.fullmatch(r"(.+)_(\d+)", lab.split("[")[0])
        if m:
            lobes.setdefault(int(m.group(2)), {}).setdefault(m.group(1), []).append(j)
    if len(lobes) < 2:
        return None
    stems = list(lobes[min(lobes)])
    cols = np.array([sum((lobes[l][s] for s in stems), []) for l in sorted(lobes)])
    keys = np.array([lobes[l][key][0] for l in sorted(lobes)])
    return cols, keys


def canonical_perm(model, key: str | None, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column permutation per row of ``x`` (..., d) that sorts the lobes by ``key``.

    Returns (perm of x's shape, for ``np.take_along_axis``; bool per row: order changed).
    """
    perm = np.broadcast_to(np.arange(x.shape[-1]), x.shape).copy()
    lc = _lobe_columns(model, key)
    if lc is None:
        return perm, np.zeros(x.shape[:-1], bool)
    cols, keys = lc
    order = np.argsort(x[..., keys], axis=-1, kind="stable")  # (..., L)
    for dst in range(len(keys)):
        perm[..., cols[dst]] = cols[order[..., dst]]
    return perm, np.any(order != np.arange(len(keys)), axis=-1)


# ----------------------------------------------------------------------------- one data set


def _lm_record(model, key: str | None, r) -> dict:
    x = flat(model, r.params)
    se = flat(model, r.stderr) if r.stderr is not None else np.full(x.size, np.nan)
    perm, swapped = canonical_perm(model, key, x)
    return {
        "value": x[perm].tolist(),
        "stderr": se[perm].tolist(),  # NaN: no interval for that scalar
        "converged": bool(r.converged),
        "status": r.status.name,
        "errors_reason": r.errors_reason,
        "at_bound": list(r.at_bound),
        "swapped": bool(swapped),
        "n_samples": int(r.n_samples),
        "wall_time": float(r.wall_time),
    }


def _passes(post, multiple: float) -> bool:
    try:
        post.require_converged(multiple)
    except ChainTooShortError:
        return False
    return True


def _post_record(model, key: str | None, post, caught: list) -> dict:
    labs = labels_of(model)
    k = len(post.labels) - len(labs)  # the noise scales: log_sigma, or _add and _mult
    if list(post.labels[:-k]) != labs:
        raise RuntimeError(f"posterior labels {post.labels} differ from the model's {labs}")
    s = post.samples()
    x = s[:, :-k]
    perm, swapped = canonical_perm(model, key, x)
    x = np.take_along_axis(x, perm, axis=-1)
    q = np.quantile(x, (0.025, 0.5, 0.975), axis=0)
    return {
        "q025": q[0].tolist(),
        "q50": q[1].tolist(),
        "q975": q[2].tolist(),
        "swapped_fraction": float(np.mean(swapped)),
        "sigma": float(np.exp(np.median(s[:, -1]))),
        "sigmas": {
            lab: float(np.exp(np.median(s[:, -k + j]))) for j, lab in enumerate(post.labels[-k:])
        },
        "tau_max": float(np.max(post.autocorr_time)),
        "ess_min": float(np.min(post.ess)),
        "rhat_max": float(np.max(post.split_rhat())),
        "converged": _passes(post, CONVERGED_MULTIPLE) and bool(np.min(post.ess) >= CONVERGED_ESS),
        "converged_default": _passes(post, DEFAULT_MULTIPLE),
        "acceptance": float(np.mean(post.acceptance_fraction)),
        "stuck_walkers": len(post.stuck_walkers),
        "at_bound": [lab for lab, _ in post.at_bound],
        "n_walkers": int(post.chain.shape[1]),
        "n_steps": post.n_steps,
        "burn": post.burn,
        "warnings": sorted({type(w.message).__name__ for w in caught}),
        "wall_time": float(post.wall_time),
    }


def _sandwich_fit(case: str, data, metric: str, cfg: Config):
    """The LM fit with default errors, started as ``cfg.start`` says (module docstring)."""
    start = {"init": truth_of(case)[0], "screen": 0} if cfg.start == "truth" else {}
    return fit(
        _model(case), data, metric, n_restarts=cfg.n_restarts, cut_deg=CUT_DEG, throw=False,
        errors="sandwich", **start,
    )  # fmt: skip


def chain_check(out: Path, setting: str, n: int, factor: int, cfg: Config) -> list[str]:
    """Re-sample data sets ``0..n-1`` of ``setting`` with ``factor`` x the steps and burn-in.

    For every posterior kind in the cache: the integrated autocorrelation time of the
    long and the cached chain, and the ratio of the 95% interval widths (long / cached)
    per scalar. Widths that do not move mean the cached chains were long enough for
    their quantiles, whatever the short chain's own tau estimate says. Returns lines.
    """
    d = load_setting(out, setting)
    if d is None:
        return [f"{setting}: no cache"]
    case, _, metric = SETTINGS[setting]
    mc, model = MODEL_CASES[case], _model(case)
    n_steps, burn = cfg.steps(mc)
    lines = []
    for kind in (k for k in KIND_ORDER if k.startswith("post_")):
        ratios = []
        for i in range(n):
            old = d["records"].get(str(i), {}).get(kind)
            if old is None:
                continue
            data, _ = make_data(setting, i)
            r = _sandwich_fit(case, data, metric, cfg)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                post = sample(
                    model, data, init=r, noise=kind[5:], n_walkers=cfg.n_walkers,
                    n_steps=factor * n_steps, burn=factor * burn, cut_deg=CUT_DEG, seed=i,
                    progress=False,
                )  # fmt: skip
            new = _post_record(model, mc.lobe_key, post, [])
            w = np.subtract(new["q975"], new["q025"]) / np.subtract(old["q975"], old["q025"])
            ratios.append(w)
            lines.append(
                f"{setting} {kind} #{i}: tau {old['tau_max']:.0f} ({n_steps} steps) -> "
                f"{new['tau_max']:.0f} ({factor * n_steps} steps); width ratio "
                f"{np.min(w):.2f}-{np.max(w):.2f}, median {np.median(w):.3f}"
            )
            print(lines[-1], flush=True)
        if ratios:
            lines.append(
                f"{setting} {kind}: median width ratio over {len(ratios)} data sets and "
                f"{len(ratios[0])} scalars {np.median(ratios):.3f} (sd {np.std(ratios):.3f})"
            )
            print(lines[-1], flush=True)
    return lines


def run_dataset(job: tuple[str, int, tuple[str, ...]], cfg: Config) -> dict:
    """Fit and sample data set ``i`` of ``setting`` for the interval ``kinds``; a status dict."""
    setting, i, kinds = job
    t0 = time.perf_counter()
    try:
        case, _, metric = SETTINGS[setting]
        mc, model = MODEL_CASES[case], _model(case)
        data, n_neg = make_data(setting, i)
        rec: dict = {"n_negative": n_neg}
        # The sandwich fit is always made: it is the posterior's start.
        r = _sandwich_fit(case, data, metric, cfg)
        if "lm_sandwich" in kinds:
            rec["lm_sandwich"] = _lm_record(model, mc.lobe_key, r)
        for kind in ("lm_classic", "lm_blocks"):
            if kind not in kinds:
                continue
            # Same optimum: started there, it stops at once; only the covariance differs.
            rc = fit(
                model, data, metric, init=r.params, screen=0, n_restarts=0, cut_deg=CUT_DEG,
                errors=kind[3:], throw=False,
            )  # fmt: skip
            rec[kind] = _lm_record(model, mc.lobe_key, rc)
            rec[kind]["max_rel_change"] = float(
                np.max(np.abs(flat(model, rc.params) - flat(model, r.params))
                       / np.maximum(np.abs(flat(model, r.params)), 1e-12))
            )  # fmt: skip
        n_steps, burn = cfg.steps(mc)
        for kind in kinds:
            if not kind.startswith("post_"):
                continue
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                post = sample(
                    model, data, init=r, noise=kind[5:], n_walkers=cfg.n_walkers,
                    n_steps=n_steps, burn=burn, cut_deg=CUT_DEG, seed=i, progress=False,
                )  # fmt: skip
            rec[kind] = _post_record(model, mc.lobe_key, post, caught)
        rec[f"wall_time:{','.join(kinds)}"] = time.perf_counter() - t0
        return {"ok": True, "setting": setting, "i": i, "kinds": kinds, "record": rec}
    except Exception as e:
        return {
            "ok": False, "setting": setting, "i": i, "kinds": kinds,
            "error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc(),
        }  # fmt: skip


# ----------------------------------------------------------------------------- the cache


def setting_path(out: Path, setting: str) -> Path:
    return out / f"{setting}.json"


def load_setting(out: Path, setting: str) -> dict | None:
    path = setting_path(out, setting)
    return json.loads(path.read_text()) if has_key(path, "records") else None


def model_source_sha1(case: str) -> str:
    """SHA-1 of the model's source file: a cache is only extended by the same model code."""
    src = inspect.getsourcefile(type(_model(case)))
    return hashlib.sha1(Path(src).read_bytes()).hexdigest()


def new_setting(setting: str, cfg: Config) -> dict:
    case, noise, metric = SETTINGS[setting]
    model = _model(case)
    full, defaulted = truth_of(case)
    mc = MODEL_CASES[case]
    n_steps, burn = cfg.steps(mc)
    return {
        "setting": setting,
        "model": mc.name,
        "options": mc.options,
        "noise": noise,
        "metric": metric,
        "config": asdict(cfg),
        "stride": list(STRIDE),
        "noise_level": NOISE_LEVEL[noise],
        "s_add": _clean(case)[1] if noise == "add" else None,
        "labels": labels_of(model),
        "truth": flat(model, full).tolist(),
        "truth_defaulted": defaulted,
        "truth_near_bound": near_bound(case),
        "posterior_steps": [n_steps, burn],
        "model_source_sha1": model_source_sha1(case),
        "records": {},
    }


def kinds_for(setting: str, posteriors: str) -> list[tuple[str, ...]]:
    """The interval kinds of ``setting`` in run phases: LM + matched, constant, other.

    ``posteriors``: ``"plan"`` (:data:`POSTERIOR_PLAN`), ``"all"``, ``"matched"``,
    ``"mixed"`` (sample()'s default noise model only), ``"none"``.
    """
    noise = SETTINGS[setting][1]
    matched = MATCHED_POSTERIOR[noise]
    other = next(n for n in POSTERIOR_NOISES if n not in (matched, "constant", "mixed"))
    plan = {
        "plan": POSTERIOR_PLAN.get(setting, ()),
        "all": ("matched", "constant", "other", "mixed"),
        "matched": ("matched",),
        "mixed": ("mixed",),
        "none": (),
    }[posteriors]
    name = {"matched": matched, "constant": "constant", "other": other, "mixed": "mixed"}
    first = [p for p in ("matched", "mixed") if p in plan][:1]
    phases = [("lm_sandwich", "lm_classic", "lm_blocks") + tuple("post_" + name[p] for p in first)]
    phases += [
        ("post_" + name[p],) for p in ("constant", "other", "mixed") if p in plan and p not in first
    ]
    return phases


# ----------------------------------------------------------------------------- analysis


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper-Pearson) two-sided interval for a binomial proportion ``k / n``."""
    if n == 0:
        return float("nan"), float("nan")
    a = 1.0 - level
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def wilson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion ``k / n``."""
    if n == 0:
        return float("nan"), float("nan")
    z = float(stats.norm.ppf(0.5 + level / 2))
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return float(centre - half), float(centre + half)


def coverage_of(inside: np.ndarray, has: np.ndarray) -> list[dict]:
    """Per scalar: hits, trials, fraction and Clopper-Pearson interval.

    ``inside``, ``has``: bool (data sets, scalars): the interval holds the truth / exists.
    """
    out = []
    for j in range(inside.shape[1]):
        n = int(np.sum(has[:, j]))
        k = int(np.sum(inside[:, j] & has[:, j]))
        lo, hi = clopper_pearson(k, n)
        out.append({"k": k, "n": n, "cov": k / n if n else float("nan"), "lo": lo, "hi": hi})
    return out


def analyse(d: dict, kind: str, n_max: int) -> dict | None:
    """Coverage and diagnostics of one interval kind over the data sets of one setting."""
    truth = np.asarray(d["truth"])
    recs = [d["records"][k] for k in sorted(d["records"], key=int) if int(k) < n_max]
    recs = [r[kind] for r in recs if kind in r]
    if not recs:
        return None
    out: dict = {"n_records": len(recs)}
    if kind.startswith("lm_"):
        conv = np.array([r["converged"] for r in recs])
        v = np.array([r["value"] for r in recs])[conv]
        se = np.array([r["stderr"] for r in recs], float)[conv]
        has = np.isfinite(se)
        inside = np.abs(v - truth) <= Z95 * np.where(has, se, 0.0)
        est, nominal = v, np.where(has, se, np.nan)
        out.update(
            n_dropped=int(np.sum(~conv)),
            swaps=int(sum(r["swapped"] for r in recs)),
            no_interval=int(np.sum(~has)),
        )
        conv_only = None
    else:
        lo = np.array([r["q025"] for r in recs])
        hi = np.array([r["q975"] for r in recs])
        est = np.array([r["q50"] for r in recs])
        has = np.ones_like(lo, bool)
        inside = (lo <= truth) & (truth <= hi)
        nominal = (hi - lo) / (2 * Z95)
        conv = np.array([r["converged"] for r in recs])
        conv_only = coverage_of(inside[conv], has[conv]) if conv.any() else None
        out.update(
            n_dropped=0,
            converged=float(np.mean(conv)),
            converged_default=float(np.mean([r["converged_default"] for r in recs])),
            tau_max_median=float(np.median([r["tau_max"] for r in recs])),
            ess_min_median=float(np.median([r["ess_min"] for r in recs])),
            acceptance_median=float(np.median([r["acceptance"] for r in recs])),
            swapped=int(sum(r["swapped_fraction"] > 0.01 for r in recs)),
            at_bound=int(sum(bool(r["at_bound"]) for r in recs)),
            stuck=int(sum(r["stuck_walkers"] > 0 for r in recs)),
        )
    cov = coverage_of(inside, has)
    with np.errstate(invalid="ignore", divide="ignore"):
        sd_emp = np.std(est, axis=0, ddof=1) if len(est) > 1 else np.full(truth.size, np.nan)
        sd_nom = (
            np.sqrt(np.nanmean(nominal**2, axis=0)) if len(est) else np.full(truth.size, np.nan)
        )
        bias = (np.mean(est, axis=0) - truth) / sd_emp if len(est) else np.full(truth.size, np.nan)
    out.update(
        per_scalar=cov,
        sd_ratio=(sd_emp / sd_nom).tolist(),
        bias_over_sd=bias.tolist(),
        conv_only=conv_only,
    )
    return out


def chance_outside(n: int, p: float = 0.95) -> float:
    """Probability that a perfectly calibrated scalar's coverage ``k / n`` is outside TARGET."""
    k = np.arange(n + 1)
    pmf = stats.binom.pmf(k, n, p)
    return float(np.sum(pmf[(k < TARGET[0] * n - 1e-9) | (k > TARGET[1] * n + 1e-9)]))


def is_matched(noise: str, kind: str) -> bool:
    """Whether interval ``kind`` assumes what data noise ``noise`` is (module docstring)."""
    everywhere = ("lm_sandwich", "lm_blocks", "post_mixed")
    return kind in everywhere or kind == f"post_{MATCHED_POSTERIOR[noise]}"


KIND_ORDER = (
    "lm_sandwich",
    "lm_classic",
    "lm_blocks",
    "post_constant",
    "post_multiplicative",
    "post_additive",
    "post_mixed",
)


def _pct(x: float) -> str:
    return "n/a" if not np.isfinite(x) else f"{100 * x:.0f}"


def _cell(c: dict, ratio: float) -> str:
    if c["n"] == 0:
        return "no interval"
    flag = ""
    if c["cov"] < TARGET[0] or c["cov"] > TARGET[1]:
        flag = " **!**" if (c["hi"] < 0.95 or c["lo"] > 0.95) else " *"
    r = f" ({ratio:.2f})" if np.isfinite(ratio) else ""
    return f"{_pct(c['cov'])} [{_pct(c['lo'])}, {_pct(c['hi'])}]{r}{flag}"


def tables(out: Path, settings: list[str], n_max: int) -> tuple[str, dict]:
    """Markdown tables of every setting found in ``out``; also the analysis as a dict."""
    summary, blocks, conv_rows, analysed = [], [], [], {}
    for setting in settings:
        d = load_setting(out, setting)
        if d is None:
            blocks.append(f"### {setting}\n\nNo results.\n")
            continue
        labels, noise = d["labels"], d["noise"]
        res = {k: a for k in KIND_ORDER if (a := analyse(d, k, n_max)) is not None}
        analysed[setting] = res
        kinds = list(res)
        head = ["scalar", "truth", "bias/sd (LM)"] + [
            f"{k}{' (matched)' if is_matched(noise, k) else ''}" for k in kinds
        ]
        body = []
        for j, lab in enumerate(labels):
            row = [lab, f"{d['truth'][j]:.4g}"]
            b = res.get("lm_sandwich", {}).get("bias_over_sd", [np.nan] * len(labels))[j]
            row.append(f"{b:+.2f}" if np.isfinite(b) else "n/a")
            row += [_cell(res[k]["per_scalar"][j], res[k]["sd_ratio"][j]) for k in kinds]
            body.append(row)
        level = f"{d['noise_level']:g}"
        if noise == "add":
            level += f" x median f cos = {d['s_add']:.4g} 1/sr"
        opts = f" {d['options']}" if d["options"] else ""
        notes = [
            f"{setting}: {d['model']}{opts} / {noise} noise ({level}) / {d['metric']}.",
            "Data sets per kind: "
            + ", ".join(f"{k} {res[k]['n_records']}" for k in kinds)
            + (
                "; LM fits dropped (not converged): "
                + ", ".join(f"{k} {res[k]['n_dropped']}" for k in kinds if k.startswith("lm_"))
            ),
        ]
        neg = sum(r.get("n_negative", 0) for k, r in d["records"].items() if int(k) < n_max)
        notes.append(f"Negative cells masked (additive noise): {neg} over all data sets.")
        if d["truth_defaulted"]:
            notes.append(
                f"Truth at the model's default (not in the case's table): {d['truth_defaulted']}."
            )
        if d["truth_near_bound"]:
            notes.append(f"Truth within 5% of a bound: {d['truth_near_bound']}.")
        blocks.append(
            f"### {setting}\n\n" + "\n".join(f"- {n}" for n in notes) + "\n\n" + render(head, body)
        )
        for k in kinds:
            a = res[k]
            covs = np.array([c["cov"] for c in a["per_scalar"] if c["n"]])
            excl = sum(1 for c in a["per_scalar"] if c["n"] and (c["hi"] < 0.95 or c["lo"] > 0.95))
            co = a.get("conv_only")
            co_med = _pct(np.median([c["cov"] for c in co if c["n"]])) if co else "n/a"
            outside = [
                lab for lab, c in zip(labels, a["per_scalar"], strict=True)
                if c["n"] and not TARGET[0] <= c["cov"] <= TARGET[1]
            ]  # fmt: skip
            n_min = min(c["n"] for c in a["per_scalar"])
            pooled = sum(c["k"] for c in a["per_scalar"]) / max(
                sum(c["n"] for c in a["per_scalar"]), 1
            )
            summary.append([
                setting, k, "yes" if is_matched(noise, k) else "no",
                str(n_min) if covs.size else "0",
                _pct(covs.min()) if covs.size else "n/a",
                _pct(np.median(covs)) if covs.size else "n/a",
                f"{100 * pooled:.1f}",
                f"{len(outside)}/{len(labels)} ({chance_outside(n_min) * len(labels):.1f})",
                f"{excl}/{len(labels)}",
                f"{np.nanmedian(a['sd_ratio']):.2f}",
                f"{100 * a['converged']:.0f}% / {100 * a['converged_default']:.0f}%"
                if "converged" in a else "-",
                co_med,
            ])  # fmt: skip
            if "converged" in a:
                conv_rows.append([
                    setting, k, str(a["n_records"]),
                    f"{100 * a['converged']:.0f}%", f"{100 * a['converged_default']:.0f}%",
                    f"{a['tau_max_median']:.0f}", f"{a['ess_min_median']:.0f}",
                    f"{a['acceptance_median']:.2f}", str(a["stuck"]), str(a["at_bound"]),
                    str(a["swapped"]),
                ])  # fmt: skip
    s_head = [
        "setting", "interval", "matched", "n", "min cov %", "median cov %", "pooled cov %",
        "scalars outside [90, 98] (expected by chance)", "CI excludes 95%", "median sd ratio",
        f"converged ({CONVERGED_MULTIPLE:g} tau + ESS {CONVERGED_ESS:g} / "
        f"{DEFAULT_MULTIPLE:g} tau)",
        "median cov %, converged chains only",
    ]  # fmt: skip
    c_head = [
        "setting", "posterior", "chains",
        f"converged (kept >= {CONVERGED_MULTIPLE:g} tau, ESS >= {CONVERGED_ESS:g})",
        f"kept >= {DEFAULT_MULTIPLE:g} tau", "median max tau", "median min ESS",
        "median acceptance", "with stuck walkers", "with at-bound flag", "with lobe swaps",
    ]  # fmt: skip
    text = (
        "## Summary\n\n"
        "n: data sets with an interval (the fewest over the scalars). pooled: hits over all "
        "scalars and data sets (the scalars of one data set are correlated, so it has no "
        "binomial interval). Expected by chance: the number of scalars whose coverage would "
        f"fall outside [90, 98] if every interval held the truth exactly 95% of the time "
        f"(with n = 50, {100 * chance_outside(50):.1f}% of them: k <= 44 or k = 50); a "
        "Clopper-Pearson interval excludes 95% for a calibrated scalar 1.2% of the time "
        "(k <= 43 of 50).\n\n"
        + render(s_head, summary)
        + "\n## Posterior convergence\n\n"
        + render(c_head, conv_rows)
        + "\n## Coverage per scalar\n\n"
        "Cell: coverage % [Clopper-Pearson 95% interval] (sd ratio = standard deviation of the "
        "estimate over the data sets / RMS of the interval's nominal sd, half-width / 1.96; "
        "> 1: too narrow). `*`: outside [90, 98]; `**!**`: and the binomial interval excludes "
        "95%. bias/sd (LM): mean error of the sandwich fit's estimate in units of its "
        "standard deviation over the data sets.\n\n" + "\n".join(blocks)
    )
    return text, analysed


# ----------------------------------------------------------------------------- main


def _versions() -> str:
    import emcee
    import jax
    import scipy

    return (
        f"jax {jax.__version__}, numpy {np.__version__}, scipy {scipy.__version__}, "
        f"emcee {emcee.__version__}, python {platform.python_version()}"
    )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n-datasets", type=int, default=50)
    ap.add_argument(
        "--settings", default="*",
        help=f"comma-separated names or globs out of: {', '.join(SETTINGS)}",
    )  # fmt: skip
    ap.add_argument(
        "--posteriors", default="plan", choices=("plan", "all", "matched", "mixed", "none"),
        help="noise models sampled: 'plan' = each model case's own (walter all three, "
        "lafortune2 the matched one), or the same for every setting",
    )  # fmt: skip
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--quick", action="store_true", help="4 data sets, short chains, /tmp cache")
    ap.add_argument("--n-restarts", type=int, default=0)
    ap.add_argument(
        "--start", default="truth", choices=("truth", "default"),
        help="LM start: the truth with the screen off (the intervals judged at the "
        "truth's basin) or brdffit's default start policy",
    )  # fmt: skip
    ap.add_argument("--out", type=Path, default=None, help="folder of the per-setting JSON cache")
    ap.add_argument("--md", type=Path, default=None, help="write the markdown tables here")
    ap.add_argument("--tables-only", action="store_true", help="rebuild tables from the cache")
    ap.add_argument(
        "--chain-check", type=int, default=0, metavar="N",
        help="instead of running: re-sample data sets 0..N-1 of each setting with 4x the "
        "steps and compare the interval widths with the cached ones",
    )  # fmt: skip
    args = ap.parse_args(argv)

    here = Path(__file__).resolve().parent
    if args.quick:
        args.n_datasets = min(args.n_datasets, 4)
        cfg = Config(args.start, args.n_restarts, steps_scale=0.25, n_walkers=None)
        out = args.out or Path("/tmp/brdffit_calibration_quick")
    else:
        cfg = Config(args.start, args.n_restarts, steps_scale=1.0, n_walkers=None)
        out = args.out or here / "results" / "calibration"
    pats = [p.strip() for p in args.settings.split(",") if p.strip()]
    settings = [s for s in SETTINGS if any(fnmatch.fnmatchcase(s, p) for p in pats)]
    if not settings:
        ap.error(f"--settings {args.settings!r} matches none of {', '.join(SETTINGS)}")
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    brdffit.enable_compilation_cache()

    jobs: list[tuple[str, int, tuple[str, ...]]] = []
    state: dict[str, dict] = {}
    changed: list[str] = []
    for setting in settings:
        d = load_setting(out, setting) or new_setting(setting, cfg)
        if d["config"] != asdict(cfg):
            sys.exit(
                f"{setting_path(out, setting)} was made with {d['config']}, this run uses "
                f"{asdict(cfg)}: use another --out or remove the file"
            )
        if d.get("model_source_sha1") != model_source_sha1(SETTINGS[setting][0]):
            text = (
                f"{setting_path(out, setting)} was made with another version of the model's "
                "source file"
            )
            if not (args.tables_only or args.chain_check):
                sys.exit(f"{text}: use another --out or remove the file")
            changed.append(setting)
        state[setting] = d
    if args.chain_check:
        for setting in settings:
            chain_check(out, setting, args.chain_check, 4, cfg)
        return
    if not args.tables_only:
        n_phases = max(len(kinds_for(s, args.posteriors)) for s in settings)
        for phase in range(n_phases):
            for setting in settings:
                phases = kinds_for(setting, args.posteriors)
                if phase >= len(phases):
                    continue
                for i in range(args.n_datasets):
                    have = state[setting]["records"].get(str(i), {})
                    need = tuple(k for k in phases[phase] if k not in have)
                    if need:
                        jobs.append((setting, i, need))
    print(f"{len(jobs)} jobs for {len(settings)} settings into {out}", flush=True)
    done_times: dict[tuple[str, tuple[str, ...]], list[float]] = {}
    n_done = [0]

    def record(job, res: dict) -> None:
        n_done[0] += 1
        setting, i, kinds = job
        if not res["ok"]:
            print(
                f"[{n_done[0]}/{len(jobs)}] {setting} #{i} {kinds}: ERROR {res['error']}",
                flush=True,
            )
            print(res.get("traceback", ""), file=sys.stderr, flush=True)
            return
        d = state[setting]
        d["records"].setdefault(str(i), {}).update(res["record"])
        write_json(setting_path(out, setting), d)
        wt = res["record"][f"wall_time:{','.join(kinds)}"]
        done_times.setdefault((SETTINGS[setting][0], kinds[-1:]), []).append(wt)
        # ETA: remaining jobs at the mean time of jobs of their model and last kind so far.
        mean_all = np.mean([t for ts in done_times.values() for t in ts])
        left = sum(
            np.mean(done_times.get((SETTINGS[s][0], k[-1:]), [mean_all]))
            for s, _, k in jobs[n_done[0] :]
        )
        print(
            f"[{n_done[0]}/{len(jobs)}] {setting} #{i} {','.join(kinds)}: {wt:.1f} s; "
            f"elapsed {time.perf_counter() - t_start:.0f} s, left ~{left / 60:.0f} min "
            f"(x 1/jobs)",
            flush=True,
        )

    def crashed(job, e: BaseException) -> dict:
        return {"ok": False, "error": f"worker failed: {type(e).__name__}: {e}"}

    if jobs:
        run_jobs(jobs, functools.partial(run_dataset, cfg=cfg), record, crashed, args.jobs)
    wall = time.perf_counter() - t_start

    text, _ = tables(out, settings, args.n_datasets)
    job_time = sum(
        v for s in settings for r in state[s]["records"].values() for k, v in r.items()
        if k.startswith("wall_time:")
    )  # fmt: skip
    steps = {c: cfg.steps(mc) for c, mc in MODEL_CASES.items()}
    cmd = sys.argv[1:] if argv is None else argv
    header = [
        f"Command: `python -m benchmarks.calibration {' '.join(cmd)}`",
        f"Date: {datetime.datetime.now().isoformat(timespec='minutes')}; machine: "
        f"{platform.machine()} {platform.system()}, {os.cpu_count()} CPUs; {_versions()}.",
        f"This invocation: {wall / 60:.1f} min wall, {len(jobs)} jobs, --jobs {args.jobs}. "
        f"Summed job time in the cache (all invocations): {job_time / 60:.1f} min.",
        f"Grid: MERL stride {STRIDE}, cut {CUT_DEG:g} degrees; LM: start {cfg.start}, "
        f"n_restarts={cfg.n_restarts}; "
        "posteriors: default walkers (max(32, 4 dim)), "
        + ", ".join(f"{c} {n} steps, burn {b}" for c, (n, b) in steps.items())
        + ".",
    ]
    if changed:
        header.append(
            "The model source file changed after these settings' caches were made (the "
            f"results are for the version then): {', '.join(changed)}."
        )
    md = (
        "# Interval calibration: `benchmarks/calibration.py`\n\n"
        + "\n".join(f"- {h}" for h in header)
        + "\n\n"
        + text
    )
    print(md)
    if args.md:
        args.md.parent.mkdir(parents=True, exist_ok=True)
        write_text(args.md, md)
        print(f"wrote {args.md}")


if __name__ == "__main__":
    main()
