"""STD (``models/std.py``, Ribardière et al. 2017) against independent checks.

* Quadrature: ``int D cos theta_h dw = 1`` and Smith's projected-area identity
  ``int <wo, m>+ D(m) dm = cos theta_o (1 + Lambda(wo))``, which checks ``Lambda`` against
  ``D`` alone, over the parameter bounds. Gauss-Legendre panels in ``theta`` (geometric
  towards the peak, split at the kink of ``<wo, m>+``) and Gauss-Jacobi with the exact
  horizon power ``(pi/2 - theta)^beta`` of the heavy Student-t tail in the last panel.
* mpmath: ``Lambda`` from Smith's 1-D integral over the slope marginal (quadrature, 30
  digits); the whole BRDF from the paper's formulas (eq. 13 with the hypergeometric S2 of
  eq. 15, ``tests/references_std.py``), also at the bounds and the extreme directions.
* Limits: ``gamma = 2`` is GGX and ``gamma -> inf`` Beckmann (``models/_terms.py``).
* The custom JVP of ``Lambda`` against plain autodiff through the continued fraction.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from scipy import special

from brdffit import models
from brdffit.models import _terms, std
from brdffit.models.check import extreme_pairs, params_at_bounds
from tests.cases import CASES
from tests.helpers import random_pairs
from tests.references_std import reference

GAMMAS = [1.51, 1.7, 2.0, 3.3, 12.0, 100.0]  # both bounds, GGX, and between
ROWS = [c for c in CASES if c.model == "std"]


def _theta_rule(width: float, kinks: tuple[float, ...], beta: float, delta: float = 1e-2):
    """Nodes and weights for ``int_0^{pi/2} f(theta) d theta``.

    ``f`` is peaked at 0 with ``width``, kinked at ``kinks`` (``0 < kink < pi/2 - delta``)
    and ``~ (pi/2 - theta)^beta`` times a smooth factor at the horizon. 24-node
    Gauss-Legendre panels (geometric from ``width/16``, towards the horizon and on both
    sides of each kink) up to ``pi/2 - delta``, then 40-node Gauss-Jacobi with weight
    ``(pi/2 - theta)^beta`` (plain Gauss-Legendre where ``beta > 2`` is smooth enough).
    """
    top = np.pi / 2 - delta
    graded = [
        [0.0, top],
        np.geomspace(width / 16, top, 40),
        np.pi / 2 - np.geomspace(delta, 1.5, 20),
    ]
    for k in kinks:  # a one-sided (theta - k)^(3/2) term: panels graded towards the kink
        steps = np.geomspace(1e-12, 1.0, 30)
        graded += [k - k * steps, k + (top - k) * steps]
    ends = np.unique(np.clip(np.concatenate(graded), 0.0, top))
    x, w = np.polynomial.legendre.leggauss(24)
    lo, hi = ends[:-1, None], ends[1:, None]
    theta = (0.5 * (hi - lo) * x + 0.5 * (hi + lo)).ravel()
    weight = (0.5 * (hi - lo) * w).ravel()
    if beta > 2.0:  # u^beta is smooth enough for Gauss-Legendre (and Jacobi overflows)
        xj, wj = np.polynomial.legendre.leggauss(40)
        u, wj = 0.5 * delta * (1.0 + xj), 0.5 * delta * wj
    else:
        xj, wj = special.roots_jacobi(40, 0.0, beta)  # weight (1 + x)^beta on [-1, 1]
        u = 0.5 * delta * (1.0 + xj)  # pi/2 - theta
        wj = (0.5 * delta) ** (beta + 1.0) * wj / u**beta
    return np.concatenate([theta, np.pi / 2 - u]), np.concatenate([weight, wj])


@functools.cache
def _jitted(anisotropic: bool):
    model = models.get("std", anisotropic=anisotropic, diffuse=False)
    return jax.jit(model.ndf), jax.jit(model.lambda_)


def _p(gamma: float, ax: float, ay: float | None = None) -> dict:
    out = {"gamma": jnp.asarray(gamma)}
    if ay is None:
        return out | {"alpha": jnp.asarray(ax)}
    return out | {"alpha_x": jnp.asarray(ax), "alpha_y": jnp.asarray(ay)}


@pytest.mark.parametrize("gamma", GAMMAS)
@pytest.mark.parametrize(("ax", "ay"), [(1e-4, None), (0.05, None), (2.0, None), (0.05, 0.4)])
def test_ndf_is_normalised(gamma, ax, ay):
    ndf = _jitted(ay is not None)[0]
    theta, w = _theta_rule(min(ax, ay or ax), (), 2.0 * gamma - 3.0)  # D cos sin ~ u^(2g-3)
    n_phi = 512 if ay is not None else 1  # trapezoid in phi: spectral for the smooth D(phi)
    phi = np.arange(n_phi) * 2.0 * np.pi / n_phi
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    h = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], -1)
    d = np.asarray(ndf(_p(gamma, ax, ay), jnp.asarray(h.reshape(-1, 3)))).reshape(tt.shape)
    total = np.sum(d * (np.cos(theta) * np.sin(theta) * w)[:, None]) * 2.0 * np.pi / n_phi
    # float64 rules of ~2500 nodes in theta; measured error <= 1.4e-15 over the grid.
    assert total == pytest.approx(1.0, abs=1e-11), total


@pytest.mark.parametrize("gamma", GAMMAS)
@pytest.mark.parametrize("alpha", [0.01, 0.3, 2.0])
def test_smith_projected_area_identity(gamma, alpha):
    """``int <wo, m>+ D(m) dm = cos theta_o (1 + Lambda(wo))`` (Heitz 2014, eq. 17 with G1)."""
    ndf, lam = _jitted(False)
    p = _p(gamma, alpha)
    for theta_o in (0.1, 0.7, 1.3, 1.55, np.pi / 2 - 1e-3):
        theta, w = _theta_rule(alpha, (np.pi / 2 - theta_o,), 2.0 * gamma - 4.0)
        # the phi integral of max(0, A + B cos phi), A = cos_o cos_m, B = sin_o sin_m
        a, b = np.cos(theta_o) * np.cos(theta), np.sin(theta_o) * np.sin(theta)
        phi0 = np.arccos(np.clip(-a / np.maximum(b, 1e-300), -1.0, 1.0))
        ring = np.where(a >= b, 2.0 * np.pi * a, 2.0 * (a * phi0 + b * np.sin(phi0)))
        h = np.stack([np.sin(theta), 0.0 * theta, np.cos(theta)], -1)
        d = np.asarray(ndf(p, jnp.asarray(h)))
        lhs = np.sum(d * ring * np.sin(theta) * w)
        wo = jnp.asarray([[np.sin(theta_o), 0.0, np.cos(theta_o)]])
        lam_o = float(lam(p, wo)[0])
        # Both sides in float64; measured <= 3e-11 (the rule at gamma = 1.51, alpha = 0.01).
        assert lhs / np.cos(theta_o) == pytest.approx(1.0 + lam_o, rel=1e-10), theta_o


def _lambda_smith_mp(z: float, gamma: float) -> float:
    """``Lambda = (1/z) int_z^inf (u - z) P2(u) du`` by mpmath quadrature (30 digits).

    ``P2(u) = K sqrt(g-1) (1 + u^2/(g-1))^(1/2-g)`` is the slope marginal in units of
    ``alpha``; with ``u = sqrt(g-1) cot(psi)`` the tail maps to ``psi in (0, psi_z)``:
    ``Lambda = K (g-1)/z int_0^psi_z (sqrt(g-1) cos psi - z sin psi) sin^(2g-4) psi dpsi``,
    a positive integrand. For ``g < 2`` the ``psi^(2g-4)`` singularity is removed by
    ``w = psi^(2g-3)``.
    """
    with mp.workdps(30):
        g, z = mp.mpf(gamma), mp.mpf(z)
        k = mp.gamma(g - 0.5) / (mp.gamma(g) * mp.sqrt(mp.pi))
        psi_z = mp.atan(mp.sqrt(g - 1) / z)
        core = lambda psi: mp.sqrt(g - 1) * mp.cos(psi) - z * mp.sin(psi)  # noqa: E731
        # mp.quad's tolerance is absolute: the integrals are scaled to O(1) on [0, 1]; for large
        # gamma sin^(2g-4) peaks within ~1/(2g) of t = 1: breakpoints there.
        if gamma >= 2.0:  # psi = psi_z t
            top = mp.sin(psi_z)
            f = lambda t: core(psi_z * t) * (mp.sin(psi_z * t) / top) ** (2 * g - 4)  # noqa: E731
            breaks = [0, 0.5, 0.9, 0.97, 0.99, 0.997, 0.999, 1]
            integral = psi_z * top ** (2 * g - 4) * mp.quad(f, breaks)
        else:  # w = psi^e = psi_z^e t
            e = 2 * g - 3

            def f(t):
                psi = psi_z * t ** (1 / e)
                return core(psi) * (mp.sin(psi) / psi) ** (2 * g - 4) / e

            integral = psi_z**e * mp.quad(f, [0, 1])
        return float(k * (g - 1) / z * integral)


@pytest.mark.parametrize("gamma", GAMMAS)
def test_lambda_matches_smith_integral(gamma):
    lam = _jitted(False)[1]
    theta = np.array([1e-6, 0.05, 0.5, 1.0, 1.4, 1.55, np.pi / 2 - 1e-6])
    v = np.stack([np.sin(theta), 0.0 * theta, np.cos(theta)], -1)
    for alpha in (1e-4, 0.3, 2.0):
        got = np.asarray(lam(_p(gamma, alpha), jnp.asarray(v)))
        want = np.array([_lambda_smith_mp(1.0 / (alpha * np.tan(t)), gamma) for t in theta])
        # Measured: 1.5e-12 relative, 1e-13 (1 + Lambda) absolute, both at gamma = 100 (the
        # gammaln difference in K, amplified by the cancellation 1/2 - Q where Lambda is
        # small); 2e-15 for gamma <= 2. Underflowing values (Lambda ~ z^(2-2 gamma) at normal
        # incidence) are compared absolutely.
        np.testing.assert_allclose(got, want, rtol=5e-12, atol=1e-300, err_msg=str(alpha))
        assert np.all(np.abs(got - want) <= 3e-13 * (1.0 + want)), alpha  # in G1 terms


@pytest.mark.parametrize("case", ROWS, ids=[c.id for c in ROWS])
def test_brdf_matches_mpmath_transcription_of_the_paper(case):
    model, params = case.build()
    wi, wo = random_pairs(11, 24)
    ei, eo = extreme_pairs()
    wi, wo = np.concatenate([wi, ei]), np.concatenate([wo, eo])
    for label, p in (
        ("row", params),
        ("low", params_at_bounds(model, "low")),
        ("high", params_at_bounds(model, "high")),
    ):
        want = reference(model, {k: np.asarray(v) for k, v in p.items()}, wi, wo).astype(float)
        got = np.asarray(model.eval(p, wi, wo))
        # Measured <= 2e-13 relative (G at gamma = 100). Values below 1e-60 come only
        # from Schlick (1 - wi.h)^5 with f0 = 0 at wi.h = 1 - ulp: set by the input's last bit.
        np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-60, err_msg=label)


def test_gamma_two_is_ggx():
    rng = np.random.default_rng(3)
    h = rng.normal(size=(200, 3))
    h[:, 2] = np.abs(h[:, 2]) + 1e-3
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    v = jnp.asarray(h)
    two = jnp.asarray(2.0)
    for ax, ay in [(1e-4, 1e-4), (0.3, 0.3), (2.0, 2.0), (0.05, 0.6)]:
        a_x, a_y = jnp.asarray(ax), jnp.asarray(ay)
        # float64: exp(log D) vs the rational GGX form, 1e-13 (|log D| < 40 here).
        np.testing.assert_allclose(
            std.std_d(v, a_x, a_y, two), _terms.ggx_d(v, a_x, a_y), rtol=1e-13
        )
        np.testing.assert_allclose(
            std.std_lambda(v, a_x, a_y, two), _terms.ggx_lambda(v, a_x, a_y), rtol=1e-13
        )


def test_large_gamma_approaches_beckmann():
    """D and Lambda differ from Beckmann's by O(1/gamma): checked at 10, 100, 1000."""
    theta = np.linspace(0.0, 1.5, 200)
    v = jnp.asarray(np.stack([np.sin(theta), 0.0 * theta, np.cos(theta)], -1))
    alpha = jnp.asarray(0.4)
    near = np.tan(theta) <= 2.0 * 0.4  # D compared where tan <= 2 alpha (the lobe)
    d_beck = np.asarray(_terms.beckmann_d(v, alpha, alpha))
    lam_beck = np.asarray(_terms.beckmann_lambda(v, alpha, alpha))
    errs = []
    for gamma in (10.0, 100.0, 1000.0):
        g = jnp.asarray(gamma)
        d = np.asarray(std.std_d(v, alpha, alpha, g))
        lam = np.asarray(std.std_lambda(v, alpha, alpha, g))
        err_d = np.max(np.abs(d[near] / d_beck[near] - 1.0))
        err_g = np.max(np.abs(lam - lam_beck) / (1.0 + lam_beck))  # error in G1 terms
        errs.append((err_d, err_g))
        # expansion: log(D/D_beck) = -(q - q^2/2)/(gamma - 1) + ..., |q - q^2/2| <= 4
        assert err_d <= 4.5 / (gamma - 1.0) and err_g <= 1.0 / gamma, (gamma, err_d, err_g)
    print("errors in D, G1 at gamma = 10, 100, 1000:", errs)
    assert errs[2][0] < errs[1][0] / 8 and errs[2][1] < errs[1][1] / 8  # ~1/gamma


def _plain_lambda(a, g, v):  # the primal without the custom rule
    return std._lambda_of_s((g - 1.0) * _terms.projected_roughness2_tan2(v, a, a), g)[0]


def _custom_lambda(a, g, v):
    return std.std_lambda(v, a, a, g)


# compiled once for the four rows below (op by op, the first row took 14 s)
_JAC_PLAIN = jax.jit(jax.jacfwd(_plain_lambda, (0, 1)))
_JAC_CUSTOM = (
    jax.jit(jax.jacfwd(_custom_lambda, (0, 1))),
    jax.jit(jax.jacrev(_custom_lambda, (0, 1))),
)


@pytest.mark.parametrize(("alpha", "gamma"), [(0.2, 2.0), (0.01, 1.51), (1.5, 30.0), (2.0, 100.0)])
def test_lambda_jvp_matches_autodiff_through_the_fraction(alpha, gamma):
    theta = np.array([1e-5, 0.05, 0.3, 0.8, 1.2, 1.5, np.pi / 2 - 1e-6])
    v = jnp.asarray(np.stack([np.sin(theta), 0.0 * theta, np.cos(theta)], -1))
    args = (jnp.asarray(alpha), jnp.asarray(gamma), v)
    ref = _JAC_PLAIN(*args)
    for jac in _JAC_CUSTOM:
        for a, b in zip(jac(*args), ref, strict=True):
            # closed-form dLambda/ds vs autodiff of E and the fraction: float64 rounding,
            # amplified by gamma in the gammaln/digamma terms: measured 1.1e-12 at gamma = 100.
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-11, atol=1e-300)
