"""Phong (Lewis 1994): closed form at hand-picked directions, lobe albedo by quadrature."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import models


def _direction(theta, phi):
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def test_closed_form_at_hand_picked_directions():
    # (theta_i, phi_i, theta_o, phi_o) in degrees: mirror pair, near mirror, off lobe, behind.
    angles = [(30, 0, 30, 180), (30, 0, 35, 170), (60, 40, 20, 250), (45, 0, 45, 0), (0, 0, 70, 10)]
    kd, ks, n = np.array([0.2, 0.3, 0.4]), np.array([0.5, 0.4, 0.3]), 37.0
    model = models.get("phong")
    params = {"kd": kd, "ks": ks, "n": n}
    ti, pi_, to, po = np.radians(np.array(angles, float)).T
    # Spherical law of cosines for the angle between wo and the mirror direction of wi
    # (polar angle theta_i, azimuth phi_i + pi): independent of the vector form in the model.
    cos_alpha = np.cos(ti) * np.cos(to) + np.sin(ti) * np.sin(to) * np.cos(po - pi_ - np.pi)
    lobe = (n + 2) / (2 * np.pi) * np.maximum(cos_alpha, 0.0) ** n
    expected = kd[None] / np.pi + ks[None] * lobe[:, None]
    got = jax.jit(model.eval)(params, _direction(ti, pi_).T, _direction(to, po).T)
    # float64 closed form against float64 model: a few ulps, amplified by cos^37.
    np.testing.assert_allclose(np.asarray(got), expected, rtol=1e-12)


def lobe_albedo(evaluate, n: float, theta_i: float, m: int = 500) -> float:
    """Directional albedo of the Phong lobe (kd = 0, ks = 1) at incidence ``theta_i``.

    Quadrature in polar coordinates (alpha, phi) around the mirror direction with the
    substitution s = cos(alpha)^(n+1), which absorbs the peak: dw = ds dphi / ((n+1) t^n).
    Midpoint rule, m x m points; the model's own zero below the horizon does the clipping.
    ``evaluate`` is the jitted ``model.eval`` (one compile for every call of a test).
    """
    s = (np.arange(m) + 0.5) / m
    phi = (np.arange(m) + 0.5) / m * 2 * np.pi
    t = s ** (1.0 / (n + 1.0))
    S, P = np.meshgrid(t, phi, indexing="ij")
    r = _direction(theta_i, np.pi)
    e1 = np.array([np.cos(theta_i), 0.0, np.sin(theta_i)])  # orthonormal frame around r
    e2 = np.array([0.0, 1.0, 0.0])
    sin_a = np.sqrt(1 - S**2)
    wo = S[..., None] * r + sin_a[..., None] * (
        np.cos(P)[..., None] * e1 + np.sin(P)[..., None] * e2
    )
    wo = wo.reshape(-1, 3)
    wi = np.broadcast_to(_direction(theta_i, 0.0), wo.shape)
    params = {"kd": jnp.zeros(3), "ks": jnp.ones(3), "n": jnp.asarray(n)}
    f = np.asarray(evaluate(params, wi, wo))[:, 0]
    jac = 1.0 / ((n + 1.0) * S.ravel() ** n)
    return float(np.sum(f * np.clip(wo[:, 2], 0, None) * jac) * (2 * np.pi / m) / m)


@pytest.mark.parametrize("n", [1.0, 30.0, 1e4])
def test_lobe_albedo_is_one_at_normal_incidence_and_at_most_one_elsewhere(n):
    evaluate = jax.jit(models.get("phong").eval)
    # Midpoint rule on s^(1/(n+1)) (a sqrt-type endpoint at n = 1) and on the horizon
    # kink: error ~3e-5 with 500 x 500 points (measured against 1000 x 1000); 2e-3 leaves a margin.
    assert lobe_albedo(evaluate, n, 0.0) == pytest.approx(1.0, abs=2e-3)
    albedos = [lobe_albedo(evaluate, n, np.radians(t)) for t in (30.0, 60.0, 85.0)]
    assert all(a <= 1.0 + 2e-3 for a in albedos), albedos
    # So kd + ks <= 1 conserves energy (Lewis 1994): the diffuse part integrates to kd.
    kd, ks = 0.4, 0.6
    assert kd + ks * max(albedos) <= 1.0 + 2e-3
