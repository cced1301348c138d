"""The glTF 2.0 material as a model (``brdffit/models/gltf_pbr.py``).

* The model is the BRDF of the glTF document its export writes: evaluated by the test
  suite's own transcriptions of the spec, which read only the JSON (``gltf_brdf`` of
  tests/export/test_export.py; with ``KHR_materials_iridescence``,
  ``document_brdf`` of tests/references_gltf.py, whose film is the extension's GLSL), for
  seeded random parameters and every option group, metal and dielectric.
* The two JSON readers agree where both apply; each plausible misreading of the
  iridescence sources (``tests/references_gltf.py::WRONG``: the OPD's other cosine, the
  film at ``N.V``, on the metal or the dielectric alone, on the unweighted ``f0``, the
  base's weight mixed) departs from the model far beyond the tolerance, so the check
  above would catch it.
* The sheen NDF integrates to 1 against ``cos theta_h`` (a wrong normalisation, or
  Filament's ``sin^2`` floor, fails).
* A feature switched on at its "off" value is the simpler model; the bare core is
  KHR_materials_specular at its defaults.
* The ``linear`` rows are exactly jointly affine; the others are not (with the film,
  ``base_color`` is not: the metal's film sits on it).
* Reciprocal without the clear coat only, as the model declares.
"""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import models
from brdffit.core.abstract_model import linear_split
from brdffit.core.geometry import shading_geometry
from brdffit.export import export
from brdffit.models import gltf_pbr
from tests.export.test_export import check_gltf_document, gltf_brdf, load_gltf, result
from tests.helpers import hemisphere_integral, random_pairs
from tests.references_gltf import WRONG, document_brdf, wrong_ref

OPTIONS = [
    {},
    {"specular": False},
    {"clearcoat": True},
    {"sheen": True},
    {"clearcoat": True, "sheen": True},
    {"iridescence": True},
    {"iridescence": True, "specular": False},
    {"iridescence": True, "clearcoat": True, "sheen": True},
]
WI, WO = random_pairs(11, 400)
FILM_PAIRS = 120
"""Pairs the mpmath reader evaluates (0.5 s per parameter set on 2 cores)."""
FILM = "KHR_materials_iridescence"
FILM_KEYS = {
    "iridescenceFactor",
    "iridescenceIor",
    "iridescenceThicknessMinimum",
    "iridescenceThicknessMaximum",
}


def checked_material(doc: dict) -> dict:
    """The document's material after the structural checks: ``check_gltf_document`` (which
    knows the other extensions) and, for ``KHR_materials_iridescence``, its schema's
    ranges (factor in [0, 1], IOR >= 1, thicknesses >= 0) checked here."""
    rest = copy.deepcopy(doc)
    ext = rest["materials"][0].get("extensions", {})
    film = ext.pop(FILM, None)
    if film is not None:
        assert FILM in rest.pop("extensionsUsed")
        rest |= {"extensionsUsed": sorted(ext)} if ext else {}
        assert set(film) <= FILM_KEYS, film
        assert 0 <= film.get("iridescenceFactor", 0) <= 1 and film.get("iridescenceIor", 1.3) >= 1
        assert min(film.get(k, 0) for k in FILM_KEYS if "Thickness" in k) >= 0
    check_gltf_document(rest)
    return doc["materials"][0]


def spec_brdf(mat: dict, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """The spec's BRDF of a material from its JSON (module docstring's two readers)."""
    if FILM in mat.get("extensions", {}):
        return document_brdf(mat, wi, wo)
    return gltf_brdf(mat, wi, wo)


def draw(model, rng: np.random.Generator) -> dict:
    """Natural values uniform in each box (roughnesses uniform in log)."""
    out = {}
    for p in model.parameters:
        lo, hi = p.bounds
        if p.transform == "log":
            out[p.name] = np.exp(rng.uniform(np.log(lo), np.log(hi), p.shape))
        else:
            out[p.name] = rng.uniform(lo, hi, p.shape)
    return out


@pytest.mark.parametrize(
    "opts",
    [
        # the film rows take 8-10 s (an mpmath reader); the one with every extension stays
        pytest.param(o, marks=pytest.mark.slow if "iridescence" in o and len(o) < 3 else ())
        for o in OPTIONS
    ],
    ids=str,
)
def test_model_is_the_spec_brdf_of_the_document_its_export_writes(opts):
    model = models.get("gltf", **opts)
    spec = models.label(model)
    ev = jax.jit(model.eval)
    rng = np.random.default_rng(len(spec))
    draws = [draw(model, rng) for _ in range(3)]
    if model.specular:  # the ior branches: f0 above 0.99 (colour > 1), f0 = 0, grey 0.04
        draws[1]["specular_f0"] = np.array([0.995, 0.3, 0.0])
        draws[2]["specular_f0"] = np.zeros(3)
        draws.append(draws[0] | {"specular_f0": np.full(3, 0.04)})
    if model.iridescence:  # a full film on a pure dielectric and on a pure metal
        draws += [draws[0] | {"metallic": np.asarray(m), "iridescence": 1.0} for m in (0.0, 1.0)]
    wi, wo = (WI[:FILM_PAIRS], WO[:FILM_PAIRS]) if model.iridescence else (WI, WO)
    worst = 0.0
    for params in draws:
        e = export(result(spec, {k: np.asarray(v).tolist() for k, v in params.items()}), "gltf")
        assert e.exact and not e.fitted, e.summary()
        mat = checked_material(load_gltf(e.files[".gltf"]))
        used = set(mat.get("extensions", {}))
        assert ("KHR_materials_clearcoat" in used) == model.clearcoat
        assert ("KHR_materials_sheen" in used) == model.sheen
        assert (FILM in used) == model.iridescence
        if not model.specular:
            assert not used & {"KHR_materials_specular", "KHR_materials_ior"}, used
        ref = spec_brdf(mat, wi, wo)
        got = np.asarray(ev(params, wi, wo))
        # float64 on both sides, different algebra (D, V, sin^2 forms): 1e-10
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-13 * np.abs(ref).max())
        worst = max(worst, float(np.max(np.abs(got - ref) / np.maximum(np.abs(ref), 1e-300))))
    print(f"{spec}: {len(draws)} parameter sets x {len(wi)} pairs, worst relative {worst:.2g}")


@pytest.mark.parametrize("opts", [o for o in OPTIONS if "iridescence" not in o], ids=str)
def test_the_two_json_readers_agree_without_a_film(opts):
    # document_brdf (mpmath, read by tests/references_gltf.py) against gltf_brdf (numpy):
    # two transcriptions of Appendix B and its extensions, and two readers of the JSON
    model = models.get("gltf", **opts)
    params = draw(model, np.random.default_rng(3))
    e = export(result(models.label(model), {k: v.tolist() for k, v in params.items()}), "gltf")
    mat = checked_material(load_gltf(e.files[".gltf"]))
    wi, wo = WI[:FILM_PAIRS], WO[:FILM_PAIRS]
    # float64 and mpmath at 53 bits, different algebra: 1e-12
    np.testing.assert_allclose(document_brdf(mat, wi, wo), gltf_brdf(mat, wi, wo), rtol=1e-12)


FILM_CASE = {
    "base_color": [0.7, 0.4, 0.2],
    "metallic": 0.5,
    "roughness": 0.45,
    "specular": 0.6,
    "specular_f0": [0.02, 0.09, 0.05],
    "iridescence": 0.6,
    "iridescence_ior": 1.8,
    "iridescence_thickness": 450.0,
}
"""Half metal, half film, a specular weight below 1 and a coloured f0 whose largest
channel differs from the film's: every change of ``WRONG`` shows (with a full film the
two diffuse weights of ``weights_mixed`` coincide)."""


@pytest.mark.parametrize("change", WRONG)
def test_each_misreading_of_the_iridescence_sources_departs_from_the_model(change):
    model = models.get("gltf", iridescence=True, sheen=True, clearcoat=True)
    params = FILM_CASE | {"sheen_color": [0.1, 0.2, 0.1], "sheen_roughness": 0.5}
    params |= {"clearcoat": 0.4, "clearcoat_roughness": 0.2}
    params = {k: np.asarray(v, float) for k, v in params.items()}
    wi, wo = WI[:FILM_PAIRS], WO[:FILM_PAIRS]
    got = np.asarray(jax.jit(model.eval)(params, wi, wo))
    wrong = np.asarray(wrong_ref(change)(model, params, wi, wo), float)
    gap = float(np.max(np.abs(got - wrong) / np.maximum(np.abs(wrong), 1e-300)))
    print(f"{change}: largest relative departure {gap:.3g}")
    assert gap > 1e-3  # the check above holds the model to 1e-10


CHARLIE = jax.jit(gltf_pbr.charlie_d)


@pytest.mark.parametrize("r", [0.045, 0.2, 0.5, 1.0])
def test_sheen_ndf_integrates_to_one_against_cos_theta_h(r):
    # (2 + 1/a) int_0^1 s^(1/a + 1) ds = 1: sin^(1/a) with its normalisation, no floor.
    # Panels geometric from 6e-8 in 1 - cos: at r = 1 the integrand is sqrt(t) there.
    total = hemisphere_integral(lambda h: CHARLIE(h, jnp.asarray(r * r)), 1e-6)
    assert total == pytest.approx(1.0, abs=1e-12)  # measured: within 1.5e-13


def test_features_at_their_off_values_are_the_simpler_model():
    params = {"base_color": [0.6, 0.3, 0.2], "metallic": 0.4, "roughness": 0.3}
    core = {"specular": 1.0, "specular_f0": [0.04] * 3}
    bare = np.asarray(jax.jit(models.get("gltf", specular=False).eval)(params, WI, WO))
    full = models.get("gltf", clearcoat=True, sheen=True)
    off = {"clearcoat": 0.0, "clearcoat_roughness": 0.5, "sheen_color": [0.0] * 3}
    out = jax.jit(full.eval)(params | core | off | {"sheen_roughness": 0.5}, WI, WO)
    # the same float64 operations up to a few reassociations
    np.testing.assert_allclose(np.asarray(out), bare, rtol=1e-13)
    film = models.get("gltf", iridescence=True)
    no_film = {"iridescence": 0.0, "iridescence_ior": 1.8, "iridescence_thickness": 300.0}
    out = jax.jit(film.eval)(params | core | no_film, WI, WO)
    np.testing.assert_allclose(np.asarray(out), bare, rtol=1e-13)  # max F_d, other algebra


def test_linear_parameters_are_jointly_affine_and_the_others_are_not():
    model = models.get("gltf", clearcoat=True, sheen=True)
    names = tuple(p.name for p in model.parameters if p.linear)
    assert names == ("base_color", "sheen_color")
    params = {k: jnp.asarray(v) for k, v in draw(model, np.random.default_rng(5)).items()}
    g = shading_geometry(jnp.asarray(WI), jnp.asarray(WO))
    f = np.asarray(model.evaluate(params, g))

    def rebuilt(names: tuple[str, ...]) -> np.ndarray:
        f0, basis = jax.jit(lambda q: linear_split(model, q, g, names))(params)
        x = jnp.concatenate([jnp.ravel(params[n]) for n in names])
        return np.asarray(f0 + basis @ x)

    np.testing.assert_allclose(rebuilt(names), f, rtol=1e-12, atol=1e-14 * np.abs(f).max())
    for other in ("metallic", "specular", "clearcoat"):  # affine alone, not with base_color
        gap = np.abs(rebuilt(names + (other,)) - f).max() / np.abs(f).max()
        assert gap > 1e-3, other


def test_with_the_film_base_color_is_not_affine():
    model = models.get("gltf", iridescence=True, sheen=True)
    assert tuple(p.name for p in model.parameters if p.linear) == ("sheen_color",)
    params = {k: jnp.asarray(v) for k, v in draw(model, np.random.default_rng(6)).items()}
    params |= {"metallic": jnp.asarray(0.8), "iridescence": jnp.asarray(1.0)}
    g = shading_geometry(jnp.asarray(WI), jnp.asarray(WO))
    f = np.asarray(model.evaluate(params, g))
    for names in (("sheen_color",), ("base_color", "sheen_color")):
        f0, basis = jax.jit(lambda q, n=names: linear_split(model, q, g, n))(params)
        x = jnp.concatenate([jnp.ravel(params[n]) for n in names])
        gap = np.abs(np.asarray(f0 + basis @ x) - f).max() / np.abs(f).max()
        assert (gap < 1e-12) == (names == ("sheen_color",)), (names, gap)


def test_reciprocal_exactly_when_there_is_no_clear_coat():
    for opts in OPTIONS:
        model = models.get("gltf", **opts)
        assert model.reciprocal == (not model.clearcoat)
        params = draw(model, np.random.default_rng(2))
        ev = jax.jit(model.eval)
        a, b = np.asarray(ev(params, WI, WO)), np.asarray(ev(params, WO, WI))
        gap = np.abs(a - b).max() / np.abs(a).max()
        assert (gap < 1e-12) == model.reciprocal, (opts, gap)
