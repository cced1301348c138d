"""A case's truth, data and random starts: what the suite fits."""

from __future__ import annotations

import hashlib
import math
import zlib
from dataclasses import dataclass
from pathlib import Path

import jax.numpy as jnp
import numpy as np

import brdffit
from brdffit import models as registry
from brdffit.core.geometry import halfdiff_to_io
from brdffit.core.measurements import Measurements

from .regimes import EXPONENT_RANGE, N_SAMPLES, ROLES, START_U, Regime

# ------------------------------------------------------------------------------ truth


FITTER_FILES = (
    "engine/fit.py",
    "engine/batch.py",
    "engine/settings.py",
    "engine/lm.py",
    "engine/starts.py",
    "engine/objective.py",
    "engine/metrics.py",
    "core/parameters.py",
)


def fitter_version() -> str:
    """Short hash of the fitting code (:data:`FITTER_FILES` of the brdffit package):
    results from different fitters are not comparable."""

    h = hashlib.sha256()
    for name in FITTER_FILES:
        h.update((Path(brdffit.__file__).parent / name).read_bytes())
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
