"""Lafortune 1997: against the paper's own lobe form (C's per channel, no separate scale),
the Phong case integrates to rho at normal incidence, isotropic = anisotropic with cx = cy."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import ParameterError, models
from brdffit.core.geometry import spherical_to_vector
from tests.helpers import random_pairs

PARAMS = {
    "kd": np.array([0.1, 0.2, 0.3]),
    "rho_1": np.array([0.5, 0.4, 0.3]),
    "cx_1": -1.0,
    "cy_1": -1.1,
    "n_1": 150.0,
    "rho_2": np.array([0.2, 0.1, 0.3]),
    "cx_2": 0.9,
    "cy_2": 0.6,
    "n_2": 3.0,
}


def paper_lafortune(wi, wo, p, n_lobes):
    """Lafortune et al. 1997 eq. 5 with the paper's coefficients, channel by channel:
    ``kd/pi + sum [Cx ux vx + Cy uy vy + Cz uz vz]^n``, zero where the bracket is <= 0."""
    f = np.broadcast_to(p["kd"] / np.pi, (len(wi), 3)).copy()
    for l in range(1, n_lobes + 1):
        n = p[f"n_{l}"]
        cz = (p[f"rho_{l}"] * (n + 2) / (2 * np.pi)) ** (1 / n)  # (3,): one Cz per channel
        cx, cy = p[f"cx_{l}"] * cz, p[f"cy_{l}"] * cz
        base = (
            cx[None] * (wi[:, 0] * wo[:, 0])[:, None]
            + cy[None] * (wi[:, 1] * wo[:, 1])[:, None]
            + cz[None] * (wi[:, 2] * wo[:, 2])[:, None]
        )
        f += np.where(base > 0, np.abs(base) ** n, 0.0)
    return f


def test_matches_paper_coefficients():
    model = models.get("lafortune", n_lobes=2, anisotropic=True)
    wi = spherical_to_vector(
        np.array([0.3, 1.0, 0.0, 1.5, 0.7, 0.4]), np.array([0.2, 2, 0, 0.1, -1, 1])
    )
    wo = spherical_to_vector(
        np.array([0.3, 1.0, 0.0, 1.4, 0.6, 0.4]), np.array([3.3, 5, 0, 3.1, 2, 1])
    )
    f = np.asarray(model.eval(PARAMS, wi, wo))
    ref = paper_lafortune(wi, wo, PARAMS, 2)
    # float64; the round trip Cz = (rho (n+2)/(2 pi))^(1/n), Cz^n costs ~n eps: 1e-11.
    np.testing.assert_allclose(f, ref, rtol=1e-11)


def test_anisotropic_with_equal_ratios_is_isotropic():
    iso = models.get("lafortune", n_lobes=2)
    aniso = models.get("lafortune", n_lobes=2, anisotropic=True)
    p = {k: v for k, v in PARAMS.items() if not k.startswith(("cx", "cy"))}
    wi, wo = random_pairs(4, 64)
    a = iso.eval({**p, "cxy_1": -1.3, "cxy_2": 0.7}, wi, wo)
    b = aniso.eval({**p, "cx_1": -1.3, "cy_1": -1.3, "cx_2": 0.7, "cy_2": 0.7}, wi, wo)
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))  # the same operations


@pytest.mark.parametrize("n", [0.5, 30.0, 1e4])
def test_phong_lobe_albedo_at_normal_incidence_is_rho(n):
    """cx = cy = -1 is the normalised Phong lobe: albedo rho at normal incidence, less elsewhere."""
    model = models.get("lafortune")
    x, w = np.polynomial.legendre.leggauss(400)
    v, wv = 0.5 * (x + 1), 0.5 * w
    theta = 0.5 * np.pi * v**2  # dense near the mirror direction for lobes down to n = 1e4
    w_theta = np.pi * v * wv * np.sin(theta)
    phi = 2 * np.pi * np.arange(64) / 64
    t, ph = np.meshgrid(theta, phi, indexing="ij")
    wo = spherical_to_vector(t, ph).reshape(-1, 3)
    weight = np.outer(w_theta, np.full(64, 2 * np.pi / 64)).ravel() * wo[:, 2]
    p = {"kd": jnp.zeros(3), "rho_1": jnp.array([1.0, 0.5, 0.25]), "cxy_1": -1.0, "n_1": n}
    albedo = jax.jit(lambda wi: model.eval(p, wi, wo).T @ weight)
    a_normal = np.asarray(albedo(np.broadcast_to([0.0, 0.0, 1.0], wo.shape)))
    # The rule integrates cos^(n+1) to ~1e-9 for n up to 1e4 (400 nodes, 30 in the lobe).
    np.testing.assert_allclose(a_normal, [1.0, 0.5, 0.25], rtol=1e-8)
    if n < 100:  # the rule is centred on the normal: it resolves oblique broad lobes only
        wi = np.broadcast_to([np.sin(1.2), 0.0, np.cos(1.2)], wo.shape)
        assert np.all(np.asarray(albedo(wi)) < np.array([1.0, 0.5, 0.25]))  # horizon cut


def test_lobe_count_is_validated():
    with pytest.raises(ParameterError, match="n_lobes"):
        models.get("lafortune", n_lobes=0)
    assert [p.name for p in models.get("lafortune", n_lobes=2).parameters] == [
        "kd",
        "rho_1",
        "cxy_1",
        "n_1",
        "rho_2",
        "cxy_2",
        "n_2",
    ]
