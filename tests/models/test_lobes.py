"""Walter's optional lobes and layers (``models/walter.py``: ``n_lobes``, ``sheen``,
``clearcoat``) against independent checks.

* glTF 2.0's reference BRDF, evaluated from a material document alone
  (``tests/export/test_export.py::gltf_brdf``, written from the spec's Appendix B and the
  ``KHR_materials_sheen`` / ``_clearcoat`` texts): a metallic glTF material
  (``metallic = 1``, Schlick of ``baseColor``, height-correlated Smith GGX) is walter with
  one lobe of ``f0 = baseColor``, no diffuse and no specular weight; with sheen and a
  clear coat on both sides the two must agree to round-off.
* Quadrature: the Charlie distribution integrates to 1 against ``cos theta_h``.
* Sums: ``n_lobes = 2`` is the one-lobe model's lobes added (each evaluated by the
  one-lobe model, which ``test_walter.py`` checks against Mitsuba).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

from brdffit import models
from brdffit.models import _terms
from brdffit.models.walter import SHEEN_FLOOR
from tests.export.test_export import gltf_brdf
from tests.helpers import random_pairs

METAL = dict(diffuse=False, specular_weight=False, masking="height_correlated")


def _gltf_material(base, roughness, sheen=None, coat=None) -> dict:
    mat = {
        "pbrMetallicRoughness": {
            "baseColorFactor": [*base, 1.0],
            "metallicFactor": 1.0,
            "roughnessFactor": roughness,
        },
        "extensions": {},
    }
    if sheen is not None:
        mat["extensions"]["KHR_materials_sheen"] = {
            "sheenColorFactor": list(sheen[0]),
            "sheenRoughnessFactor": sheen[1],
        }
    if coat is not None:
        mat["extensions"]["KHR_materials_clearcoat"] = {
            "clearcoatFactor": coat[0],
            "clearcoatRoughnessFactor": coat[1],
        }
    return mat


@pytest.mark.parametrize(
    "sheen, coat",
    [
        (None, None),
        (([0.3, 0.5, 0.9], 0.4), None),
        (None, (0.7, 0.2)),
        (([0.8, 0.1, 0.2], 0.9), (1.0, 0.6)),
    ],
)
def test_sheen_and_clear_coat_equal_the_gltf_reference(sheen, coat):
    base, rough = np.array([0.9, 0.6, 0.2]), 0.35
    model = models.get("walter", sheen=sheen is not None, clearcoat=coat is not None, **METAL)
    p = {"f0": base, "alpha": rough**2}
    if sheen is not None:
        p |= {"sheen_color": np.array(sheen[0]), "sheen_roughness": sheen[1]}
    if coat is not None:
        p |= {"clearcoat": coat[0], "clearcoat_alpha": coat[1] ** 2}
    wi, wo = random_pairs(3, 500)
    got = np.asarray(model.eval(p, wi, wo))
    ref = gltf_brdf(_gltf_material(base, rough, sheen, coat), wi, wo)
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)
    assert model.reciprocal == (coat is None)


@pytest.mark.parametrize("roughness", [0.1, 0.3, 0.6, 1.0])
def test_charlie_distribution_is_normalised(roughness):
    a = jnp.asarray(roughness**2)
    d = jax.jit(lambda h: _terms.charlie_d(h, a, SHEEN_FLOOR))

    def integrand(theta: float) -> float:
        h = jnp.array([[math.sin(theta), 0.0, math.cos(theta)]])
        return float(d(h)[0]) * math.cos(theta) * math.sin(theta)

    total, _ = integrate.quad(integrand, 0.0, math.pi / 2, epsabs=1e-12, limit=200)
    assert 2.0 * math.pi * total == pytest.approx(1.0, rel=1e-7)


@pytest.mark.parametrize("options", [{}, {"anisotropic": True}, {"specular_weight": False}])
def test_two_lobes_are_the_sum_of_one_lobe_models(options):
    two = models.get("walter", n_lobes=2, **options)
    one = models.get("walter", **options)
    alone = models.get("walter", diffuse=False, **options)
    rng = np.random.default_rng(5)
    p2 = {q.name: rng.uniform(0.05, 0.6, q.shape) for q in two.parameters}
    wi, wo = random_pairs(4, 300)
    first = {q.name: p2[q.name + "_1" if q.name != "kd" else "kd"] for q in one.parameters}
    second = {q.name: p2[q.name + "_2"] for q in alone.parameters}
    want = np.asarray(one.eval(first, wi, wo)) + np.asarray(alone.eval(second, wi, wo))
    np.testing.assert_allclose(np.asarray(two.eval(p2, wi, wo)), want, rtol=1e-12)


def test_lobe_names_defaults_and_linear_parameters():
    m = models.get("walter", n_lobes=3, sheen=True, clearcoat=True)
    names = [p.name for p in m.parameters]
    assert names[:4] == ["kd", "ks_1", "f0_1", "alpha_1"] and "alpha_3" in names
    alphas = [m.parameter(f"alpha_{k}").default for k in (1, 2, 3)]
    assert alphas == pytest.approx([0.05, 0.05 * 10**0.5, 0.5])  # narrow to wide
    linear = {p.name for p in m.parameters if p.linear}
    assert linear == {"kd", "ks_1", "ks_2", "ks_3", "sheen_color"}
    assert [p.name for p in models.get("walter").parameters] == ["kd", "ks", "f0", "alpha"]
    with pytest.raises(Exception, match="n_lobes"):
        models.get("walter", n_lobes=0)


def test_the_model_is_jointly_affine_in_its_linear_parameters():
    """linear_split's exactness: f at a random point equals f0 + basis @ x."""
    from brdffit.core.abstract_model import linear_split
    from brdffit.core.geometry import shading_geometry

    m = models.get("walter", n_lobes=2, sheen=True, clearcoat=True)
    rng = np.random.default_rng(9)
    p = {q.name: jnp.asarray(rng.uniform(0.1, 0.5, q.shape)) for q in m.parameters}
    wi, wo = random_pairs(6, 200)
    g = shading_geometry(jnp.asarray(wi), jnp.asarray(wo))
    names = tuple(q.name for q in m.parameters if q.linear)
    f0, basis = linear_split(m, p, g, names)
    x = jnp.concatenate([jnp.ravel(p[n]) for n in names])
    np.testing.assert_allclose(f0 + basis @ x, m.evaluate(p, g), rtol=1e-10, atol=1e-14)
