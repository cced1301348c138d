"""Kurt et al. 2010: against a numpy transcription in the paper's angles, Beckmann lobes
integrate to 1, isotropic = anisotropic with mx = my, float32 at grazing."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import models
from brdffit.core.geometry import spherical_to_vector
from tests.helpers import random_pairs

PARAMS = {
    "kd": np.array([0.2, 0.1, 0.05]),
    "ks_1": np.array([0.6, 0.5, 0.4]),
    "f0_1": 0.3,
    "mx_1": 0.08,
    "my_1": 0.25,
    "alpha_1": 0.3,
    "ks_2": np.array([0.1, 0.2, 0.3]),
    "f0_2": 0.8,
    "mx_2": 0.6,
    "my_2": 0.4,
    "alpha_2": 0.9,
}


def paper_kurt(wi, wo, p, n_lobes):
    """Kurt et al. 2010 eqs. 3-5: Beckmann in (theta_h, phi_h), Schlick F, (cos_i cos_o)^a."""
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    th, ph = np.arccos(h[:, 2]), np.arctan2(h[:, 1], h[:, 0])
    kh = np.sum(wi * h, -1)
    f = np.broadcast_to(p["kd"] / np.pi, (len(wi), 3)).copy()
    for l in range(1, n_lobes + 1):
        mx, my = p[f"mx_{l}"], p[f"my_{l}"]
        slope = np.tan(th) ** 2 * (np.cos(ph) ** 2 / mx**2 + np.sin(ph) ** 2 / my**2)
        d = np.exp(-slope) / (np.pi * mx * my * np.cos(th) ** 4)
        fres = p[f"f0_{l}"] + (1 - p[f"f0_{l}"]) * (1 - kh) ** 5
        lobe = fres * d / (4 * kh * (wi[:, 2] * wo[:, 2]) ** p[f"alpha_{l}"])
        f += p[f"ks_{l}"][None] * lobe[:, None]
    return f


def test_matches_paper_transcription():
    model = models.get("kurt", n_lobes=2, anisotropic=True)
    wi = spherical_to_vector(
        np.array([0.3, 1.0, 0.0, 1.5, 0.7, 0.4]), np.array([0.2, 2, 0, 0.1, -1, 1])
    )
    wo = spherical_to_vector(
        np.array([0.3, 1.0, 0.0, 1.4, 0.6, 0.4]), np.array([3.3, 5, 0, 3.1, 2, 1])
    )
    f = np.asarray(model.eval(PARAMS, wi, wo))
    # float64; tan/arccos/arctan2 in the reference against components in the model: 1e-11.
    np.testing.assert_allclose(f, paper_kurt(wi, wo, PARAMS, 2), rtol=1e-11)


def test_anisotropic_with_equal_roughness_is_isotropic():
    iso = models.get("kurt", n_lobes=2)
    aniso = models.get("kurt", n_lobes=2, anisotropic=True)
    p = {k: v for k, v in PARAMS.items() if not k.startswith(("mx", "my"))}
    wi, wo = random_pairs(6, 64)
    a = iso.eval({**p, "m_1": 0.1, "m_2": 0.5}, wi, wo)
    b = aniso.eval({**p, "mx_1": 0.1, "my_1": 0.1, "mx_2": 0.5, "my_2": 0.5}, wi, wo)
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))  # the same operations


@pytest.mark.parametrize("mx,my", [(0.01, 0.01), (0.3, 0.3), (2.0, 2.0), (0.05, 0.5)])
def test_beckmann_lobe_integrates_to_one(mx, my):
    model = models.get("kurt", anisotropic=True)
    x, w = np.polynomial.legendre.leggauss(400)
    v, wv = 0.5 * (x + 1), 0.5 * w
    theta = 0.5 * np.pi * v**2  # dense near the normal: resolves m = 0.01 (theta ~ 0.01 rad)
    phi = 2 * np.pi * np.arange(256) / 256
    t, ph = np.meshgrid(theta, phi, indexing="ij")
    h = spherical_to_vector(t, ph).reshape(-1, 3)
    weight = np.outer(np.pi * v * wv * np.sin(theta) * np.cos(theta), np.full(256, 2 * np.pi / 256))
    d = model.ndf({"mx_1": jnp.asarray(mx), "my_1": jnp.asarray(my)}, 1, jnp.asarray(h))
    # int D cos theta_h dw = 1 (Walter 2007); the rule is accurate to ~1e-9 here.
    np.testing.assert_allclose(float(np.sum(np.asarray(d) * weight.ravel())), 1.0, rtol=1e-8)


def test_grazing_float32_is_finite_and_close_to_float64():
    """(cos_i cos_o)^-alpha at cos 1e-3 and 1e-6 reaches 1e12: float32 must still agree."""
    model = models.get("kurt")
    p = {"kd": jnp.full(3, 0.1), "ks_1": jnp.full(3, 0.5), "f0_1": 0.2, "m_1": 0.5, "alpha_1": 1.0}
    c = np.array([1e-6, 1e-3])
    wi = np.stack([np.sqrt(1 - c**2), 0 * c, c], -1)
    wo = np.stack([-np.sqrt(1 - c**2), 0 * c, c], -1)
    f64 = np.asarray(model.eval(p, wi, wo))
    f32 = np.asarray(jax.jit(model.eval)(p, wi.astype(np.float32), wo.astype(np.float32)))
    assert np.all(np.isfinite(f32)) and f32.dtype == np.float32
    # Cosines of 1e-6 carry float32 rounding of ~1e-7 relative: 1e-5 covers the products.
    np.testing.assert_allclose(f32, f64, rtol=1e-5)
