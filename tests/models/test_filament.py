"""Filament (``models/filament.py``) against a line-by-line numpy transcription of Filament's
shaders (``brdf.fs``, ``shading_model_standard.fs``, ``shading_model_cloth.fs``,
``getPixelParams`` of ``common_lighting.fs``), plus normalisation and limit checks."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import models
from brdffit.models import _terms, filament
from tests.helpers import hemisphere_integral

PI = np.pi
WI = np.array([[0.0, 0.0, 1], [0.5, 0.1, 0], [0.3, -0.2, 0], [0.8, 0.3, 0], [-0.2, 0.9, 0]])
WO = np.array([[0.1, 0.2, 0], [-0.48, -0.12, 0], [0.6, 0.5, 0], [-0.1, -0.7, 0], [0.9, 0.1, 0]])
for _v in (WI, WO):
    _v[:, 2] = np.sqrt(1.0 - _v[:, 0] ** 2 - _v[:, 1] ** 2)


# --- brdf.fs, transcribed -------------------------------------------------------------
def D_GGX(roughness, NoH):  # noqa: N802, N803
    one_minus = 1.0 - NoH * NoH
    a = NoH * roughness
    k = roughness / (one_minus + a * a)
    return k * k / PI


def D_GGX_Anisotropic(at, ab, ToH, BoH, NoH):  # noqa: N802, N803
    a2 = at * ab
    d2 = (ab * ToH) ** 2 + (at * BoH) ** 2 + (a2 * NoH) ** 2
    b2 = a2 / d2
    return a2 * b2 * b2 / PI


def D_Charlie(roughness, NoH):  # noqa: N802, N803
    inv_alpha = 1.0 / roughness
    sin2h = np.maximum(1.0 - NoH * NoH, 0.0078125)
    return (2.0 + inv_alpha) * sin2h ** (inv_alpha * 0.5) / (2.0 * PI)


def V_SmithGGXCorrelated(roughness, NoV, NoL):  # noqa: N802, N803
    a2 = roughness * roughness
    lambda_v = NoL * np.sqrt((NoV - a2 * NoV) * NoV + a2)
    lambda_l = NoV * np.sqrt((NoL - a2 * NoL) * NoL + a2)
    return 0.5 / (lambda_v + lambda_l)


def V_SmithGGXCorrelated_Anisotropic(at, ab, ToV, BoV, ToL, BoL, NoV, NoL):  # noqa: N802, N803
    lambda_v = NoL * np.sqrt((at * ToV) ** 2 + (ab * BoV) ** 2 + NoV**2)
    lambda_l = NoV * np.sqrt((at * ToL) ** 2 + (ab * BoL) ** 2 + NoL**2)
    return 0.5 / (lambda_v + lambda_l)


def V_Kelemen(LoH):  # noqa: N802, N803
    return 0.25 / (LoH * LoH)


def V_Neubelt(NoV, NoL):  # noqa: N802, N803
    return 1.0 / (4.0 * (NoL + NoV - NoL * NoV))


def F_Schlick(f0, f90, VoH):  # noqa: N802, N803
    return f0 + (f90 - f0) * (1.0 - VoH) ** 5


def Fd_Burley(roughness, NoV, NoL, LoH):  # noqa: N802, N803
    f90 = 0.5 + 2.0 * roughness * LoH * LoH
    return F_Schlick(1.0, f90, NoL) * F_Schlick(1.0, f90, NoV) / PI


def Fd_Wrap(NoL, w):  # noqa: N802, N803
    return np.clip((NoL + w) / (1.0 + w) ** 2, 0.0, 1.0)


def diffuse(kind, roughness, NoV, NoL, LoH):  # noqa: N803
    return Fd_Burley(roughness, NoV, NoL, LoH) if kind == "burley" else np.full_like(NoV, 1 / PI)


# --- surfaceShading / getPixelParams, transcribed, divided by NoL (BRDF, no cosine) ----
def glsl_standard(p, kind, aniso=False, coat=False, sheen=False):
    l, v = WI, WO
    h = (l + v) / np.linalg.norm(l + v, axis=1, keepdims=True)
    NoV, NoL, NoH, LoH = v[:, 2], l[:, 2], h[:, 2], np.sum(l * h, axis=1)  # noqa: N806
    bc, m = np.asarray(p["base_color"]), p["metallic"]
    diffuse_color = bc * (1.0 - m)
    f0 = bc * m + 0.16 * p["reflectance"] ** 2 * (1.0 - m)
    pr = p["roughness"]
    if coat:
        ccr = np.clip(p["clear_coat_roughness"], 0.045, 1.0)
        poly = np.clip(f0 * (f0 * (0.941892 - 0.263008 * f0) + 0.346479) - 0.0285998, 0, 1)
        f0 = f0 + (poly - f0) * p["clear_coat"]  # mix(f0, f0ClearCoatToSurface(f0), cc)
        pr = pr + (max(pr, ccr) - pr) * p["clear_coat"]
    pr = np.clip(pr, 0.045, 1.0)
    r = pr * pr
    F = F_Schlick(f0[None, :], 1.0, LoH[:, None])  # noqa: N806
    if aniso:
        at = max(r * (1.0 + p["anisotropy"]), 0.002025)
        ab = max(r * (1.0 - p["anisotropy"]), 0.002025)
        D = D_GGX_Anisotropic(at, ab, h[:, 0], h[:, 1], NoH)  # noqa: N806
        V = V_SmithGGXCorrelated_Anisotropic(at, ab, v[:, 0], v[:, 1], l[:, 0], l[:, 1], NoV, NoL)  # noqa: N806
    else:
        D, V = D_GGX(r, NoH), V_SmithGGXCorrelated(r, NoV, NoL)  # noqa: N806
    Fr = (D * V)[:, None] * F  # noqa: N806
    Fd = diffuse_color[None, :] * diffuse(kind, r, NoV, NoL, LoH)[:, None]  # noqa: N806
    color = Fd + Fr  # energyCompensation = 1
    if sheen:
        sr = np.clip(p["sheen_roughness"], 0.045, 1.0) ** 2
        color = color + (D_Charlie(sr, NoH) * V_Neubelt(NoV, NoL))[:, None] * p["sheen_color"]
    if coat:
        Fcc = F_Schlick(0.04, 1.0, LoH) * p["clear_coat"]  # noqa: N806
        clear = D_GGX(ccr * ccr, NoH) * V_Kelemen(LoH) * Fcc
        color = color * (1.0 - Fcc)[:, None] + clear[:, None]
    return color


def glsl_cloth(p, kind, subsurface=False):
    l, v = WI, WO
    h = (l + v) / np.linalg.norm(l + v, axis=1, keepdims=True)
    NoV, NoL, NoH, LoH = v[:, 2], l[:, 2], h[:, 2], np.sum(l * h, axis=1)  # noqa: N806
    r = np.clip(p["roughness"], 0.045, 1.0) ** 2
    Fr = (D_Charlie(r, NoH) * V_Neubelt(NoV, NoL))[:, None] * p["sheen_color"]  # noqa: N806
    dif = diffuse(kind, r, NoV, NoL, LoH)
    if subsurface:
        dif = dif * Fd_Wrap(NoL, 0.5)
    Fd = dif[:, None] * p["base_color"]  # noqa: N806
    if subsurface:
        Fd = Fd * np.clip(p["subsurface_color"] + NoL[:, None], 0.0, 1.0)  # noqa: N806
        return (Fd + Fr * NoL[:, None]) / NoL[:, None]  # shader omits NoL: divide it out
    return Fd + Fr


STANDARD = {"base_color": [0.8, 0.5, 0.2], "metallic": 0.3, "reflectance": 0.6, "roughness": 0.4}
EXTRA = {
    "anisotropy": 0.55,
    "clear_coat": 0.7,
    "clear_coat_roughness": 0.6,  # above roughness: the base-roughness hack is active
    "sheen_color": [0.3, 0.2, 0.1],
    "sheen_roughness": 0.5,
}


@pytest.mark.parametrize(
    "opts",
    [
        {},
        {"diffuse": "burley"},
        {"anisotropy": True},
        {"clearcoat": True},
        {"sheen": True},
        {"diffuse": "burley", "anisotropy": True, "clearcoat": True, "sheen": True},
    ],
    ids=str,
)
def test_standard_matches_shader_transcription(opts):
    model = models.get("filament", **opts)
    p = {k: v for k, v in (STANDARD | EXTRA).items() if k in [q.name for q in model.parameters]}
    ref = glsl_standard(
        {k: np.asarray(v) for k, v in p.items()},
        opts.get("diffuse", "lambert"),
        opts.get("anisotropy", False),
        opts.get("clearcoat", False),
        opts.get("sheen", False),
    )
    # float64; the shader's 1 - NoH^2 (ours uses hx^2 + hy^2) costs ~1e-15 / alpha^2.
    np.testing.assert_allclose(np.asarray(jax.jit(model.eval)(p, WI, WO)), ref, rtol=1e-10)


@pytest.mark.parametrize(("kind", "subsurface"), [("lambert", False), ("burley", True)])
def test_cloth_matches_shader_transcription(kind, subsurface):
    model = models.get("filament", shading="cloth", diffuse=kind, subsurface=subsurface)
    p = {"base_color": [0.2, 0.3, 0.5], "sheen_color": [0.5, 0.4, 0.3], "roughness": 0.7}
    if subsurface:
        p["subsurface_color"] = [0.4, 0.2, 0.1]
    ref = glsl_cloth({k: np.asarray(v) for k, v in p.items()}, kind, subsurface)
    ev = jax.jit(model.eval)
    np.testing.assert_allclose(np.asarray(ev(p, WI, WO)), ref, rtol=1e-10)
    if subsurface:  # the wrap term depends on NoL alone: not reciprocal, as flagged
        assert not model.reciprocal
        back = np.asarray(ev(p, WO, WI))
        assert np.max(np.abs(back / ref - 1.0)) > 0.1


def test_switched_on_features_at_zero_reduce_to_the_base_model():
    base = models.get("filament", diffuse="burley")
    ref = np.asarray(jax.jit(base.eval)(STANDARD, WI, WO))
    for opts, zero in [
        ({"anisotropy": True}, {"anisotropy": 0.0}),
        ({"clearcoat": True}, {"clear_coat": 0.0, "clear_coat_roughness": 0.9}),
        ({"sheen": True}, {"sheen_color": [0.0] * 3, "sheen_roughness": 0.5}),
    ]:
        ev = jax.jit(models.get("filament", diffuse="burley", **opts).eval)
        out = ev(STANDARD | zero, WI, WO)
        # same float64 operations up to a few reassociations: 1e-13.
        np.testing.assert_allclose(np.asarray(out), ref, rtol=1e-13)


def test_visibility_is_height_correlated_smith_over_4_cosines():
    # V = G2 / (4 NoL NoV) with G2 = 1 / (1 + Lambda_l + Lambda_v) (Heitz 2014, eq. 99).
    at, ab = jnp.asarray(0.3), jnp.asarray(0.08)
    wi, wo = jnp.asarray(WI), jnp.asarray(WO)
    v = filament.smith_ggx_v(wi, wo, at, ab)
    g2 = 1.0 / (1.0 + _terms.ggx_lambda(wi, at, ab) + _terms.ggx_lambda(wo, at, ab))
    np.testing.assert_allclose(np.asarray(v * 4 * wi[:, 2] * wo[:, 2]), np.asarray(g2), rtol=1e-13)


CHARLIE = jax.jit(filament.charlie_d)


@pytest.mark.parametrize("a", [0.002025, 0.05, 0.3, 1.0])
def test_charlie_is_normalised_up_to_filaments_floor(a):
    # panel ends of the quadrature put on the floor's kink at t = 1 - cos(theta0)
    kink = 1.0 - np.sqrt(1.0 - 2.0**-7)
    total = hemisphere_integral(lambda h: CHARLIE(h, jnp.asarray(a)), 16.0 * kink)
    # Without the floor the integral is (2 + 1/a) int_0^1 s^(1/a + 1) ds = 1 exactly; the
    # floor sin^2 >= 2^-7 adds, over theta_h < theta0 = asin(2^-3.5), the integral of
    # (D(theta0) - D(theta)) cos sin 2 pi dtheta; computed here by numpy quadrature.
    x, w = np.polynomial.legendre.leggauss(200)
    t0 = np.arcsin(2.0**-3.5)
    th, wt = 0.5 * t0 * (x + 1.0), 0.5 * t0 * w
    d = lambda s2: (2 + 1 / a) * s2 ** (0.5 / a) / (2 * PI)  # noqa: E731
    excess = np.sum((d(2.0**-7) - d(np.sin(th) ** 2)) * np.cos(th) * np.sin(th) * wt) * 2 * PI
    # float64 quadrature: 1e-10.
    assert total == pytest.approx(1.0 + excess, abs=1e-10)
