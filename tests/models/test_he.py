"""He et al. 1991 as bbm's NganHe (``models/he.py``) against independent checks.

* The 40-digit transcription of the paper and bbm's ``he.h`` (``tests/references_he.py``) at
  published Ngan et al. 2005 fits (bbm ``fits/ngan_he.fit``: smooth to rough, tau 4 to 103 um)
  and at random parameters, on random, near-mirror and extreme direction pairs.
* bbm itself (``benchmarks/published/bbm.py``, the ``bbm_eval`` binary) on the published
  lines, where the binary is built. bbm's ``NganHe`` is ``scaledmodel<ndf_sampler<he_base<...>>>``:
  ``ndf_sampler`` passes ``eval`` through (``using BSDFMODEL::eval``) and replaces only
  ``sample`` and ``pdf``, so its values are ``albedo * he_base::eval``.
* Reciprocity, finite values and forward- and reverse-mode derivatives at grazing angles and
  at the bounds, the published values inside the bounds, and (slow) a fit recovering its
  own parameters.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import Measurements, fit, models
from brdffit.core.geometry import halfdiff_to_io
from brdffit.models.check import check_params, extreme_pairs
from tests.helpers import params_at_bounds, random_pairs, random_params
from tests.references_he import reference

MODEL = models.get("he")
EVAL = jax.jit(MODEL.eval)
FIT_FILE = Path(__file__).parents[2] / "benchmarks" / "published" / "fits" / "ngan_he.fit"

# Lines of bbm fits/ngan_he.fit (Ngan et al. 2005), from smooth (sigma 0.01 um) to rough
# (sigma 8.74 um, where min g > 19 and only the rough limit is summed), tau 4 to 103 um.
PUBLISHED = [
    "specular-red-phenolic = Aggregate(Lambertian(albedo = [0.3, 0.0299, 0.00522]), "
    "NganHe(albedo = [25.8, 20.7, 14.1], autocorrelation = 28.0, roughness = 0.01, eta = 1.26))",
    "blue-acrylic = Aggregate(Lambertian(albedo = [0.0147, 0.0334, 0.0641]), "
    "NganHe(albedo = [2.93, 1.92, 1.17], autocorrelation = 28.7, roughness = 0.063, eta = 1.08))",
    "chrome-steel = Aggregate(Lambertian(albedo = [0.0316, 0.0275, 0.0229]), "
    "NganHe(albedo = [0.0818, 0.0601, 0.0298], autocorrelation = 103.0, "
    "roughness = 0.384, eta = 9.1))",
    "alum-bronze = Aggregate(Lambertian(albedo = [0.0866, 0.0589, 0.0292]), "
    "NganHe(albedo = [0.165, 0.0994, 0.0532], autocorrelation = 24.0, "
    "roughness = 0.514, eta = 2.33))",
    "yellow-plastic = Aggregate(Lambertian(albedo = [0.245, 0.182, 0.0229]), "
    "NganHe(albedo = [0.604, 0.495, 0.301], autocorrelation = 4.0, roughness = 0.697, eta = 1.31))",
    "green-fabric = Aggregate(Lambertian(albedo = [0.0389, 0.0275, 0.0223]), "
    "NganHe(albedo = [2.43, 2.9, 2.27], autocorrelation = 18.9, roughness = 8.74, eta = 1.19))",
]
# Extremes over all 86 lines of the file (checked against the file itself below when present).
PUBLISHED_RANGE = {
    "kd": (0.0, 0.413),
    "ks": (0.00338, 1.96e9),
    "sigma": (0.01, 8.74),
    "tau": (3.97, 103.0),
    "eta": (1.0, 15.0),
}
ATOL = 1e-280
"""Below this (1/sr) float64 is near its underflow and bbm's products of subnormal numbers
lose their digits: not scored (as ``tests/models/test_precision.py``)."""


def _vector(text: str) -> np.ndarray:
    return np.array([float(x) for x in text.split(",")])


def parse(line: str) -> tuple[str, str, dict[str, np.ndarray]]:
    """(material, bbm expression, our natural parameters) of one fit-file line."""
    material, _, expression = (s.strip() for s in line.partition("="))
    kd = re.search(r"Lambertian\(albedo = \[([^\]]*)\]", expression).group(1)
    he = re.search(r"NganHe\((.*)\)\)\s*$", expression).group(1)
    ks = re.search(r"albedo = \[([^\]]*)\]", he).group(1)

    def scalar(key: str) -> np.ndarray:
        return np.asarray(float(re.search(rf"{key} = ([-+0-9.eE]+)", he).group(1)))

    params = {
        "kd": _vector(kd),
        "ks": _vector(ks),
        "sigma": scalar("roughness"),
        "tau": scalar("autocorrelation"),
        "eta": scalar("eta"),
    }
    return material, expression, params


def all_published() -> list[str]:
    """Every line of the fit file where the benchmark folder has it, else :data:`PUBLISHED`."""
    if FIT_FILE.is_file():
        return [ln for ln in FIT_FILE.read_text().splitlines() if "NganHe(" in ln]
    return PUBLISHED


def near_mirror_pairs(seed: int, n: int, spread: float) -> tuple[np.ndarray, np.ndarray]:
    """``n`` pairs with ``wo`` within ~``spread`` rad of the mirror direction of ``wi``."""
    rng = np.random.default_rng(seed)
    wi, _ = random_pairs(seed, n)
    wo = wi * np.array([-1.0, -1.0, 1.0]) + rng.normal(0.0, spread, (n, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 1e-3
    return wi, wo / np.linalg.norm(wo, axis=1, keepdims=True)


def directions() -> tuple[np.ndarray, np.ndarray]:
    """Extreme pairs, 12 random pairs and 12 near-mirror pairs (spreads 1e-3 to 0.05 rad)."""
    sets = [extreme_pairs(), random_pairs(11, 12)]
    sets += [near_mirror_pairs(s, 4, spread) for s, spread in enumerate((1e-3, 1e-2, 5e-2))]
    return np.concatenate([w for w, _ in sets]), np.concatenate([w for _, w in sets])


def relative_error(ours: np.ndarray, ref: np.ndarray, floor: float = ATOL) -> np.ndarray:
    """``|ours - ref| / |ref|`` where ``|ref| > floor``; below it ``|ours - ref| / floor``
    capped at 1 (both below the floor: 0)."""
    seen = np.abs(ref) > floor
    scale = np.where(seen, np.abs(ref), floor)
    return np.where(seen, np.abs(ours - ref) / scale, np.minimum(np.abs(ours - ref) / floor, 1.0))


def test_published_values_lie_inside_the_bounds():
    lines = all_published()
    seen: dict[str, list[float]] = {k: [] for k in PUBLISHED_RANGE}
    for line in lines:
        _, _, params = parse(line)
        for p in MODEL.parameters:
            p.check_value(params[p.name])  # raises outside the bounds
            seen[p.name] += list(np.ravel(params[p.name]))
    for name, (lo, hi) in PUBLISHED_RANGE.items():
        p = MODEL.parameter(name)
        assert p.bounds[0] <= lo and hi <= p.bounds[1], name
        if len(lines) == 86:  # the whole file: its extremes are the table above
            assert (min(seen[name]), max(seen[name])) == (lo, hi), name


@pytest.mark.parametrize("line", PUBLISHED, ids=[ln.split(" ")[0] for ln in PUBLISHED])
def test_matches_reference_at_published_fits(line):
    _, _, params = parse(line)
    wi, wo = directions()
    lobe = params | {"kd": np.zeros(3)}  # the He term alone: Lambert would hide its tails
    ours = np.asarray(EVAL(lobe, wi, wo))
    ref = reference(MODEL, lobe, wi, wo).astype(float)
    err = relative_error(ours, ref)
    print(f"{line.split(' ')[0]}: worst relative error {err.max():.2e}, max f {ref.max():.3g}")
    # a = pi^2 tau^2 v_xy^2 / lambda^2 reaches 2e6 at tau = 103 um: its rounding enters
    # exp(-a/m) as ~a eps / m; measured 1e-10 at worst (chrome-steel)
    assert err.max() < 1e-9


@pytest.mark.parametrize("seed", range(4))
def test_matches_reference_at_random_parameters(seed):
    params = {
        k: np.asarray(v) for k, v in random_params(MODEL, np.random.default_rng(seed)).items()
    }
    wi, wo = directions()
    ours = np.asarray(EVAL(params, wi, wo))
    ref = reference(MODEL, params, wi, wo).astype(float)
    err = relative_error(ours, ref)
    print(f"seed {seed}: worst relative error {err.max():.2e}")
    assert err.max() < 1e-9


def test_reciprocity():
    rng = np.random.default_rng(5)
    lines = [parse(ln)[2] for ln in PUBLISHED]
    for params in lines + [random_params(MODEL, rng) for _ in range(4)]:
        wi, wo = random_pairs(int(rng.integers(1 << 30)), 128)
        mi, mo = near_mirror_pairs(int(rng.integers(1 << 30)), 64, 0.02)
        wi, wo = np.concatenate([wi, mi]), np.concatenate([wo, mo])
        a, b = np.asarray(EVAL(params, wi, wo)), np.asarray(EVAL(params, wo, wi))
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("which", ["defaults", "low", "high"])
@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_finite_values_and_gradients_at_extremes(which, dtype):
    params = MODEL.defaults() if which == "defaults" else params_at_bounds(MODEL, which)
    row = check_params(MODEL, params, dtype, which)
    assert row.passed, row.note


def _unflatten(x: jax.Array) -> dict:
    out, i = {}, 0
    for p in MODEL.parameters:
        k = math.prod(p.shape)
        out[p.name] = x[i : i + k].reshape(p.shape)
        i += k
    return out


@jax.jit
def _jacobian_at(x: jax.Array, wi: jax.Array, wo: jax.Array) -> jax.Array:
    """One compiled program for every parameter set (a closure per set recompiles)."""
    return jax.jacfwd(lambda y: MODEL.eval(_unflatten(y), wi, wo))(x)


def _flat_jacobian(params: dict, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """``d f / d theta`` by forward mode (as the fitter), every parameter scalar, float64."""
    flat = np.concatenate([np.ravel(np.asarray(params[p.name], float)) for p in MODEL.parameters])
    return np.asarray(_jacobian_at(jnp.asarray(flat), jnp.asarray(wi), jnp.asarray(wo)))


def test_forward_derivatives_finite_at_grazing_bounds_and_published_fits():
    wi, wo = extreme_pairs()
    g = 1e-6  # grazing pairs beside the mirror direction and the normal
    s = math.sqrt(1 - g * g)
    extra_i = np.array([[s, 0.0, g], [0.6, 0.0, 0.8], [s, 0.0, g]])
    extra_o = np.array([[-s * 0.9999, s * 0.01413, g], [-0.6, 1e-4, 0.8], [0.0, 0.0, 1.0]])
    extra_o /= np.linalg.norm(extra_o, axis=1, keepdims=True)
    wi, wo = np.concatenate([wi, extra_i]), np.concatenate([wo, extra_o])
    sets = [MODEL.defaults(), params_at_bounds(MODEL, "low"), params_at_bounds(MODEL, "high")]
    sets += [parse(ln)[2] for ln in PUBLISHED]
    for params in sets:
        jac = _flat_jacobian(params, wi, wo)
        assert np.all(np.isfinite(jac)), params
        assert np.all(np.isfinite(np.asarray(EVAL(params, wi, wo))))


def _bbm():
    try:
        from benchmarks.published import bbm
    except ImportError:
        return None
    return bbm if bbm.available() else None


def merl_like_pairs(stride: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """MERL bin centres (strided), both directions above the horizon and off the normal."""
    th = ((np.arange(0, 90, stride[0]) + 0.5) / 90) ** 2 * (np.pi / 2)
    td = (np.arange(0, 90, stride[1]) + 0.5) / 90 * (np.pi / 2)
    pd = (np.arange(0, 180, stride[2]) + 0.5) / 180 * np.pi
    a, b, c = np.meshgrid(th, td, pd, indexing="ij")
    wi, wo = halfdiff_to_io(a.ravel(), b.ravel(), c.ravel(), 0.3)
    keep = (wi[:, 2] > 1e-3) & (wo[:, 2] > 1e-3) & (wi[:, 2] < 1 - 1e-12) & (wo[:, 2] < 1 - 1e-12)
    return wi[keep], wo[keep]


BBM_FLOOR = 1e-200
"""Smallest bbm value (1/sr) scored against ours. Where the series' smallest channel (blue,
far from the mirror direction) has terms below 5e-324, bbm reads them as 0 and never stops
on them, so its other channels sum a few more terms than the rule in exact arithmetic (ours
and the reference, which decide on logs): 3e-8 relative at values ~1e-270 on the published
fits. Nothing above 1e-220 differs."""
NEAR_NORMAL = 1e-3
"""Directions closer to the normal (sin theta, rad) are scored apart: bbm's ``G`` divides
``1 - z^2`` computed in float64 (error ``eps / sin^2``: 6e-10 at 5e-4 rad, NaN at 0)."""


NO_BBM = (
    "bbm_eval not built ($BBM_EVAL or ~/.cache/brdffit/bbm_eval; "
    "benchmarks/published/build_bbm_eval.sh)"
)


@pytest.mark.skipif(_bbm() is None, reason=NO_BBM)
def test_matches_bbm_nganhe_on_published_fits():
    """Our model at each published line, mapped (kd = Lambertian albedo, ks = NganHe albedo,
    sigma = roughness, tau = autocorrelation, eta), against bbm's own evaluation of the line:
    the whole BRDF, and the He term alone (Lambertian albedo 0) where ``eta > 1``: at
    ``eta = 1.0`` (as printed, 4 lines) ``F`` is 0 here and rounding noise (1e-32) in bbm.
    """
    bbm = _bbm()
    wi_m, wo_m = merl_like_pairs((3, 6, 12))
    wi_r, wo_r = random_pairs(3, 400)
    wi_n, wo_n = near_mirror_pairs(4, 400, 0.01)
    wi = np.concatenate([wi_m, wi_r, wi_n])
    wo = np.concatenate([wo_m, wo_r, wo_n])
    off_normal = (
        np.minimum(np.hypot(wi[:, 0], wi[:, 1]), np.hypot(wo[:, 0], wo[:, 1])) > NEAR_NORMAL
    )
    lines = all_published()
    theirs = bbm.evaluate([parse(ln)[1] for ln in lines], wi, wo)
    no_lambert = r"Lambertian\(albedo = \[[^\]]*\]"
    lobes = [re.sub(no_lambert, "Lambertian(albedo = [0, 0, 0]", parse(ln)[1]) for ln in lines]
    theirs_lobe = bbm.evaluate(lobes, wi, wo)
    worst = {"whole": (0.0, ""), "He term": (0.0, ""), "near normal": (0.0, "")}
    for k, line in enumerate(lines):
        material, _, params = parse(line)
        ours = np.asarray(EVAL(params, wi, wo))
        err = relative_error(ours, theirs[k], BBM_FLOOR)
        worst["whole"] = max(worst["whole"], (float(err[off_normal].max()), material))
        worst["near normal"] = max(worst["near normal"], (float(err.max()), material))
        if params["eta"] > 1.0:
            ours_lobe = np.asarray(EVAL(params | {"kd": np.zeros(3)}, wi, wo))
            err_lobe = relative_error(ours_lobe, theirs_lobe[k], BBM_FLOOR)
            worst["He term"] = max(worst["He term"], (float(err_lobe[off_normal].max()), material))
    summary = ", ".join(f"{k} {v[0]:.2e} ({v[1]})" for k, v in worst.items())
    print(f"{len(lines)} lines x {len(wi)} pairs ({np.sum(~off_normal)} near normal): {summary}")
    assert worst["whole"][0] < 1e-9 and worst["He term"][0] < 1e-9
    assert worst["near normal"][0] < 1e-6


@pytest.mark.slow  # ~25 s on 2 cores, nearly all compiling the fit
def test_fit_recovers_its_own_parameters():
    truth = parse(PUBLISHED[4])[2]  # yellow-plastic: rms slope 2 sigma / tau = 0.35
    wi, wo = random_pairs(7, 2000)
    f = np.asarray(EVAL(truth, wi, wo))
    data = Measurements.from_directions(wi, wo, f, source="synthetic he")
    r = fit(MODEL, data, "ngan", throw=False)
    assert r.converged, r.report()
    for name, want in truth.items():
        np.testing.assert_allclose(np.asarray(r.params[name]), want, rtol=1e-6, err_msg=name)
