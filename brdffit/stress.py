"""Numerical-stability stress suite: fits on synthetic data in hard regimes, from random starts.

A *case* is one model, one metric and one :class:`Regime`. For each case the truth is
drawn from the model's baseline parameters (:data:`ROLES`, jittered with the case's
seed) and changed as the regime says; the data are synthesised from it; then the model
is fitted once from the truth (the *reference*) and from ``n_starts`` seeded random
starts (``init=`` a random natural point, ``n_restarts=0``; the fit's own screen of
spread candidates still adds its starts, as it does in use, seeded with the start's
number so that the screen too differs from start to start).

**Recovery.** A start is recovered when its fit is finite, converged (``Status.CONVERGED``)
and its final objective ``J`` (``0.5 sum rho(r)^2``, what LM minimises: the metric's
residuals, robust ones when the regime fits with a robust loss, all at one robust scale)
lies within ``REL_TOL J_best + ABS_TOL J_0`` of the best ``J_best`` over the reference,
every start and the truth itself (``truth_objective``: a fit that ends above the truth's
own objective has missed the truth's basin, whatever the other fits did); ``J_0`` is the
objective of the zero BRDF (the data's own energy), so the floor only matters for
noise-free data, where ``J_best`` is ~0. Every other end is a
failure with its reason: the solver status (``MAX_STEPS``, with whether ``J`` was already
within the tolerance, ``SOLVER_FAILED``, ``NONFINITE``), ``wrong minimum`` (converged, but
``J`` above the tolerance), ``stalled next to the minimum`` (the same, within
``STALL_DISTANCE`` of the best point in the optimiser space: the descent stopped early),
``silent non-finite`` (a NaN or Inf in the loss or parameters of a fit that did not say
so: a bug), or the exception raised. A failure's *excess* is
``(J - J_best) / max(J_best, ABS_TOL J_0)``.

**Identifiable.** The recovery target applies to cases identifiable in principle. A case
is not when :data:`NOT_IDENTIFIABLE` says so, or when its data are corrupted (noise,
outliers) and the minimum of the truth's basin is not the lowest: such a case also gets
a ``local`` fit, a plain descent from the truth (``screen=0``), and when that converges
to a distinct minimum above the best, the corruption decides which of several minima is
lowest, and none of them is the material's (:func:`_optimum_moved`). The reference is
no test of that: its screen's starts can leave the basin. On noise-free data the truth
is an exact minimum, so a failed reference there stays a failure.

**Data.** Every regime gives exactly ``n_samples`` fitted samples (valid and inside the
cut), so one compiled fit serves every regime of a model and metric. Directions are
random in Rusinkiewicz coordinates with MERL's density (``theta_h = (pi/2) u^2``, ``u``,
``theta_d``, ``phi_d`` and ``phi_h`` uniform: 2.5% of the samples have ``theta_h < 1e-3``,
so a near-mirror peak is sampled) or, for the grazing regimes, each direction with
probability 0.8 in ``theta > 60`` degrees. Weights are the Monte Carlo solid-angle measure
``dwi dwo`` of each sample (the Ngan metric uses them).

**Roughness.** :data:`ROLES` names per model the parameter that sets the lobe width and
how it maps a roughness ``r`` (GGX/Beckmann ``alpha`` units): ``width`` (the parameter is
``r``), ``squared`` (``alpha = x^2``: ``x = sqrt(r)``; Brady's ``tan theta_h`` scale is
``beta^2`` too), ``exponent`` (Phong-type ``cos^n``: ``n = 2 / r^2``; near-mirror draws
``n`` log-uniformly in ``EXPONENT_RANGE``), ``sigma`` (Oren-Nayar's facet slope; no
specular lobe). A regime that has no meaning for a model (near-mirror Lambert) is
*not applicable*: it is listed, never run.

Results are one JSON file per case, ``<out>/<model>__<metric>__<regime>.json``, written
atomically: an interrupted run resumes and skips finished cases.
"""

from __future__ import annotations

import concurrent.futures as cf
import hashlib
import json
import math
import multiprocessing
import os
import time
import traceback
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from brdffit import enable_compilation_cache, metrics
from brdffit import models as registry
from brdffit.atomic import remove_temporaries, write_text
from brdffit.fit import fit
from brdffit.geometry import halfdiff_to_io
from brdffit.measurements import Measurements
from brdffit.metrics import get_metric, prepare
from brdffit.result import FitResult, nan_to_none
from brdffit.tables import render

N_STARTS = 20
N_SAMPLES = 2000
REL_TOL = 1e-6
ABS_TOL = 1e-10
NEAR_MIRROR = 1e-3
EXPONENT_RANGE = (1e4, 1e5)
DYNAMIC_RANGE = 1e7
RECOVERY_TARGET = 0.95
DEFAULT_METRICS = ("low_e2", "ngan")
MAX_STEPS = 512  # LM steps per descent: brdffit.fit's default
STALL_DISTANCE = 0.1  # optimiser-space distance under which a converged miss is a stall
START_U = 3.0  # random starts: u ~ U(-START_U, START_U) in each parameter's optimiser space


@dataclass(frozen=True)
class Regime:
    """One stress regime: how it changes the truth, the data and the fit.

    Fields: ``name``, ``description``; truth: ``roughness`` (set the lobe width to this
    roughness, ``alpha`` units; ``"near_mirror"`` also draws Phong-type exponents in
    :data:`EXPONENT_RANGE`), ``dynamic_range`` (scale the diffuse parameter so that the
    specular peak over the diffuse floor is this), ``at_bounds`` (albedo channels on
    their bounds), ``correlated`` (multi-lobe models, or a broad lobe); data:
    ``directions`` (``"rusinkiewicz"`` or ``"grazing"``), ``noise_mult`` (log-normal),
    ``missing`` (fraction of cells invalid), ``outliers`` (fraction of cells multiplied
    by ``outlier_factor``), ``float32`` (data made by the model evaluated in float32;
    the fit itself runs in float64, as :class:`Measurements` holds float64); fit:
    ``cut_deg`` and ``robust``.
    """

    name: str
    description: str
    roughness: float | None = None
    near_mirror: bool = False
    dynamic_range: float | None = None
    at_bounds: bool = False
    correlated: bool = False
    directions: str = "rusinkiewicz"
    cut_deg: float | None = 80.0
    noise_mult: float = 0.0
    missing: float = 0.0
    outliers: float = 0.0
    outlier_factor: float = 100.0
    robust: str | None = None
    float32: bool = False

    @property
    def needs_lobe(self) -> bool:
        """True when the regime changes a specular lobe (not applicable without one)."""
        return self.near_mirror or self.roughness is not None or self.dynamic_range is not None


REGIMES: dict[str, Regime] = {
    r.name: r
    for r in (
        Regime("baseline", "moderate roughness, noise-free, cut 80"),
        Regime(
            "near_mirror",
            f"roughness {NEAR_MIRROR:g}; Phong-type exponents log-uniform in "
            f"[{EXPONENT_RANGE[0]:g}, {EXPONENT_RANGE[1]:g}]",
            roughness=NEAR_MIRROR,
            near_mirror=True,
        ),
        Regime("fully_rough", "roughness 1 (exponents 2)", roughness=1.0),
        Regime(
            "dynamic_range",
            f"roughness 0.01 and diffuse scaled so that peak / diffuse floor = {DYNAMIC_RANGE:g}",
            roughness=0.01,
            dynamic_range=DYNAMIC_RANGE,
        ),
        Regime(
            "grazing_cut80",
            "80% of directions beyond 60 degrees, cut 80",
            directions="grazing",
        ),
        Regime(
            "grazing_nocut",
            "80% of directions beyond 60 degrees, no cut",
            directions="grazing",
            cut_deg=None,
        ),
        Regime("noise30", "30% multiplicative log-normal noise", noise_mult=0.3),
        Regime("missing_half", "half the cells invalid", missing=0.5),
        Regime("outliers", "1% of cells x100, plain least squares", outliers=0.01),
        Regime("outliers_huber", "1% of cells x100, Huber loss", outliers=0.01, robust="huber"),
        Regime(
            "at_bounds",
            "albedo channels on bounds: 1st RGB parameter [0] low and [2] high, 2nd [1] low",
            at_bounds=True,
        ),
        Regime(
            "correlated",
            "two lobes (Lafortune, Kurt); else a broad lobe (roughness 0.5) against the albedo",
            correlated=True,
        ),
        Regime("float32", "data from the model evaluated in float32", float32=True),
    )
}


@dataclass(frozen=True)
class Roles:
    """What the stress regimes need to know about one model.

    Fields: ``truth`` baseline parameters (natural units; others take defaults);
    ``rough`` the lobe-width parameter and ``kind`` its mapping (module docstring);
    ``diffuse`` the diffuse albedo parameter; ``freeze`` parameters frozen at the truth
    (not identifiable, with the reason, as declared in ``tests/cases*.py``);
    ``two_lobes`` (options, truth) for the correlated regime; ``floor_zero`` parameters
    set to 0 in the dynamic-range regime so that the diffuse parameter scales the diffuse
    term only (Disney's metallic and tint, Filament's metallic), and frozen there: with
    the base colour at 1e-5, metallic moves only F0, which ``specular``/``reflectance``
    also set, and the diffuse scale, which the base colour also sets (a ridge: the fits
    reached the minimum's cost along it and crawled); ``narrow`` parameters set when the
    lobe exponent exceeds 1e3 (Lafortune's ``cxy = -1``: with ``|cxy| > 1`` the lobe
    grows as ``|cxy|^n`` towards grazing, 1e1000 at ``n = 1e4``, far past the model's
    ``e^60`` cap; no material does that, and the capped model is flat in ``n``);
    ``alpha_floor`` the narrowest lobe (``alpha``) the model evaluates, and ``narrow``
    then applies at near-mirror too: Disney clamps each axis at ``alpha = 0.001``, so its
    near-mirror truth is isotropic with ``alpha = 1.1e-3``. At ``alpha = 1e-3`` with
    anisotropic 0.53 the narrow axis sat on the clamp and the specular lobe fixed only
    ``roughness^2 / aspect``; roughness was left to the diffuse retro-reflection term,
    no start (of 20, either metric) recovered, and the traced low_e2 fit crawled along
    that curved valley.
    """

    truth: dict
    rough: str | None = None
    kind: str | None = None
    diffuse: str | None = None
    freeze: dict = field(default_factory=dict)
    two_lobes: tuple[dict, dict] | None = None
    floor_zero: tuple[str, ...] = ()
    narrow: dict = field(default_factory=dict)
    alpha_floor: float = 0.0


_DISNEY_TINT = (
    "with metallic on, F0 = A + B C per channel: base_color, metallic, specular and "
    "specular_tint fix only C (1 - metallic), A and B (tests/cases_c.py)"
)

ROLES: dict[str, Roles] = {
    "ashikhmin_shirley": Roles(
        {"rd": [0.5, 0.3, 0.2], "rs": [0.1, 0.2, 0.3], "n": 300.0}, "n", "exponent", "rd"
    ),
    "blinn_phong": Roles(
        {"kd": [0.2, 0.3, 0.4], "ks": [0.3, 0.2, 0.1], "n": 120.0}, "n", "exponent", "kd"
    ),
    "brady": Roles(
        {"kd": [0.1, 0.2, 0.3], "ks": [2.0, 1.5, 1.0], "f0": 0.1, "beta": 0.4},
        "beta",
        "squared",
        "kd",
    ),
    "cook_torrance": Roles(
        {"kd": [0.1, 0.2, 0.3], "ks": [0.8, 0.7, 0.6], "f0": [0.9, 0.6, 0.3], "m": 0.2},
        "m",
        "width",
        "kd",
    ),
    "course_cook_torrance": Roles(
        {"albedo": [0.7, 0.4, 0.2], "f0": [0.04, 0.05, 0.06], "roughness": 0.4},
        "roughness",
        "squared",
        "albedo",
    ),
    "disney": Roles(
        {
            "base_color": [0.8, 0.5, 0.2],
            "metallic": 0.3,
            "subsurface": 0.4,
            "specular": 0.6,
            "roughness": 0.4,
            "specular_tint": 0.3,
            "anisotropic": 0.5,
            "sheen": 0.4,
            "sheen_tint": 0.6,
            "clearcoat": 0.5,
            "clearcoat_gloss": 0.7,
        },
        "roughness",
        "squared",
        "base_color",
        freeze={"specular_tint": _DISNEY_TINT},
        floor_zero=("metallic", "specular_tint"),
        narrow={"anisotropic": 0.0},
        alpha_floor=1e-3,
    ),
    "filament": Roles(
        {"base_color": [0.8, 0.5, 0.2], "metallic": 0.3, "reflectance": 0.6, "roughness": 0.4},
        "roughness",
        "squared",
        "base_color",
        floor_zero=("metallic",),
    ),
    "kurt": Roles(
        {"kd": [0.2, 0.1, 0.05], "ks_1": [0.6, 0.5, 0.4], "f0_1": 0.3, "m_1": 0.2, "alpha_1": 0.3},
        "m_1",
        "width",
        "kd",
        two_lobes=(
            {"n_lobes": 2},
            {
                "ks_1": [0.2, 0.1, 0.1],
                "f0_1": 0.5,
                "m_1": 0.4,
                "alpha_1": 0.8,
                "ks_2": [0.3, 0.4, 0.5],
                "m_2": 0.05,
                "alpha_2": 0.2,
            },
        ),
    ),
    "lafortune": Roles(
        {"kd": [0.1, 0.2, 0.3], "rho_1": [0.5, 0.4, 0.3], "cxy_1": -1.2, "n_1": 30.0},
        "n_1",
        "exponent",
        "kd",
        narrow={"cxy_1": -1.0},
        two_lobes=(
            {"n_lobes": 2},
            {
                "rho_1": [0.3, 0.2, 0.1],
                "cxy_1": -1.3,
                "n_1": 5.0,
                "rho_2": [0.2, 0.3, 0.4],
                "cxy_2": -1.0,
                "n_2": 300.0,
            },
        ),
    ),
    "lambert": Roles({"kd": [0.2, 0.5, 0.8]}, diffuse="kd"),
    "low": Roles(
        {"kd": [0.1, 0.2, 0.3], "ks": [0.5, 0.4, 0.3], "B": 500.0, "C": 1.3, "eta": 1.6},
        "B",
        "exponent",
        "kd",
    ),
    "nishino_lombardi": Roles(
        {"kd": [0.3, 0.2, 0.1], "f0": [0.9, 0.7, 0.5], "k": 3.0, "m": 200.0},
        "m",
        "exponent",
        "kd",
    ),
    "oren_nayar": Roles({"rho": [0.3, 0.5, 0.8], "sigma": 0.4}, "sigma", "sigma", "rho"),
    "phong": Roles(
        {"kd": [0.2, 0.3, 0.4], "ks": [0.3, 0.2, 0.1], "n": 80.0}, "n", "exponent", "kd"
    ),
    "walter": Roles(
        {"kd": [0.1, 0.2, 0.3], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}, "alpha", "width", "kd"
    ),
    "ward": Roles(
        {"kd": [0.2, 0.3, 0.4], "ks": [0.1, 0.1, 0.1], "alpha": 0.15}, "alpha", "width", "kd"
    ),
}

NOT_IDENTIFIABLE: dict[tuple[str, str], str] = {}
"""(model, regime) -> why the case has no unique optimum even in principle, declared;
:func:`score` also finds cases whose data move the optimum (:func:`_optimum_moved`)."""


# ------------------------------------------------------------------------------ truth


def fitter_version() -> str:
    """Short hash of the fitting code (``fit.py``, ``metrics.py``, ``parameters.py``):
    results from different fitters are not comparable."""

    h = hashlib.sha256()
    for name in ("fit.py", "metrics.py", "parameters.py"):
        h.update((Path(__file__).parent / name).read_bytes())
    return h.hexdigest()[:12]


def case_seed(model: str, regime: str) -> int:
    """Stable seed of a (model, regime) pair; the metrics of a pair share data and truth."""
    return zlib.crc32(f"{model}:{regime}".encode())


def not_applicable(model: str, regime: Regime) -> str | None:
    """Why ``regime`` cannot apply to ``model``, or None when it can."""
    roles = ROLES[model]
    if regime.needs_lobe and roles.kind is None:
        return "no roughness parameter"
    if regime.needs_lobe and roles.kind == "sigma" and regime.name != "fully_rough":
        return "no specular lobe (sigma is a diffuse facet slope)"
    if regime.correlated and roles.kind is None:
        return "no roughness to trade against the albedo"
    return None


def _clip(p, value, margin: float) -> np.ndarray:
    """``value`` kept ``margin`` of the range inside ``p``'s bounds (log parameters with
    a positive lower bound: of the range of ``log x``)."""
    lo, hi = p.bounds
    x = np.asarray(value, float)
    if p.transform == "log" and lo > 0 and math.isfinite(hi):
        a, b = math.log(lo), math.log(hi)
        return np.asarray(np.exp(np.clip(np.log(x), a + margin * (b - a), b - margin * (b - a))))
    if not math.isfinite(hi):
        return np.asarray(np.maximum(x, lo + margin * max(abs(lo), 1.0)))
    return np.asarray(np.clip(x, lo + margin * (hi - lo), hi - margin * (hi - lo)))


def _rough_value(kind: str, r: float) -> float:
    if kind == "width":
        return r
    if kind == "squared":
        return math.sqrt(r)
    if kind == "exponent":
        return 2.0 / (r * r)
    if kind == "sigma":
        return r
    raise ValueError(f"unknown roughness kind {kind!r}")


def _f_normal(model, params: dict) -> np.ndarray:
    """f at ``wi = wo = n`` (the specular peak of every isotropic lobe), RGB."""
    z = np.array([[0.0, 0.0, 1.0]])
    return np.asarray(model.eval(params, z, z), float)[0]


def _peak_to_floor(model, truth: dict, name: str) -> float:
    """Largest channel of ``f(n, n)`` with ``name`` at 0 over the largest channel it adds."""
    p = model.parameter(name)
    peak = _f_normal(model, {**truth, name: jnp.zeros(p.shape)})
    floor = _f_normal(model, truth) - peak
    return float(np.max(peak) / max(np.max(floor), 1e-300))


def _set_dynamic_range(model, truth: dict, name: str, ratio: float) -> tuple[dict, float]:
    """Scale the diffuse parameter ``name`` so that peak / floor = ``ratio`` at ``wi = wo = n``.

    Three fixed-point passes of :func:`_peak_to_floor` (exact for an additive diffuse
    term). Returns the truth and the ratio reached.
    """
    p = model.parameter(name)
    out = dict(truth)
    for _ in range(3):
        scale = _peak_to_floor(model, out, name) / ratio
        out[name] = jnp.asarray(np.clip(np.asarray(out[name]) * scale, p.bounds[0], p.bounds[1]))
    return out, _peak_to_floor(model, out, name)


@dataclass(frozen=True)
class CaseSpec:
    """A case's model, truth and fit settings (before data are made)."""

    model_name: str
    options: dict
    truth: dict
    freeze: dict
    notes: tuple[str, ...]
    seed: int

    def build(self):
        """The model with the case's options."""
        return registry.get(self.model_name, **self.options)


def case_spec(model_name: str, regime: Regime) -> CaseSpec:
    """The truth of (``model_name``, ``regime``): baseline jittered by the case seed, then
    the regime's changes. Raises ``ValueError`` if the regime does not apply."""

    reason = not_applicable(model_name, regime)
    if reason:
        raise ValueError(f"{regime.name} does not apply to {model_name}: {reason}")
    roles = ROLES[model_name]
    seed = case_seed(model_name, regime.name)
    rng = np.random.default_rng([seed, 1])
    options, base = {}, dict(roles.truth)
    rough_name = roles.rough
    notes: list[str] = []
    if regime.correlated and roles.two_lobes is not None:
        options, base = dict(roles.two_lobes[0]), dict(roles.two_lobes[1])
        rough_name = None
        notes.append(f"{options}")
    model = registry.get(model_name, **options)
    truth = {k: np.asarray(v, float) for k, v in model.defaults().items()}
    for k, v in base.items():
        truth[k] = np.broadcast_to(np.asarray(v, float), model.parameter(k).shape).copy()
    for p in model.parameters:  # jitter: +-15% (log and logit), +-0.1 (identity)
        if p.name in roles.freeze:
            continue
        x = truth[p.name]
        if p.transform == "identity":
            x = x + rng.uniform(-0.1, 0.1, p.shape)
        else:
            x = x * np.exp(rng.uniform(-0.15, 0.15, p.shape))
        truth[p.name] = _clip(p, x, 0.01)
    if regime.correlated and rough_name is not None:
        r = 0.15 if roles.kind == "sigma" else 0.5
        truth[rough_name] = np.asarray(_rough_value(roles.kind, r))
        notes.append(f"{rough_name} = {float(truth[rough_name]):.4g} (roughness {r:g})")
    if regime.roughness is not None and rough_name is not None:
        p = model.parameter(rough_name)
        if regime.near_mirror and roles.kind == "exponent":
            lo, hi = EXPONENT_RANGE
            value = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
        else:
            r = regime.roughness
            if r < 1.1 * roles.alpha_floor:  # on or below the clamp: 1.1 x, as for a bound
                r = 1.1 * roles.alpha_floor
                notes.append(f"alpha {regime.roughness:g} is on the model's clamp; {r:g} used")
            value = _rough_value(roles.kind, r)
        if value < p.bounds[0]:
            notes.append(f"{rough_name} {value:.4g} is below its bound; 1.1 x the bound used")
            value = 1.1 * p.bounds[0]
        value = min(value, p.bounds[1])
        if value == p.bounds[1]:
            notes.append(f"{rough_name} on its upper bound")
        truth[rough_name] = np.asarray(value)
        notes.append(f"{rough_name} = {value:.4g}")
    exponent_high = roles.kind == "exponent" and truth[rough_name] > 1e3 if rough_name else False
    if exponent_high or (regime.near_mirror and roles.alpha_floor > 0):
        why = "a narrow lobe that stays bounded" if exponent_high else "isotropic, above the clamp"
        for k, v in roles.narrow.items():
            truth[k] = np.asarray(v, float)
            notes.append(f"{k} = {v:g} ({why})")
    if regime.dynamic_range is not None:
        for name in roles.floor_zero:
            truth[name] = np.asarray(0.0)
        if roles.floor_zero:
            notes.append(f"{', '.join(roles.floor_zero)} = 0 (the base colour only diffuse)")
        jt = {k: jnp.asarray(v) for k, v in truth.items()}
        jt, achieved = _set_dynamic_range(model, jt, roles.diffuse, regime.dynamic_range)
        truth = {k: np.asarray(v, float) for k, v in jt.items()}
        notes.append(f"peak / diffuse floor = {achieved:.3g}")
    if regime.at_bounds:
        rgb = [p for p in model.parameters if p.shape == (3,) and p.name not in roles.freeze]
        if rgb:
            p = rgb[0]
            truth[p.name][0] = p.bounds[0]
            if math.isfinite(p.bounds[1]):
                truth[p.name][2] = p.bounds[1]
        if len(rgb) > 1:
            truth[rgb[1].name][1] = rgb[1].bounds[0]
        notes.append(", ".join(f"{p.name}={truth[p.name].tolist()}" for p in rgb[:2]))
    freeze = {k: truth[k] for k in roles.freeze if k in truth}
    if regime.dynamic_range is not None:
        freeze.update({k: truth[k] for k in roles.floor_zero})
    return CaseSpec(model_name, options, truth, freeze, tuple(notes), seed)


# ------------------------------------------------------------------------------ data


def sample_directions(
    kind: str, n: int, cut_deg: float | None, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exactly ``n`` pairs with both directions above the horizon and inside the cut.

    Returns ``(wi, wo, weights)``; ``weights`` is the Monte Carlo measure ``dwi dwo``
    (sr^2) of each pair: the measure over the sampling density, divided by the number of
    pairs drawn (rejected ones included), so they sum to about the measure of the kept
    region ((2 pi)^2 without a cut). Kinds: ``"rusinkiewicz"`` (MERL's density, module
    docstring) and ``"grazing"`` (each direction with probability 0.8 from
    ``cos theta`` uniform in [0, 0.5], else uniform on the hemisphere).
    """

    cmin = math.cos(math.radians(cut_deg)) if cut_deg is not None else 0.0
    kept_i, kept_o, kept_w, drawn = [], [], [], 0
    count = 0
    while count < n:
        m = 2 * n
        if kind == "rusinkiewicz":
            u = rng.uniform(0.0, 1.0, m)
            th = 0.5 * np.pi * u * u
            td = rng.uniform(0.0, 0.5 * np.pi, m)
            pd = rng.uniform(0.0, 2.0 * np.pi, m)
            ph = rng.uniform(0.0, 2.0 * np.pi, m)
            wi, wo = halfdiff_to_io(th, td, pd, ph)
            # dwi dwo = 4 cos td sin td sin th dth dtd dpd dph, dth = pi u du
            box = (0.5 * np.pi) * (2.0 * np.pi) ** 2
            w = 4.0 * np.cos(td) * np.sin(td) * np.sin(th) * np.pi * u * box
        elif kind == "grazing":

            def draw(m: int) -> tuple[np.ndarray, np.ndarray]:
                z = np.where(
                    rng.uniform(size=m) < 0.8,
                    rng.uniform(0.0, 0.5, m),
                    rng.uniform(0.0, 1.0, m),
                )
                phi = rng.uniform(0.0, 2.0 * np.pi, m)
                r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
                pdf = (0.8 * (z < 0.5) / 0.5 + 0.2) / (2.0 * np.pi)
                return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1), pdf

            (wi, pi_), (wo, po) = draw(m), draw(m)
            w = 1.0 / (pi_ * po)
        else:
            raise ValueError(f"unknown direction kind {kind!r}")
        ok = (wi[:, 2] > cmin) & (wo[:, 2] > cmin)
        take = np.flatnonzero(ok)[: n - count]
        drawn += (take[-1] + 1) if take.size and count + take.size == n else m
        kept_i.append(wi[take])
        kept_o.append(wo[take])
        kept_w.append(w[take])
        count += take.size
    wi, wo, w = (np.concatenate(a) for a in (kept_i, kept_o, kept_w))
    return wi, wo, w / drawn


def inject_outliers(
    values: np.ndarray, fraction: float, factor: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Multiply ``round(fraction * N)`` cells (all channels), drawn without replacement, by
    ``factor``. Returns the new values and the indices changed."""
    n = values.shape[0]
    idx = np.sort(rng.choice(n, size=int(round(fraction * n)), replace=False))
    out = np.array(values, float)
    out[idx] *= factor
    return out, idx


def make_data(spec: CaseSpec, regime: Regime, n_samples: int = N_SAMPLES):
    """Synthetic :class:`Measurements` of a case and a dict describing them.

    Exactly ``n_samples`` cells are valid and inside the regime's cut; with ``missing``
    the data hold ``n_samples / (1 - missing)`` cells, the others marked invalid.
    """

    model = spec.build()
    rng = np.random.default_rng([spec.seed, 0])
    n_cells = int(round(n_samples / (1.0 - regime.missing)))
    wi, wo, w = sample_directions(regime.directions, n_cells, regime.cut_deg, rng)
    dtype = np.dtype(np.float32 if regime.float32 else np.float64)
    f = np.array(
        model.eval(model.cast(spec.truth, dtype), jnp.asarray(wi, dtype), jnp.asarray(wo, dtype)),
        np.float64,
    )
    info: dict = {"n_cells": n_cells, "nonfinite_values": int(np.sum(~np.isfinite(f)))}
    if regime.noise_mult:
        f = f * np.exp(regime.noise_mult * rng.standard_normal(f.shape))
    valid = np.ones(n_cells, bool)
    if regime.missing:
        valid[rng.choice(n_cells, size=n_cells - n_samples, replace=False)] = False
    if regime.outliers:
        kept = np.flatnonzero(valid)
        bad, idx = inject_outliers(f[kept], regime.outliers, regime.outlier_factor, rng)
        f[kept] = bad
        info["n_outliers"] = int(idx.size)
    info["n_negative_values"] = int(np.sum(np.any(f < 0, axis=1)))
    data = Measurements.from_directions(
        wi, wo, f, weights=w, valid=valid, source=f"stress {spec.model_name} {regime.name}"
    )
    positive = f[data.valid][f[data.valid] > 0]
    info.update(
        n_valid=data.n_valid,
        f_max=float(np.max(f[data.valid])) if data.n_valid else float("nan"),
        f_min_positive=float(np.min(positive)) if positive.size else float("nan"),
    )
    return data, info


# ------------------------------------------------------------------------------ fits


def random_start(model, freeze: dict, rng: np.random.Generator) -> dict:
    """A random natural point: ``u ~ U(-START_U, START_U)`` in each free parameter's
    optimiser space (identity parameters: uniform in ``[-START_U, START_U]`` clipped to
    their bounds)."""

    out = {}
    for p in model.parameters:
        if p.name in freeze:
            continue
        u = rng.uniform(-START_U, START_U, p.shape)
        x = np.clip(np.asarray(p.to_natural(jnp.asarray(u)), float), p.bounds[0], p.bounds[1])
        out[p.name] = x
    return out


def case_start(model, spec: CaseSpec, index: int) -> dict:
    """The case's ``index``-th random start (seeded by the case and the index)."""
    return random_start(model, spec.freeze, np.random.default_rng([spec.seed, 2, index]))


@eqx.filter_jit
def _objective(model, metric, robust, params, prep, scale):
    return metrics.objective(metric, model.evaluate(params, prep.g), prep, robust, scale)


def objective(model, metric: str, robust: str | None, scale: float, params: dict, prep) -> float:
    """``0.5 sum rho(r)^2`` of the metric's residuals at ``params`` (natural units)."""
    p = {k: jnp.asarray(v, jnp.float64) for k, v in params.items()}
    return float(_objective(model, get_metric(metric), robust, p, prep, jnp.asarray(scale)))


def zero_objective(metric: str, robust: str | None, scale: float, prep) -> float:
    """The objective of the zero BRDF: the data's own energy (the tolerance floor's scale)."""
    zero = jnp.zeros_like(prep.values)
    return float(metrics.objective(get_metric(metric), zero, prep, robust, jnp.asarray(scale)))


def _finite_params(params: dict) -> bool:
    return all(np.all(np.isfinite(np.asarray(v, float))) for v in params.values())


def case_fit(
    model,
    data,
    metric: str,
    regime: Regime,
    spec: CaseSpec,
    init: dict,
    scale=None,
    max_steps: int = MAX_STEPS,
    seed: int = 0,
    screen: int | None = None,
):
    """The fit the suite runs from ``init`` (``seed`` seeds its screen; ``scale`` the
    robust scale, ``None`` to estimate it; ``screen=0`` a plain descent from ``init``,
    ``None`` the fit's default screen); returns the :class:`FitResult`."""
    return fit(
        model,
        data,
        metric,
        init=init,
        freeze=spec.freeze or None,
        cut_deg=regime.cut_deg,
        n_restarts=0,
        **({} if screen is None else {"screen": screen}),
        seed=seed,
        robust=regime.robust,
        robust_scale=scale,
        max_steps=max_steps,
        throw=False,
    )


def _one_fit(run: Callable[[], FitResult]) -> tuple[dict, FitResult | None]:
    """Run one fit, ``run()`` (a :func:`case_fit` call), and record it; returns (record
    dict, FitResult or None when it raised)."""

    t0 = time.perf_counter()
    try:
        r = run()
    except Exception as e:  # recorded as a failure, the suite goes on
        return {
            "status": "EXCEPTION",
            "error": f"{type(e).__name__}: {e}",
            "traceback": traceback.format_exc(limit=4),
            "wall_time": time.perf_counter() - t0,
            "n_steps": None,
            "loss": None,
            "finite": False,
        }, None
    finite = (
        math.isfinite(r.loss)
        and _finite_params(r.params)
        and all(math.isfinite(v) for v in r.losses.values())
    )
    return {
        "status": r.status.name,
        "loss": r.loss,
        "n_steps": int(r.n_steps),
        "wall_time": float(r.wall_time),
        "finite": finite,
        "at_bound": list(r.at_bound),
        "condition_number": r.condition_number,
        "params": {k: np.asarray(v, float).tolist() for k, v in r.params.items()},
        "stderr_nonfinite": [
            k for k, v in (r.stderr or {}).items() if not np.all(np.isfinite(np.asarray(v)))
        ],
        "errors_reason": r.errors_reason,
    }, r


def _classify(rec: dict, best: float, tol: float) -> tuple[bool, str | None]:
    """(recovered, failure reason) of one fit record with its objective ``J``."""
    status = rec["status"]
    if status == "EXCEPTION":
        return False, f"exception {rec['error'].split(':')[0]}"
    j = rec.get("objective")
    if status != "NONFINITE" and (not rec["finite"] or j is None or not math.isfinite(j)):
        return False, "silent non-finite"
    if status == "NONFINITE":
        return False, "NONFINITE"
    if status != "CONVERGED":
        at_min = j is not None and j - best <= tol
        return False, f"{status} ({'at the minimum' if at_min else 'short of it'})"
    if j - best > tol:
        return False, "wrong minimum"
    return True, None


def _u_distance(model, freeze, a: dict, b: dict) -> float:
    """Largest difference of the free scalars of ``a`` and ``b`` in the optimiser space."""

    d = 0.0
    for p in model.parameters:
        if p.name in freeze:
            continue
        ua, ub = (np.asarray(p.to_unconstrained(jnp.asarray(x[p.name], float))) for x in (a, b))
        d = max(d, float(np.max(np.abs(ua - ub))))
    return d


def run_case(
    model_name: str,
    metric: str,
    regime: Regime | str,
    *,
    n_starts: int = N_STARTS,
    n_samples: int = N_SAMPLES,
    max_steps: int = MAX_STEPS,
) -> dict:
    """Run one case (reference fit + ``n_starts`` random starts); returns its JSON dict."""

    regime = REGIMES[regime] if isinstance(regime, str) else regime
    out: dict = {
        "model": model_name,
        "metric": metric,
        "regime": regime.name,
        "description": regime.description,
        "settings": {"n_starts": n_starts, "n_samples": n_samples, "rel_tol": REL_TOL,
                     "abs_tol": ABS_TOL, "cut_deg": regime.cut_deg, "robust": regime.robust,
                     "max_steps": max_steps, "fitter": fitter_version()},
    }  # fmt: skip
    reason = not_applicable(model_name, regime)
    if reason:
        out.update(applicable=False, reason=reason, identifiable=None)
        return out
    t_case = time.perf_counter()
    spec = case_spec(model_name, regime)
    model = spec.build()
    data, info = make_data(spec, regime, n_samples)
    prep = prepare(data, get_metric(metric), cut_deg=regime.cut_deg)
    out.update(
        applicable=True,
        options=spec.options,
        truth={k: np.asarray(v).tolist() for k, v in spec.truth.items()},
        frozen=sorted(spec.freeze),
        notes=list(spec.notes),
        data=info,
        n_fitted=prep.n,
    )
    free_truth = {k: v for k, v in spec.truth.items() if k not in spec.freeze}

    def one_fit(init: dict, scale, **kw) -> tuple[dict, FitResult | None]:
        return _one_fit(
            lambda: case_fit(model, data, metric, regime, spec, init, scale, max_steps, **kw)
        )

    ref, ref_result = one_fit(free_truth, None)
    scale = ref_result.robust_scale if ref_result is not None else None
    robust_scale = 1.0 if scale is None else float(scale)
    starts = []
    for i in range(n_starts):
        init = case_start(model, spec, i)
        rec, _ = one_fit(init, scale, seed=i + 1)
        rec["seed"] = i
        rec["init"] = {k: np.asarray(v).tolist() for k, v in init.items()}
        starts.append(rec)
    # the truth's basin: a plain descent from the truth, no screen
    local = one_fit(free_truth, scale, screen=0)[0] if corrupts(regime) else None
    for rec in [ref, *starts, *([local] if local else [])]:
        rec["objective"] = (
            objective(model, metric, regime.robust, robust_scale, rec["params"], prep)
            if rec.get("params") is not None and rec["finite"]
            else None
        )
    j0 = zero_objective(metric, regime.robust, robust_scale, prep)
    jt = objective(model, metric, regime.robust, robust_scale, spec.truth, prep)
    out.update(robust_scale=scale, zero_objective=j0, truth_objective=jt, reference=ref,
               starts=starts, **({"local": local} if local else {}))  # fmt: skip
    score(out, model)
    out["case_time"] = time.perf_counter() - t_case
    return out


def score(case: dict, model=None) -> dict:
    """Classify the fits of a case dict (``reference``, ``starts`` with their objectives,
    ``zero_objective``) and fill in the recovery fields; returns ``case``.

    Works on a stored case too (the tolerances are this module's): the model is built
    from ``case["model"]`` and ``case["options"]`` when not given.
    """
    if model is None:
        model = registry.get(case["model"], **case.get("options", {}))
    ref, starts, j0 = case["reference"], case["starts"], case["zero_objective"]
    local = case.get("local")
    freeze = set(case.get("frozen", ()))
    fits = [ref, *starts, *([local] if local else [])]
    finite = [r for r in fits if r.get("objective") is not None and math.isfinite(r["objective"])]
    jt = case.get("truth_objective")
    if jt is not None and math.isfinite(jt):  # the truth itself bounds the best minimum
        finite.append({"objective": jt, "params": case["truth"]})
    best_rec = min(finite, key=lambda r: r["objective"]) if finite else None
    best = best_rec["objective"] if best_rec else float("nan")
    tol = REL_TOL * abs(best) + ABS_TOL * j0 if best_rec else float("nan")
    failures: dict[str, int] = {}
    excess: dict[str, list[float]] = {}
    for rec in fits:
        rec.setdefault("objective", None)
        ok, why = _classify(rec, best, tol)
        j = rec["objective"]
        if j is not None and math.isfinite(best):
            rec["excess"] = (j - best) / max(abs(best), ABS_TOL * j0, 1e-300)
        if why == "wrong minimum" and best_rec is not None:
            # converged above the tolerance: next to the best point (a stall) or elsewhere
            rec["u_distance"] = _u_distance(model, freeze, rec["params"], best_rec["params"])
            if rec["u_distance"] < STALL_DISTANCE:
                why = "stalled next to the minimum"
        rec["recovered"], rec["reason"] = ok, why
        if rec is not ref and rec is not local and why is not None:
            failures[why] = failures.get(why, 0) + 1
            if rec.get("excess") is not None:
                excess.setdefault(why, []).append(rec["excess"])
    declared = NOT_IDENTIFIABLE.get((case["model"], case["regime"]))
    reason = declared or _optimum_moved(REGIMES.get(case["regime"]), local or ref, jt)
    case.update(identifiable=reason is None, not_identifiable_reason=reason)
    n_ok = sum(r["recovered"] for r in starts)
    steps = [r["n_steps"] for r in starts if r.get("n_steps") is not None]
    times = [r["wall_time"] for r in starts]
    case.update(
        best_objective=best,
        tolerance=tol,
        recovery=n_ok / len(starts) if starts else float("nan"),
        n_recovered=n_ok,
        median_steps=float(np.median(steps)) if steps else None,
        median_time=float(np.median(times)) if times else None,
        failures=failures,
        failure_excess={k: float(np.median(v)) for k, v in excess.items()},
        n_nonfinite=sum(not r["finite"] and r["status"] != "EXCEPTION" for r in fits),
        condition_number=ref.get("condition_number"),
    )
    return case


def corrupts(regime: Regime) -> bool:
    """True when the regime corrupts the data (noise, outliers): the truth is then no
    longer an exact minimum, and the suite also descends plainly from it."""
    return bool(regime.noise_mult or regime.outliers)


def _optimum_moved(
    regime: Regime | None, ref: dict, truth_objective: float | None = None
) -> str | None:
    """Why a case is not identifiable from its data, or None: in a regime that corrupts
    the data (noise, outliers), the descent from the truth converged to a distinct
    minimum (a wrong minimum, not a stall) that some start beat.

    ``ref`` is the case's ``local`` fit, a plain descent from the truth with no screen:
    its end is the minimum of the truth's basin. (Cases stored before that fit existed
    pass their reference, whose own screen can leave the basin.) When a start beats it
    elsewhere, the lowest minimum is not the truth's: the corruption decides which of
    several minima is lowest, and reaching it is a search among minima that say nothing
    about the material. On noise-free data the truth is an exact minimum, so there a
    failed reference stays the fitter's failure. A descent that ends above
    ``truth_objective``, the objective at the truth itself, did not descend: that too
    stays the fitter's failure, whatever the data.
    """
    if regime is None or not corrupts(regime):
        return None
    if ref.get("status") != "CONVERGED" or ref.get("reason") != "wrong minimum":
        return None
    if truth_objective is not None and not ref["objective"] <= truth_objective:
        return None
    what = "outliers" if regime.outliers else "noise"
    return (
        f"the {what} move the lowest minimum out of the truth's basin: the descent from "
        f"the truth converges {ref.get('excess', float('nan')):.1e} (relative) above it, "
        f"{ref.get('u_distance', float('nan')):.2g} away in the optimiser space"
    )


def rescore(out: str | os.PathLike[str]) -> int:
    """Re-classify every finished case in folder ``out`` with the current tolerances
    (no refit); rewrites the files atomically and returns how many it rescored."""
    n = 0
    for p in sorted(Path(out).glob("*__*__*.json")):
        if p.name.endswith(".error.json") or not is_finished(p):
            continue
        d = json.loads(p.read_text())
        if d.get("applicable"):
            write_case(p, score(d))
            n += 1
    return n


# ------------------------------------------------------------------------------ files


def case_path(out: str | os.PathLike[str], model: str, metric: str, regime: str) -> Path:
    """``<out>/<model>__<metric>__<regime>.json``."""
    return Path(out) / f"{model}__{metric}__{regime}.json"


def write_case(path: str | os.PathLike[str], result: dict) -> None:
    """Write one case's JSON atomically (NaN and Inf as null)."""

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(nan_to_none(result), indent=1, allow_nan=False))


def is_finished(path: Path) -> bool:
    """True when ``path`` parses and holds a finished case."""
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return False
    return "applicable" in d and (not d["applicable"] or "recovery" in d)


def load_results(out: str | os.PathLike[str]) -> list[dict]:
    """Every finished case of folder ``out``, sorted by model, metric and regime order."""
    order = {name: i for i, name in enumerate(REGIMES)}
    rows = []
    for p in sorted(Path(out).glob("*__*__*.json")):
        if is_finished(p):
            rows.append(json.loads(p.read_text()))
    return sorted(rows, key=lambda d: (d["model"], d["metric"], order.get(d["regime"], 99)))


# ------------------------------------------------------------------------------ suite


def _run_group(
    model: str,
    metric: str,
    regimes: Sequence[str],
    out: str,
    n_starts: int,
    n_samples: int,
    max_steps: int = MAX_STEPS,
    report: Callable[[dict], None] | None = None,
) -> list[dict]:
    """Run (and write) the cases of one model and metric in order; one process, one compile.

    ``report`` is called with each case's status as soon as it is written."""
    done: list[dict] = []
    report = report or done.append
    for name in regimes:
        path = case_path(out, model, metric, name)
        if is_finished(path):
            continue
        try:
            res = run_case(
                model, metric, name, n_starts=n_starts, n_samples=n_samples, max_steps=max_steps
            )
        except Exception as e:  # the case is recorded as an error and retried next time
            res = {
                "model": model,
                "metric": metric,
                "regime": name,
                "error": f"{type(e).__name__}: {e}",
                "traceback": traceback.format_exc(),
            }
            write_case(path.with_suffix(".error.json"), res)
            report({"case": path.name, "ok": False, "error": res["error"]})
            continue
        write_case(path, res)
        path.with_suffix(".error.json").unlink(missing_ok=True)
        report({"case": path.name, "ok": True, "recovery": res.get("recovery")})
    return done


def run_suite(
    out: str | os.PathLike[str],
    models: Sequence[str],
    metrics: Sequence[str] = DEFAULT_METRICS,
    regimes: Sequence[str] = tuple(REGIMES),
    *,
    n_starts: int = N_STARTS,
    n_samples: int = N_SAMPLES,
    max_steps: int = MAX_STEPS,
    jobs: int = 1,
    progress: Callable[[str], None] | None = None,
) -> int:
    """Run every unfinished case of ``models x metrics x regimes`` into folder ``out``.

    Cases of one model and metric run in one process, in order (one compile serves
    them). ``jobs`` > 1 runs such groups in worker processes started with ``spawn``
    (JAX is not fork-safe). Returns the number of cases run.
    """

    for m in models:
        registry.get(m)
        if m not in ROLES:
            raise ValueError(f"model {m!r} has no stress roles in brdffit.stress.ROLES")
    for m in metrics:
        get_metric(m)
    unknown = [r for r in regimes if r not in REGIMES]
    if unknown:
        raise ValueError(f"unknown regime(s) {unknown}; known: {', '.join(REGIMES)}")
    Path(out).mkdir(parents=True, exist_ok=True)
    remove_temporaries(out)
    groups = [
        (mo, me, [r for r in regimes if not is_finished(case_path(out, mo, me, r))])
        for mo in models
        for me in metrics
    ]
    groups = [g for g in groups if g[2]]
    say = progress or (lambda s: None)
    n = 0

    def report(d: dict) -> None:
        nonlocal n
        n += 1
        say(_progress_line(d))

    if jobs <= 1:
        for mo, me, rs in groups:
            _run_group(mo, me, rs, str(out), n_starts, n_samples, max_steps, report)
        return n
    ctx = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(jobs, mp_context=ctx, initializer=enable_compilation_cache) as pool:
        futures = {
            pool.submit(_run_group, mo, me, rs, str(out), n_starts, n_samples, max_steps): (mo, me)
            for mo, me, rs in groups
        }
        for fut in cf.as_completed(futures):
            try:
                for d in fut.result():
                    report(d)
            except Exception as e:  # a dead worker: its unfinished cases rerun next time
                say(f"{futures[fut]}: worker failed: {type(e).__name__}: {e}")
    return n


def _progress_line(d: dict) -> str:
    if not d["ok"]:
        return f"{d['case']}: ERROR {d['error']}"
    rec = d.get("recovery")
    return f"{d['case']}: " + ("not applicable" if rec is None else f"recovery {100 * rec:.0f}%")


# ------------------------------------------------------------------------------ table


def _failures_cell(d: dict) -> str:
    parts = []
    data, n = d.get("data") or {}, d.get("settings", {}).get("n_samples")
    if data.get("nonfinite_values"):
        parts.append(f"data: {data['nonfinite_values']} non-finite values")
    if n is not None and d.get("n_fitted") is not None and d["n_fitted"] < n:
        parts.append(f"data: {d['n_fitted']} of {n} samples fitted")
    ref = d.get("reference") or {}
    if ref and not ref.get("recovered", True):
        parts.append(f"reference: {ref.get('reason')}")
    for why, k in sorted((d.get("failures") or {}).items(), key=lambda kv: -kv[1]):
        exc = (d.get("failure_excess") or {}).get(why)
        parts.append(f"{k}x {why}" + ("" if exc is None else f" (excess {exc:.1e})"))
    return "; ".join(parts)


def _fmt(x: float | None, spec: str) -> str:
    return "" if x is None else format(x, spec)


def format_table(rows: Sequence[dict]) -> str:
    """The Markdown table of case results (:func:`load_results`)."""
    head = ["model", "metric", "regime", "identifiable", "recovery %", "median steps",
            "median time (s)", "cond (ref)", "failures"]  # fmt: skip
    body = []
    for d in rows:
        if not d.get("applicable", False):
            cells = [d["model"], d["metric"], d["regime"], "", "n/a", "", "", "",
                     f"not applicable: {d.get('reason', '')}"]  # fmt: skip
        else:
            cond = d.get("condition_number")
            cells = [
                d["model"],
                d["metric"],
                d["regime"],
                "yes" if d["identifiable"] else "no",
                f"{100 * d['recovery']:.0f} ({d['n_recovered']}/{len(d['starts'])})",
                _fmt(d.get("median_steps"), ".0f"),
                _fmt(d.get("median_time"), ".2f"),
                "" if cond is None else f"{cond:.1e}",
                _failures_cell(d),
            ]
        body.append(cells)
    return render(head, body, "markdown").rstrip("\n")


def format_matrix(rows: Sequence[dict]) -> str:
    """Recovery % per model (rows) and regime (columns), one Markdown table per metric.

    A cell is the recovery in percent, ``n/a`` for a case that does not apply, ``NI``
    appended for a case that is not identifiable, and empty for a case not run.
    """
    by_key = {(d["model"], d["metric"], d["regime"]): d for d in rows}
    regimes = [r for r in REGIMES if any(d["regime"] == r for d in rows)]
    blocks = []
    for metric in dict.fromkeys(d["metric"] for d in rows):
        body = []
        for model in sorted({d["model"] for d in rows if d["metric"] == metric}):
            cells = [model]
            for regime in regimes:
                d = by_key.get((model, metric, regime))
                if d is None:
                    cells.append("")
                elif not d.get("applicable", False):
                    cells.append("n/a")
                else:
                    ni = "" if d.get("identifiable") else " NI"
                    cells.append(f"{100 * d['recovery']:.0f}{ni}")
            body.append(cells)
        blocks.append(f"{metric}:\n\n" + render(["model", *regimes], body, "markdown"))
    return "\n".join(blocks).rstrip("\n")


def summary(rows: Sequence[dict]) -> str:
    """One line: cases run, not applicable, identifiable ones (the others named), those
    under the recovery target, fits that ended non-finite (and whether any did so
    silently)."""
    run = [d for d in rows if d.get("applicable")]
    ident = [d for d in run if d.get("identifiable")]
    not_ident = [
        f"{d['model']}/{d['metric']}/{d['regime']}" for d in run if not d.get("identifiable")
    ]
    under = [d for d in ident if d["recovery"] < RECOVERY_TARGET]
    nonfinite = sum(d.get("n_nonfinite", 0) for d in run)
    silent = sum((d.get("failures") or {}).get("silent non-finite", 0) for d in run)
    if len(under) <= 12:
        names = ", ".join(f"{d['model']}/{d['metric']}/{d['regime']}" for d in under)
    else:
        per_model: dict[str, int] = {}
        for d in under:
            per_model[d["model"]] = per_model.get(d["model"], 0) + 1
        names = "by model: " + ", ".join(f"{k} {v}" for k, v in per_model.items())
    return (
        f"{len(rows)} cases: {len(run)} run, {len(rows) - len(run)} not applicable; "
        f"{len(ident)} identifiable"
        + (f" ({len(not_ident)} not: {', '.join(not_ident)})" if not_ident else "")
        + f", {len(under)} under {100 * RECOVERY_TARGET:.0f}% recovery"
        + (f" ({names})" if names else "")
        + f"; {nonfinite} non-finite fits ({silent} silent)"
    )
