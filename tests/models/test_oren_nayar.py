"""Oren-Nayar 1994: Lambert at sigma = 0, the paper's formulas in angles, reciprocity of
the full model, albedo limits by quadrature, positivity at the sigma bound."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import models
from brdffit.core.geometry import uniform_hemisphere

VARIANTS = ["qualitative", "full"]


def _direction(theta, phi):
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)


def paper_formula(variant, ti, pi_, to, po, rho, sigma):
    """Eqs. 27-30 of the paper transcribed with angles (arccos-free inputs, np.tan)."""
    s2 = sigma**2
    alpha, beta = np.maximum(ti, to), np.minimum(ti, to)
    cos_phi = np.cos(pi_ - po)
    a = 1 - 0.5 * s2 / (s2 + 0.33)
    b = 0.45 * s2 / (s2 + 0.09)
    if variant == "qualitative":
        shape = a + b * np.maximum(0, cos_phi) * np.sin(alpha) * np.tan(beta)
        return rho[None] / np.pi * shape[:, None]
    c2 = np.where(cos_phi >= 0, b * np.sin(alpha), b * (np.sin(alpha) - (2 * beta / np.pi) ** 3))
    c3 = 0.125 * s2 / (s2 + 0.09) * (4 * alpha * beta / np.pi**2) ** 2
    l1 = a + cos_phi * c2 * np.tan(beta) + (1 - np.abs(cos_phi)) * c3 * np.tan((alpha + beta) / 2)
    l2 = 0.17 * s2 / (s2 + 0.13) * (1 - cos_phi * (2 * beta / np.pi) ** 2)
    return (rho[None] * l1[:, None] + rho[None] ** 2 * l2[:, None]) / np.pi


@pytest.mark.parametrize("variant", VARIANTS)
def test_matches_paper_formula(variant):
    # (theta_i, phi_i, theta_o, phi_o) degrees: cos_phi > 0, < 0, = 0, grazing, mixed.
    angles = [
        (30, 0, 50, 20),
        (60, 10, 40, 200),
        (45, 0, 70, 90),
        (85, 0, 80, 30),
        (20, 0, 75, 140),
    ]
    ti, pi_, to, po = np.radians(np.array(angles, float)).T
    rho, sigma = np.array([0.3, 0.6, 0.9]), 0.5
    model = models.get("oren_nayar", variant=variant)
    got = jax.jit(model.eval)({"rho": rho, "sigma": sigma}, _direction(ti, pi_), _direction(to, po))
    expected = paper_formula(variant, ti, pi_, to, po, rho, sigma)
    # float64 both ways; the model's sine/cosine forms vs. np.tan of angles: ~1e-15.
    np.testing.assert_allclose(np.asarray(got), expected, rtol=1e-12)


@pytest.mark.parametrize("variant", VARIANTS)
def test_sigma_zero_is_lambert_exactly(variant):
    wi, wo = (
        uniform_hemisphere(np.random.default_rng(0), 64),
        uniform_hemisphere(np.random.default_rng(1), 64),
    )
    rho = jnp.asarray([0.2, 0.5, 0.8])
    got = models.get("oren_nayar", variant=variant).eval({"rho": rho, "sigma": 0.0}, wi, wo)
    expected = models.get("lambert").eval({"kd": rho}, wi, wo)
    # A = 1, B = C3 = 0 and the interreflection weight 0 exactly: bit-identical.
    np.testing.assert_array_equal(np.asarray(got), np.asarray(expected))


def test_full_model_reciprocal_at_normal_grazing_and_opposite_azimuths():
    g = np.radians(89.9)
    wi = _direction(np.array([0.0, g, g, 1.2, 0.3]), np.array([0.0, 0.0, 0.0, 0.5, 2.0]))
    wo = _direction(np.array([1.0, g, 0.7, 1.2, 1.4]), np.array([2.0, np.pi, 3.0, 3.6, 5.0]))
    model = models.get("oren_nayar", variant="full")
    params = {"rho": jnp.asarray([0.9, 0.5, 0.1]), "sigma": 0.6}
    evaluate = jax.jit(model.eval)
    a, b = evaluate(params, wi, wo), evaluate(params, wo, wi)
    # Every term is a symmetric function of (theta_i, theta_o, cos_phi): equal to rounding.
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-14)


def albedo(evaluate, params, theta_i, n=200):
    """Directional albedo: Gauss-Legendre in theta_o, midpoint rule in phi_o."""
    t, wt = np.polynomial.legendre.leggauss(n)
    th, wth = np.pi / 4 * (t + 1), np.pi / 4 * wt
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    TH, PH = np.meshgrid(th, ph, indexing="ij")
    wo = _direction(TH, PH).reshape(-1, 3)
    wi = np.broadcast_to(_direction(theta_i, 0.0), wo.shape)
    f = np.asarray(evaluate(params, wi, wo))[:, 0]
    weight = (wth * np.sin(th) * np.cos(th))[:, None] * np.ones_like(PH) * (np.pi / n)
    return float(np.sum(f * weight.ravel()))


def test_qualitative_albedo_limits_and_energy_gain():
    evaluate = jax.jit(models.get("oren_nayar").eval)
    s2 = 0.2**2
    a, b = 1 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)
    params = {"rho": jnp.ones(3), "sigma": jnp.asarray(0.2)}
    # Normal incidence: beta = 0 everywhere, albedo = rho A exactly (smooth quadrature).
    assert albedo(evaluate, params, 0.0) == pytest.approx(a, abs=1e-6)
    # Grazing incidence: albedo -> rho (A + B/2), 1.0152 at sigma = 0.2: above rho, which
    # is why energy_conserving is False. At 89.99 degrees the limit holds to ~1e-4.
    grazing = albedo(evaluate, params, np.radians(89.99))
    assert grazing == pytest.approx(a + b / 2, abs=5e-4)
    assert grazing > 1.01


def test_full_model_nonnegative_up_to_its_sigma_bound():
    model = models.get("oren_nayar", variant="full")
    hi = model.parameter("sigma").bounds[1]
    th = np.radians(np.linspace(0.0, 89.999, 200))
    ti, to = np.meshgrid(th, th, indexing="ij")
    wi = _direction(ti.ravel(), np.zeros(ti.size))
    wo = _direction(to.ravel(), np.full(ti.size, np.pi))  # cos_phi = -1: the C2 minimum
    f = jax.jit(model.eval)({"rho": jnp.full(3, 1e-6), "sigma": hi}, wi, wo)
    # The minimum sits at both-grazing (C1 - 6 B / pi > 0 for sigma <= 0.65).
    assert float(jnp.min(f)) >= 0.0
