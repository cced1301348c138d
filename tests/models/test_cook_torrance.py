"""Cook-Torrance 1982: exact Fresnel terms against complex-index optics and Mitsuba 3,
the model against the paper's formulas at hand-picked directions, D normalisation and
the specular albedo by quadrature."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import models
from brdffit.models import _terms
from tests.helpers import half_vector_albedo

COS = np.linspace(0.0, 1.0, 41)
# Jitted once per module: one compile each instead of one per eager primitive and test.
DIELECTRIC = jax.jit(_terms.fresnel_dielectric)
CONDUCTOR = jax.jit(_terms.fresnel_conductor)
BECKMANN = jax.jit(_terms.beckmann_d)
CONDUCTORS = [(0.2, 3.9), (1.5, 7.0), (2.9, 3.1), (0.01, 1e-3), (0.5, 0.01), (6.0, 15.0)]


def fresnel_complex(cos: np.ndarray, eta: complex) -> np.ndarray:
    """Unpolarised reflectance from Snell's law with a complex index (numpy complex128)."""
    sin_t = np.sqrt(1 - cos.astype(complex) ** 2) / eta
    cos_t = np.sqrt(1 - sin_t**2)
    rs = (cos - eta * cos_t) / (cos + eta * cos_t)
    rp = (eta * cos - cos_t) / (eta * cos + cos_t)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


@pytest.mark.parametrize("eta", [1.01, 1.33, 1.5, 2.4, 0.7])
def test_fresnel_dielectric_matches_complex_optics_and_mitsuba(eta):
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    ours = np.asarray(DIELECTRIC(jnp.asarray(COS), jnp.asarray(eta)))
    ref = np.where(COS**2 <= 1 - eta**2, 1.0, fresnel_complex(COS, eta + 0j))
    # Both float64 and exact formulas: agreement to rounding.
    np.testing.assert_allclose(ours, ref, rtol=1e-12, atol=1e-15)
    mits = np.array([mi.fresnel(float(c), eta)[0] for c in COS])
    # Mitsuba's scalar_rgb variant computes in float32.
    np.testing.assert_allclose(ours, mits, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize(("eta", "k"), CONDUCTORS)
def test_fresnel_conductor_matches_complex_optics_normal_incidence_and_mitsuba(eta, k):
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    ours = np.asarray(CONDUCTOR(jnp.asarray(COS), jnp.asarray(eta), jnp.asarray(k)))
    np.testing.assert_allclose(ours, fresnel_complex(COS, eta + 1j * k), rtol=1e-12)
    normal = ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)
    assert ours[-1] == pytest.approx(normal, rel=1e-14)
    mits = np.array([mi.fresnel_conductor(float(c), dr.scalar.Complex2f(eta, k)) for c in COS])
    # float32 in Mitsuba; its a^2 = (|z| + t0)/2 cancels for eta = 0.01, k = 1e-3 (1.2e-4
    # relative there, where ours agrees with complex128 optics to 1e-15).
    np.testing.assert_allclose(ours, mits, rtol=2e-4 if eta < 0.1 else 1e-5)


def test_fresnel_conductor_with_k_zero_is_the_dielectric():
    cos, eta = jnp.asarray(COS), jnp.asarray(1.5)
    ours = np.asarray(CONDUCTOR(cos, eta, jnp.asarray(0.0)))
    ref = np.asarray(DIELECTRIC(cos, eta))
    np.testing.assert_allclose(ours, ref, rtol=1e-13)


def _direction(theta, phi):
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)


def paper_dielectric_f(c, n):
    """Cook-Torrance 1982 eq. for F, transcribed: g^2 = n^2 + c^2 - 1."""
    g = np.sqrt(n**2 + c**2 - 1)
    return 0.5 * (g - c) ** 2 / (g + c) ** 2 * (1 + (c * (g + c) - 1) ** 2 / (c * (g - c) + 1) ** 2)


@pytest.mark.parametrize("fresnel", ["schlick", "dielectric"])
def test_model_matches_paper_formula(fresnel):
    # (theta_i, phi_i, theta_o, phi_o) in degrees: specular, off-specular, grazing, retro.
    ti, pi_, to, po = np.radians(
        np.array([(30, 0, 30, 180), (40, 10, 25, 200), (80, 0, 75, 170), (50, 0, 50, 0)], float)
    ).T
    wi, wo = _direction(ti, pi_), _direction(to, po)
    m, kd, ks = 0.3, np.array([0.1, 0.2, 0.3]), np.array([0.9, 0.8, 0.7])
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    n_h, n_v, n_l, v_h = h[:, 2], wo[:, 2], wi[:, 2], np.sum(wo * h, -1)
    alpha = np.arccos(n_h)
    # SIGGRAPH 1981 D (the 1982 D over 4): R_s = F D G / (pi (N.L)(N.V)).
    d = np.exp(-((np.tan(alpha) / m) ** 2)) / (4 * m**2 * np.cos(alpha) ** 4)
    g = np.minimum(1, np.minimum(2 * n_h * n_v / v_h, 2 * n_h * n_l / v_h))
    model = models.get("cook_torrance", fresnel=fresnel)
    params = {"kd": kd, "ks": ks, "m": m}
    if fresnel == "schlick":
        f0 = np.array([0.9, 0.5, 0.04])
        params["f0"] = f0
        F = f0[None] + (1 - f0[None]) * (1 - v_h[:, None]) ** 5
    else:
        params["eta"] = 1.7
        F = paper_dielectric_f(v_h, 1.7)[:, None]
    expected = kd[None] / np.pi + ks[None] * F * (d * g / (np.pi * n_l * n_v))[:, None]
    got = np.asarray(jax.jit(model.eval)(params, wi, wo))
    # float64 both ways; tan/arccos vs. slope form: ~1e-15 relative.
    np.testing.assert_allclose(got, expected, rtol=1e-12)


@pytest.mark.parametrize("m", [0.02, 0.3, 1.5])
def test_beckmann_d_integrates_to_one_against_cos_theta_h(m):
    # theta_h = arctan(m x), x in [0, 12] (exp(-144) beyond), Gauss-Legendre in x.
    x, w = np.polynomial.legendre.leggauss(400)
    x, w = 6.0 * (x + 1), 6.0 * w
    th = np.arctan(m * x)
    dth = m / (1 + (m * x) ** 2)
    h = _direction(th, np.zeros_like(th))
    d = np.asarray(BECKMANN(jnp.asarray(h), jnp.asarray(m), jnp.asarray(m)))
    total = 2 * np.pi * np.sum(w * dth * d * np.cos(th) * np.sin(th))
    # Smooth integrand, 400 nodes: rounding-level error.
    assert total == pytest.approx(1.0, abs=1e-9)


def test_specular_albedo_at_most_one_with_unit_fresnel():
    # V-cavity masking: with F = 1 and ks = 1 the lobe loses, never gains, energy.
    model = models.get("cook_torrance", diffuse=False)
    evaluate = jax.jit(model.eval)
    for m in (0.05, 0.5, 2.0):
        params = {"ks": jnp.ones(3), "m": jnp.asarray(m), "f0": jnp.ones(3)}
        albedos = [half_vector_albedo(evaluate, params, np.radians(t), m) for t in (0, 45, 80, 89)]
        # Quadrature error < 1e-4 (150 x 300 nodes against 600 x 1200; horizon kink in phi).
        assert max(albedos) <= 1.0 + 1e-3, (m, albedos)
    # Rough lobe at normal incidence, against the same quadrature at 600 x 1200 nodes (0.89242).
    params = {"ks": jnp.ones(3), "m": jnp.asarray(0.5), "f0": jnp.ones(3)}
    assert half_vector_albedo(evaluate, params, 0.0, 0.5) == pytest.approx(0.89242, abs=5e-4)
