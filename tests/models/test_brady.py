"""Brady et al. 2014 (``models/brady.py``, the model table's form) against independent checks.

* a direct numpy transcription of the table's formula (arccos, tan, plain power) at fixed
  directions;
* the lobe's normalisation, measured by quadrature (it is not normalised: ``ks`` is no albedo);
* the ``1 / (4 cos_d)`` factor is the half-vector Jacobian: the directional albedo of the
  specular term equals the h-space integral of its lobe.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import models
from brdffit.models import brady
from tests.helpers import random_pairs

PARAMS = {"kd": [0.1, 0.2, 0.3], "ks": [2.0, 1.5, 1.0], "f0": 0.1, "beta": 0.4, "exponent": 1.2}


def table_formula(wi, wo, p):
    """``rho_d / pi + rho_s F / (4 L.H) exp(-(tan(theta_h) / beta^2)^a)``, Schlick F, numpy."""
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=1, keepdims=True)
    l_dot_h = np.sum(wi * h, axis=1)
    theta_h = np.arccos(np.clip(h[:, 2], -1, 1))
    lobe = np.exp(-((np.tan(theta_h) / p["beta"] ** 2) ** p["exponent"]))
    fresnel = p["f0"] + (1 - p["f0"]) * (1 - l_dot_h) ** 5
    spec = fresnel * lobe / (4 * l_dot_h)
    return np.asarray(p["kd"])[None, :] / np.pi + np.asarray(p["ks"])[None, :] * spec[:, None]


@pytest.mark.parametrize("beta, exponent", [(0.4, 1.2), (0.1, 2.0), (0.8, 0.5), (1.5, 6.0)])
def test_matches_table_formula(beta, exponent):
    model = models.get("brady")
    p = {**PARAMS, "beta": beta, "exponent": exponent}
    wi, wo = random_pairs(21, 60)
    extra_i = np.array([[0, 0, 1.0], [0.6, 0, 0.8], [0.6, 0, 0.8], [0.28, 0.96, 0.0002]])
    extra_o = np.array([[0, 0, 1.0], [-0.6, 0, 0.8], [0, 0.6, 0.8], [-0.96, 0.28, 0.0002]])
    wi, wo = np.concatenate([wi, extra_i]), np.concatenate([wo, extra_o])
    wi, wo = wi / np.linalg.norm(wi, axis=1)[:, None], wo / np.linalg.norm(wo, axis=1)[:, None]
    ours = np.asarray(model.eval({k: np.asarray(v, float) for k, v in p.items()}, wi, wo))
    ref = table_formula(wi, wo, p)
    err = np.max(np.abs(ours / ref - 1))
    print(f"beta {beta}, a {exponent}: max relative difference to the table formula {err:.2e}")
    # float64; log-space power vs arccos/tan/pow: the exponent x carries ~1e-15 |log x| relative
    # error, amplified by x in exp(-x) (x < 750 wherever the value is not 0): below 1e-11.
    assert err < 1e-11


def normalisation(beta: float, a: float) -> float:
    """``2 pi int_0^inf exp(-(t/b)^a) t / (1 + t^2)^2 dt``, ``b = beta^2``, ``t = tan(theta_h)``.

    Substituting ``t = b s``: trapezoid over ln s in [-30, ln(40^(1/a)) + 5] (the lobe is
    below exp(-40) past s = 40^(1/a)), 20001 nodes.
    """
    b = beta**2
    ln_s = np.linspace(-30.0, math.log(40.0) / a + 5.0, 20001)
    s = np.exp(ln_s)
    t = b * s
    integrand = np.exp(-(s**a)) * t / (1 + t * t) ** 2 * (b * s)  # dt = b s d(ln s)
    return 2 * np.pi * np.trapezoid(integrand, ln_s)


@pytest.mark.parametrize("beta, a", [(0.1, 1.0), (0.1, 2.0), (0.3, 0.5), (0.7, 1.5), (1.5, 3.0)])
def test_lobe_normalisation_measured_not_assumed(beta, a):
    # The model's own lobe, integrated over theta_h (midpoint, 200000 nodes in theta_h).
    th = (np.arange(200_000) + 0.5) * (np.pi / 2) / 200_000
    lobe = np.asarray(
        brady.brady_lobe(
            jnp.asarray(np.sin(th) ** 2), jnp.asarray(np.cos(th)), jnp.asarray(beta), jnp.asarray(a)
        )
    )
    n_model = 2 * np.pi * np.sum(lobe * np.cos(th) * np.sin(th)) * (np.pi / 2) / 200_000
    n_ref = normalisation(beta, a)
    asymptote = 2 * np.pi * beta**4 * math.gamma(2 / a) / a  # (1 + t^2)^-2 -> 1 for b -> 0
    print(
        f"beta {beta}, a {a}: int lobe cos d(omega_h) = {n_model:.6g} (1-D {n_ref:.6g}, "
        f"narrow-lobe 2 pi beta^4 Gamma(2/a)/a = {asymptote:.6g})"
    )
    # Two quadratures of a smooth integrand: 1e-6 relative (cusp at theta_h = 0 for a < 1 is
    # integrable and carries weight t^(a+1), resolved by both grids).
    assert n_model == pytest.approx(n_ref, rel=1e-6)
    if beta <= 0.1:  # b = .01: (1 + t^2)^-2 shifts it by ~2 b^2 G(4/a)/G(2/a) = 1.2e-3 at a = 1
        assert n_model == pytest.approx(asymptote, rel=5e-3)


def test_specular_albedo_at_normal_incidence_is_the_h_space_integral():
    # wi = n: wo is h reflected, theta_o = 2 theta_h, cos_d = cos(theta_h), and
    # d(omega_o) = 4 cos_d d(omega_h). With kd = 0 and f0 = 1 (F = 1) the directional albedo
    # int f cos_o d(omega_o) is int lobe(theta_h) cos(2 theta_h) d(omega_h), theta_h < pi/4.
    model = models.get("brady")
    p = {"kd": np.zeros(3), "ks": np.ones(3), "f0": 1.0, "beta": 0.5, "exponent": 1.5}
    n_t, n_p = 400, 64
    t_o = (np.arange(n_t) + 0.5) * (np.pi / 2) / n_t
    p_o = (np.arange(n_p) + 0.5) * 2 * np.pi / n_p
    T, P = np.meshgrid(t_o, p_o, indexing="ij")  # noqa: N806
    wo = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    wi = np.broadcast_to([0.0, 0.0, 1.0], wo.shape)
    f = np.asarray(jax.jit(model.eval)(p, wi, wo))[:, 0]
    albedo = np.sum(f * wo[:, 2] * np.sin(T).reshape(-1)) * (np.pi / 2 / n_t) * (2 * np.pi / n_p)
    th = (np.arange(100_000) + 0.5) * (np.pi / 4) / 100_000
    lobe = np.exp(-((np.tan(th) / 0.25) ** 1.5))
    h_space = 2 * np.pi * np.sum(lobe * np.cos(2 * th) * np.sin(th)) * (np.pi / 4) / 100_000
    print(f"specular albedo at normal incidence {albedo:.6f}, h-space integral {h_space:.6f}")
    assert albedo == pytest.approx(h_space, rel=1e-4)  # midpoint rule, 400 theta_o nodes


def test_lobe_is_exactly_one_at_the_normal_with_finite_gradient():
    one = jnp.ones(1)
    for dtype in (jnp.float32, jnp.float64):
        args = (jnp.zeros(1, dtype), one.astype(dtype), jnp.asarray(0.3, dtype))
        assert float(brady.brady_lobe(*args, jnp.asarray(0.2, dtype))[0]) == 1.0
        grad = jax.grad(lambda a, args=args: brady.brady_lobe(*args, a)[0])(jnp.asarray(0.2, dtype))
        assert float(grad) == 0.0
