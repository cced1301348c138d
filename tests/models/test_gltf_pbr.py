"""The glTF 2.0 material as a model (``brdffit/models/gltf_pbr.py``).

* The model is the BRDF of the glTF document its export writes: evaluated by the test
  suite's own transcription of the spec (``gltf_brdf`` of tests/export/test_export.py,
  which reads only the JSON), for seeded random parameters and every option group.
* The sheen NDF integrates to 1 against ``cos theta_h`` (a wrong normalisation, or
  Filament's ``sin^2`` floor, fails).
* A feature switched on at its "off" value is the simpler model; the bare core is
  KHR_materials_specular at its defaults.
* The ``linear`` rows are exactly jointly affine; the others are not.
* Reciprocal without the clear coat only, as the model declares.
"""

from __future__ import annotations

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

OPTIONS = [
    {},
    {"specular": False},
    {"clearcoat": True},
    {"sheen": True},
    {"clearcoat": True, "sheen": True},
]
WI, WO = random_pairs(11, 400)


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


@pytest.mark.parametrize("opts", OPTIONS, ids=str)
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
    worst = 0.0
    for params in draws:
        e = export(result(spec, {k: np.asarray(v).tolist() for k, v in params.items()}), "gltf")
        assert e.exact and not e.fitted, e.summary()
        mat = check_gltf_document(load_gltf(e.files[".gltf"]))
        used = set(mat.get("extensions", {}))
        assert ("KHR_materials_clearcoat" in used) == model.clearcoat
        assert ("KHR_materials_sheen" in used) == model.sheen
        if not model.specular:
            assert not used & {"KHR_materials_specular", "KHR_materials_ior"}, used
        ref = gltf_brdf(mat, WI, WO)
        got = np.asarray(ev(params, WI, WO))
        # float64 on both sides, different algebra (D, V, sin^2 forms): 1e-10
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-13 * np.abs(ref).max())
        worst = max(worst, float(np.max(np.abs(got - ref) / np.abs(ref))))
    print(f"{spec}: {len(draws)} parameter sets x {len(WI)} pairs, worst relative {worst:.2g}")


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


def test_reciprocal_exactly_when_there_is_no_clear_coat():
    for opts in OPTIONS:
        model = models.get("gltf", **opts)
        assert model.reciprocal == (not model.clearcoat)
        params = draw(model, np.random.default_rng(2))
        ev = jax.jit(model.eval)
        a, b = np.asarray(ev(params, WI, WO)), np.asarray(ev(params, WO, WI))
        gap = np.abs(a - b).max() / np.abs(a).max()
        assert (gap < 1e-12) == model.reciprocal, (opts, gap)
