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
from brdffit.models import _films, _terms
from tests.export.test_export import gltf_brdf
from tests.helpers import random_pairs
from tests.references_gltf import iridescent_fresnel

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
    d = jax.jit(lambda h: _terms.charlie_d(h, a))

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


# --- thin film: KHR_materials_iridescence's reference text, and the CIE tables ----------------
# The extension's GLSL is transcribed once, in tests/references_gltf.py (iridescent_fresnel,
# at mpmath's default 53 bits here), which the glTF model's reference uses too.
@pytest.mark.parametrize(
    "thickness, film_ior, f0",
    [
        (400.0, 1.3, [0.04, 0.04, 0.04]),
        (250.0, 1.8, [0.9, 0.6, 0.3]),
        (900.0, 2.2, [0.2, 0.5, 0.02]),
    ],
)
def test_thin_film_equals_the_iridescence_extension_text(thickness, film_ior, f0):
    cos1 = np.linspace(0.02, 1.0, 60)
    got = jax.jit(_films.thin_film_fresnel)(
        jnp.asarray(cos1), jnp.asarray(thickness), jnp.asarray(film_ior), jnp.asarray(f0)
    )
    want = np.array(
        [[float(x) for x in iridescent_fresnel(c, thickness, film_ior, f0)] for c in cos1]
    )
    np.testing.assert_allclose(np.asarray(got), want, rtol=1e-10, atol=1e-12)


def test_thin_film_colours_follow_the_cie_tables():
    """Belcour's Fourier-space fits against the CIE 1931 2-degree functions integrated over
    wavelength (colour-science's tables): the cosine-modulated spectrum's XYZ, in RGB."""
    import colour

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    lam, xyz = cmfs.wavelengths * 1e-9, cmfs.values
    m = np.asarray(_films.XYZ_TO_REC709)
    for opd in (0.0, 150.0, 300.0, 600.0, 1000.0):
        for shift in (0.0, math.pi / 2, math.pi):
            c = np.cos(2 * math.pi * opd * 1e-9 / lam + shift)
            ref = m @ (np.trapezoid(xyz * c[:, None], lam, axis=0) / np.trapezoid(xyz[:, 1], lam))
            got = _films._sensitivity(jnp.array([[opd]]), jnp.full((1, 3), shift))[0]
            np.testing.assert_allclose(np.asarray(got), ref, atol=0.05 if opd <= 300 else 0.12)


def test_a_film_of_weight_zero_is_the_plain_lobe_and_colour_turns_with_angle():
    plain = models.get("walter")
    film = models.get("walter", thin_film=True)
    p = {"kd": [0.05, 0.05, 0.05], "ks": [0.8, 0.8, 0.8], "f0": [0.04] * 3, "alpha": 0.2}
    wi, wo = random_pairs(8, 200)
    zero = p | {"film_weight": 0.0, "film_thickness": 400.0, "film_ior": 1.5}
    np.testing.assert_allclose(film.eval(zero, wi, wo), plain.eval(p, wi, wo), rtol=1e-12)
    on = zero | {"film_weight": 1.0}
    f = _films.thin_film_fresnel(
        jnp.linspace(0.05, 1.0, 20), jnp.asarray(400.0), jnp.asarray(1.5), jnp.full(3, 0.04)
    )
    hue = np.asarray(f) / np.asarray(f).sum(axis=1, keepdims=True)
    assert np.ptp(hue, axis=0).max() > 0.1  # the colour changes with the angle
    assert not np.allclose(film.eval(on, wi, wo), plain.eval(p, wi, wo), rtol=1e-3)
    assert not m_linear(film, "f0") and m_linear(film, "ks")


def m_linear(model, name: str) -> bool:
    return model.parameter(name).linear
