"""The ``openpbr`` model (``brdffit/models/openpbr.py``) against MaterialX's own evaluation.

The reference (``tests/references_openpbr.py``, written apart from the model) interprets
the ``open_pbr_surface`` node graph of MaterialX's library node by node, its closures
transcribed from MaterialX 1.39.5's GLSL. Every row of ``tests/cases_j.py`` (one per
option and one with every option) is compared at 3000 random direction pairs, at the
row's values, at four parameter sets drawn over the box, and at every parameter on its
lower and upper bound (with MaterialX's own F82 metal Fresnel, which the model floors at 0
unless asked not to: the floor acts at some drawn sets, and the model without it is
compared at every other set); and at each row's values against the GLSL MaterialX generates, run
on an OpenGL context (``tests/materialx_glsl.py``). Then the comparison with the reference
is run on the model with one term perturbed, to show that it fails for a wrong formula.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from brdffit.export.materialx import f82_tint_floor
from brdffit.models import _films, _terms, openpbr
from brdffit.models.check import params_at_bounds
from tests.cases import CASES
from tests.helpers import random_pairs, random_params
from tests.materialx_glsl import context, response
from tests.models.test_openpbr_glsl import TOLERANCE, directions, relative_error
from tests.references_openpbr import open_pbr_brdf

ROWS = [c for c in CASES if c.model == "openpbr"]
ENDS = [
    pytest.param(c, id=c.id, marks=() if i in (0, len(ROWS) - 1) else pytest.mark.slow)
    for i, c in enumerate(ROWS)
]
"""ROWS for the two comparisons with MaterialX: its base form and the row with every
option on run in the default suite (5-11 s a row), the others in
``benchmarks/slow_checks.sh``."""
WI, WO = random_pairs(21, 3000)
TOL = 1e-9
"""float64 on both sides; the model groups the same operations differently and uses
cancellation-free forms (the dielectric Fresnel, Fujii's albedo): measured at most 3e-13."""


def max_relative_difference(model, params: dict) -> float:
    """max over pairs and channels of |model - reference| / |reference| (a reference value
    of exactly 0 must be matched by 0: the denominator is floored at 1e-300)."""
    f = np.asarray(model.eval(params, WI, WO))
    inputs = {k: np.asarray(v).tolist() for k, v in params.items()}
    ref = open_pbr_brdf(inputs, WI, WO)
    return float(np.max(np.abs(f - ref) / np.maximum(np.abs(ref), 1e-300)))


def parameter_sets(case) -> list[dict]:
    model, row = case.build()
    rng = np.random.default_rng(7)
    drawn = [random_params(model, rng) for _ in range(4)]
    return [row, *drawn, params_at_bounds(model, "low"), params_at_bounds(model, "high")]


def floors_f82(params: dict) -> bool:
    """Whether the model floors MaterialX's F82 at these values: a metal lobe whose
    ``specular_color`` lies below :func:`~brdffit.export.materialx.f82_tint_floor`."""
    metal = float(params["base_metalness"]) > 0 and float(params["specular_weight"]) > 0
    floor = f82_tint_floor(np.asarray(params["base_color"]))
    return metal and bool(np.any(np.asarray(params["specular_color"]) < floor))


@pytest.mark.parametrize("case", ENDS)
def test_matches_materialx_pointwise(case):
    """With ``negative_f82`` (MaterialX's metal Fresnel as it is) the model is MaterialX at
    every parameter set; without it, at every set where the floor does not act."""
    model, _ = case.build()
    raw = openpbr.OpenPbr(**(model.options() | {"negative_f82": True}))
    sets = parameter_sets(case)
    worst = [max_relative_difference(raw, p) for p in sets]
    plain = [max_relative_difference(model, p) for p in sets if not floors_f82(p)]
    print(
        f"{case.id}: max relative difference per parameter set {np.array(worst)}; without "
        f"negative_f82 at the {len(plain)} sets where the floor does not act {max(plain):.2e}"
    )
    assert max(worst) < TOL and max(plain) < TOL and len(plain) >= 4


@pytest.mark.parametrize("case", ENDS)
def test_matches_materialx_glsl(case):
    """The GLSL MaterialX generates, run on an OpenGL context (:mod:`tests.materialx_glsl`;
    skipped without one): float32 there, so the tolerance of ``test_openpbr_glsl``, 5e-5
    relative on responses floored at 1e-3 of the largest (measured: at most 7e-6)."""
    context()
    model, params = case.build()
    wi, wo = directions()
    glsl = response({k: np.asarray(v).tolist() for k, v in params.items()}, wi, wo)
    got = relative_error(np.asarray(model.eval(params, wi, wo)) * wi[:, 2:3], glsl)
    print(f"{case.id}: relative difference to MaterialX's GLSL {got:.2e}")
    assert got < TOLERANCE


_GGX_ALBEDO, _ZELTNER_ALBEDO = openpbr.ggx_albedo, _terms.zeltner_albedo


def _no_compensation(f, a, b):
    return jnp.ones_like(f)


def _albedo_without_f90(cos_v, alpha):
    a, _ = _GGX_ALBEDO(cos_v, alpha)
    return a, jnp.zeros_like(a)


def _plain_schlick(f0, tint, cos):
    return _terms.schlick_fresnel(f0, cos)


def _zeltner_albedo_high(cos, r):
    return 1.001 * _ZELTNER_ALBEDO(cos, r)


PERTURBED = [
    # (row index in ROWS, module, attribute, replacement, what it breaks)
    (0, openpbr, "compensation", _no_compensation, "Turquin's energy compensation dropped"),
    (0, openpbr, "ggx_albedo", _albedo_without_f90, "the albedo fit's F90 term B dropped"),
    (0, _terms, "f82_schlick", _plain_schlick, "the metal's F82 tint dropped"),
    (0, _terms, "FUJII_C2", _terms.FUJII_C2 * 1.001, "EON's average albedo constant +0.1%"),
    (4, _terms, "zeltner_albedo", _zeltner_albedo_high, "the fuzz albedo +0.1%"),
]


@pytest.mark.parametrize("row,module,name,value,what", PERTURBED, ids=[p[-1] for p in PERTURBED])
def test_a_wrong_formula_fails_the_comparison(monkeypatch, row, module, name, value, what):
    case = ROWS[row]
    monkeypatch.setattr(module, name, value)
    model, params = case.build()
    got = max_relative_difference(model, params)
    print(f"{case.id} with {what}: max relative difference {got:.3g}")
    assert got > 1e3 * TOL


def test_features_at_zero_weight_are_the_features_off():
    """coat, fuzz and thin film at weight 0 and anisotropy 0 are the model without them."""
    core, _ = ROWS[0].build()
    _, params = ROWS[-1].build()  # every option on
    params = params | {
        "coat_weight": jnp.asarray(0.0),
        "fuzz_weight": jnp.asarray(0.0),
        "thin_film_weight": jnp.asarray(0.0),
        "specular_roughness_anisotropy": jnp.asarray(0.0),
    }
    every = openpbr.OpenPbr(anisotropic=True, coat=True, fuzz=True, thin_film=True)
    plain = {p.name: params[p.name] for p in core.parameters}
    np.testing.assert_allclose(every.eval(params, WI, WO), core.eval(plain, WI, WO), rtol=1e-14)


def test_a_film_of_index_one_leaves_the_base_fresnel():
    """With the film's index 1 the top interface reflects nothing, so MaterialX's Airy sum
    is the base's own Fresnel, taken as XYZ and converted to CIE RGB: the exact dielectric
    one for a dielectric base (grey, which the matrix keeps to 1e-7); for a metal base
    ``M (F82 / 2)``, ``M`` the XYZ-to-RGB matrix (MaterialX writes ``R23 = 0.5 F`` for each
    polarisation and converts the metal's RGB as if it were XYZ)."""
    cos = jnp.linspace(0.02, 1.0, 50)
    one, d = jnp.asarray(1.0), jnp.asarray(400.0)
    got = _films.airy_fresnel(cos, one, d, jnp.full(3, 1.7), None)
    want = _terms.fresnel_dielectric(cos, jnp.asarray(1.7))[:, None]
    np.testing.assert_allclose(got, np.broadcast_to(want, got.shape), rtol=2e-7)  # B row: 1 + 1e-7
    f0, tint = jnp.array([0.9, 0.6, 0.3]), jnp.array([1.0, 0.8, 0.6])
    got = _films.airy_fresnel(cos, one, d, openpbr._f0_to_ior(f0), (f0, tint))
    matrix = np.asarray(_films.XYZ_TO_CIE_RGB)
    want = np.clip(0.5 * np.asarray(_terms.f82_schlick(f0, tint, cos)) @ matrix.T, 0.0, 1.0)
    # R12 is 0 to round-off (1e-17), and sqrt(R12 R23) enters the sum: 1e-8
    np.testing.assert_allclose(got, want, rtol=1e-7)


def test_materialx_has_no_lambertian_setting():
    """``specular_weight`` 0 removes the dielectric lobe but not its throughput ``1 - B``
    (the albedo fit's F90 term), so the Lambertian setting of OpenPBR renders darker than
    ``base_color / pi``, most at grazing views (read from the reference, not the model)."""
    inputs = {"base_color": 0.5, "specular_weight": 0.0, "specular_roughness": 1.0}
    ratio = open_pbr_brdf(inputs, WI, WO)[:, 0] / (0.5 / np.pi)
    print(f"f / (base_color / pi): {ratio.min():.4f} .. {ratio.max():.4f}")
    assert ratio.max() < 1.0 and ratio.min() < 0.99


DARK_METAL = {"base_color": [0.05, 0.3, 0.6], "base_metalness": 1.0, "specular_color": 0.1}
"""MaterialX's F82 Fresnel is negative here in R: tint 0.1, below the 0.31 that a base
colour of 0.05 needs (``brdffit.export.materialx.f82_tint_floor``)."""


def test_the_metal_fresnel_is_floored_where_materialx_goes_negative():
    """MaterialX's metal lobe is negative at middle angles for a low ``specular_color`` over
    a dark ``base_color``; the model floors its F82 at 0 (a BRDF), and with the option
    ``negative_f82`` it is MaterialX's value again."""
    model = openpbr.OpenPbr()
    params = model.defaults() | {
        k: jnp.broadcast_to(jnp.asarray(v, float), model.parameter(k).shape)
        for k, v in DARK_METAL.items()
    }
    ref = open_pbr_brdf({k: np.asarray(v).tolist() for k, v in params.items()}, WI, WO)
    f = np.asarray(model.eval(params, WI, WO))
    raw = np.asarray(openpbr.OpenPbr(negative_f82=True).eval(params, WI, WO))
    print(f"reference min {ref.min():.3g}; model min {f.min():.3g}")
    assert ref.min() < -1e-3 and f.min() >= 0.0
    np.testing.assert_allclose(raw, ref, rtol=TOL, atol=1e-12 * np.abs(ref).max())
    positive = np.all(ref > 0, axis=1)  # where MaterialX is positive, the two agree
    np.testing.assert_allclose(f[positive], ref[positive], rtol=TOL)
