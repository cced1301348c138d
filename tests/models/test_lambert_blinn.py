"""Lambert and normalised Blinn-Phong against closed forms and quadrature."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import models
from brdffit.models.blinn_phong import blinn_lobe
from tests.helpers import hemisphere_integral, random_pairs


def test_lambert_is_albedo_over_pi_and_its_albedo_is_kd():
    m = models.get("lambert")
    kd = jnp.array([0.2, 0.5, 0.8])
    wi, wo = random_pairs(0, 64)
    np.testing.assert_array_equal(
        np.asarray(m.eval({"kd": kd}, wi, wo)), np.broadcast_to(np.asarray(kd) / np.pi, (64, 3))
    )

    # int f cos dw over the hemisphere, by quadrature of the constant: kd (1e-12).
    def g(h):
        return m.eval({"kd": kd}, jnp.broadcast_to(jnp.array([0.0, 0.0, 1.0]), h.shape), h)[:, 1]

    np.testing.assert_allclose(hemisphere_integral(g, 1.0), 0.5, rtol=1e-12)


def test_blinn_phong_matches_hand_formula():
    m = models.get("blinn_phong")
    p = {"kd": jnp.array([0.1, 0.2, 0.3]), "ks": jnp.array([0.3, 0.2, 0.1]), "n": jnp.array(77.0)}
    wi, wo = random_pairs(1, 200)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=1, keepdims=True)
    want = (
        np.array([0.1, 0.2, 0.3]) / np.pi
        + np.array([0.3, 0.2, 0.1]) * (77 + 8) / (8 * np.pi) * h[:, 2:3] ** 77
    )
    # Same float64 operations reassociated: 1e-13 relative.
    np.testing.assert_allclose(np.asarray(m.eval(p, wi, wo)), want, rtol=1e-13)


@pytest.mark.parametrize("n", [1.0, 20.0, 1e3, 1e5, 1e6])
def test_blinn_lobe_integral_matches_closed_form(n):
    # int (n+8)/(8 pi) cos^n(t) cos(t) dw = (n+8) / (4 (n+2)): the normalisation is
    # approximate by design (1.5 at n = 1, -> 1/4 for sharp lobes, where the 4 cos_d
    # of the half-vector Jacobian takes over); quadrature to 1e-9.
    total = hemisphere_integral(lambda h: blinn_lobe(h[:, 2], jnp.asarray(n)), 2.0 / (n + 2.0))
    np.testing.assert_allclose(total, (n + 8.0) / (4.0 * (n + 2.0)), rtol=1e-9)
