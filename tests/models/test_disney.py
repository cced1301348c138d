"""Disney 2012 (``models/disney.py``) against independent references.

* a line-by-line numpy transcription of the BRDF Explorer shader ``disney.brdf`` (seed 003),
  including its mon2lin colour conversion, for the full model and with each feature off;
* Mitsuba 3's ``principled`` BSDF where its formulas coincide with Disney 2012;
* the op count of the all-off configuration against a hand-written Burley + GGX;
* GTR1 at alpha = 1, and D integrating to 1 against cos(theta_h).
"""

from __future__ import annotations

import jax
import jax.extend.core as jex
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import models
from brdffit.core.geometry import shading_geometry
from brdffit.models import _terms, disney
from tests.cases import CASES
from tests.helpers import random_pairs

PI = 3.14159265358979323846
# The full-model row of tests/cases_c.py: every parameter inside its bounds, base colour not grey.
_DISNEY = next(c.params for c in CASES if c.model == "disney" and not c.options)
_OFF = dict.fromkeys(
    ("subsurface", "sheen", "clearcoat", "anisotropic", "metallic", "specular_tint"), False
)


# --- the shader, transcribed line by line in numpy (L = wi, V = wo, N = z, X = x, Y = y) ---
def sqr(x):
    return x * x


def mix(x, y, a):
    return x * (1 - a) + y * a


def SchlickFresnel(u):  # noqa: N802 (the shader's names)
    m = np.clip(1 - u, 0, 1)
    m2 = m * m
    return m2 * m2 * m


def GTR1(NdotH, a):  # noqa: N802, N803
    if a >= 1:
        return 1 / PI
    a2 = a * a
    t = 1 + (a2 - 1) * NdotH * NdotH
    return (a2 - 1) / (PI * np.log(a2) * t)


def GTR2_aniso(NdotH, HdotX, HdotY, ax, ay):  # noqa: N802, N803
    return 1 / (PI * ax * ay * sqr(sqr(HdotX / ax) + sqr(HdotY / ay) + NdotH * NdotH))


def smithG_GGX(NdotV, alphaG):  # noqa: N802, N803
    a = alphaG * alphaG
    b = NdotV * NdotV
    return 1 / (NdotV + np.sqrt(a + b - a * b))


def smithG_GGX_aniso(NdotV, VdotX, VdotY, ax, ay):  # noqa: N802, N803
    return 1 / (NdotV + np.sqrt(sqr(VdotX * ax) + sqr(VdotY * ay) + sqr(NdotV)))


def mon2lin(x):
    return np.power(x, 2.2)


def shader_brdf(L, V, p):  # noqa: N803
    """``BRDF(L, V, N, X, Y)`` of disney.brdf for (n, 3) directions; ``p`` uses shader names."""
    X, Y = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])  # noqa: N806
    NdotL, NdotV = L[:, 2], V[:, 2]  # noqa: N806
    H = (L + V) / np.linalg.norm(L + V, axis=1, keepdims=True)  # noqa: N806
    NdotH, LdotH = H[:, 2], np.sum(L * H, axis=1)  # noqa: N806
    Cdlin = mon2lin(np.asarray(p["baseColor"]))  # noqa: N806
    Cdlum = 0.3 * Cdlin[0] + 0.6 * Cdlin[1] + 0.1 * Cdlin[2]  # noqa: N806
    Ctint = Cdlin / Cdlum if Cdlum > 0 else np.ones(3)  # noqa: N806
    Cspec0 = mix(
        p["specular"] * 0.08 * mix(np.ones(3), Ctint, p["specularTint"]), Cdlin, p["metallic"]
    )  # noqa: N806, E501
    Csheen = mix(np.ones(3), Ctint, p["sheenTint"])  # noqa: N806
    FL, FV = SchlickFresnel(NdotL), SchlickFresnel(NdotV)  # noqa: N806
    Fd90 = 0.5 + 2 * LdotH * LdotH * p["roughness"]  # noqa: N806
    Fd = mix(1.0, Fd90, FL) * mix(1.0, Fd90, FV)  # noqa: N806
    Fss90 = LdotH * LdotH * p["roughness"]  # noqa: N806
    Fss = mix(1.0, Fss90, FL) * mix(1.0, Fss90, FV)  # noqa: N806
    ss = 1.25 * (Fss * (1 / (NdotL + NdotV) - 0.5) + 0.5)
    aspect = np.sqrt(1 - p["anisotropic"] * 0.9)
    ax = max(0.001, sqr(p["roughness"]) / aspect)
    ay = max(0.001, sqr(p["roughness"]) * aspect)
    Ds = GTR2_aniso(NdotH, H @ X, H @ Y, ax, ay)  # noqa: N806
    FH = SchlickFresnel(LdotH)  # noqa: N806
    Fs = mix(Cspec0[None, :], np.ones(3)[None, :], FH[:, None])  # noqa: N806
    Gs = smithG_GGX_aniso(NdotL, L @ X, L @ Y, ax, ay)  # noqa: N806
    Gs *= smithG_GGX_aniso(NdotV, V @ X, V @ Y, ax, ay)  # noqa: N806
    Fsheen = FH[:, None] * p["sheen"] * Csheen[None, :]  # noqa: N806
    Dr = GTR1(NdotH, mix(0.1, 0.001, p["clearcoatGloss"]))  # noqa: N806
    Fr = mix(0.04, 1.0, FH)  # noqa: N806
    Gr = smithG_GGX(NdotL, 0.25) * smithG_GGX(NdotV, 0.25)  # noqa: N806
    return (
        ((1 / PI) * mix(Fd, ss, p["subsurface"])[:, None] * Cdlin[None, :] + Fsheen)
        * (1 - p["metallic"])
        + (Gs * Ds)[:, None] * Fs
        + (0.25 * p["clearcoat"] * Gr * Fr * Dr)[:, None]
    )


SHADER_NAMES = {
    "specular_tint": "specularTint",
    "sheen_tint": "sheenTint",
    "clearcoat_gloss": "clearcoatGloss",
}
# The parameter a feature removes; off equals the full model with it at 0.
REMOVES = {
    "subsurface": "subsurface",
    "sheen": "sheen",
    "clearcoat": "clearcoat",
    "anisotropic": "anisotropic",
    "metallic": "metallic",
    "specular_tint": "specularTint",
}


def fixed_pairs() -> tuple[np.ndarray, np.ndarray]:
    """Normal incidence, retro, mirror, near-grazing (cos .02), oblique, plus 57 random pairs."""
    d = [
        ([0, 0, 1], [0, 0, 1]),
        ([0.6, 0, 0.8], [0.6, 0, 0.8]),
        ([0.6, 0, 0.8], [-0.6, 0, 0.8]),
        ([0.6, 0.48, 0.64], [-0.6, -0.48, 0.64]),
        ([0.9998, 0, 0.02], [0, 0.9998, 0.02]),
        ([0.9998, 0, 0.02], [-0.9998, 0, 0.02]),
        ([0.3, -0.4, np.sqrt(0.75)], [0, 0, 1]),
    ]
    wi = np.array([a for a, _ in d], float)
    wo = np.array([b for _, b in d], float)
    ri, ro = random_pairs(11, 57)  # 64 in all: one shape, compiled once
    wi, wo = np.concatenate([wi, ri]), np.concatenate([wo, ro])
    return wi / np.linalg.norm(wi, axis=1, keepdims=True), wo / np.linalg.norm(wo, axis=1)[:, None]


@pytest.mark.parametrize(
    "off", [(), *[(k,) for k in REMOVES], tuple(REMOVES)], ids=lambda o: "off=" + "+".join(o)
)
def test_matches_shader_transcription(off):
    options = {k: k not in off for k in REMOVES}
    model = models.get("disney", **options)
    names = {p.name for p in model.parameters}
    params = {k: np.asarray(v, float) for k, v in _DISNEY.items() if k in names}
    shader = {SHADER_NAMES.get(k, k): v for k, v in _DISNEY.items()}
    # Our base_color is linear: the shader's slider value is its 1/2.2 power (mon2lin undone).
    shader["baseColor"] = np.asarray(_DISNEY["base_color"]) ** (1 / 2.2)
    shader.update({REMOVES[k]: 0.0 for k in off})
    wi, wo = fixed_pairs()
    ours = np.asarray(model.eval(params, wi, wo))
    ref = shader_brdf(wi, wo, shader)
    err = np.max(np.abs(ours / ref - 1))
    print(f"off={off}: max relative difference to the shader {err:.2e}")
    # float64 both; D is written sin^2 + a^2 cos^2 here and 1 + (a^2 - 1) cos^2 (via the
    # anisotropic form) there, and mix() reassociates: a few ulps (measured 6e-15), far below 1e-12.
    assert err < 1e-12


def minimal_reference(params, g):
    """Hand-written Burley diffuse + GGX (seed formulas: GTR2, smithG_GGX, Schlick F0 = .08 s)."""
    r = params["roughness"]
    fl, fv, fh = (1 - g.cos_i) ** 5, (1 - g.cos_o) ** 5, (1 - g.cos_d) ** 5
    fd90 = 0.5 + 2 * g.cos_d**2 * r
    fd = (1 + (fd90 - 1) * fl) * (1 + (fd90 - 1) * fv)
    a2 = jnp.maximum(0.001, r * r) ** 2
    t = 1 + (a2 - 1) * g.cos_h**2
    d = a2 / (jnp.pi * t * t)

    def smith(c):
        return 1 / (c + jnp.sqrt(a2 + c * c - a2 * c * c))

    f0 = 0.08 * params["specular"]
    spec = d * smith(g.cos_i) * smith(g.cos_o) * (f0 + (1 - f0) * fh)
    return params["base_color"][None, :] * (fd / jnp.pi)[:, None] + spec[:, None]


def count_equations(jaxpr) -> int:
    """Primitive equations of a jaxpr, counting inside nested jaxprs (pjit, custom_jvp)."""
    n = 0
    for eqn in jaxpr.eqns:
        subs = list(jex.jaxprs_in_params(eqn.params))
        n += sum(count_equations(s) for s in subs) if subs else 1
    return n


def test_all_features_off_costs_no_more_than_hand_written():
    model = models.get("disney", **_OFF)
    # Cast as eval does (strong float64): weak-typed scalars would add no-op converts to both.
    params = model.cast(
        {**{k: _DISNEY[k] for k in ("base_color", "specular")}, "roughness": 0.3},
        jnp.dtype("float64"),
    )
    wi, wo = random_pairs(4, 64)
    g = shading_geometry(jnp.asarray(wi), jnp.asarray(wo))
    ours = count_equations(jax.make_jaxpr(model.core)(params, g).jaxpr)
    hand = count_equations(jax.make_jaxpr(minimal_reference)(params, g).jaxpr)
    full_model = models.get("disney")
    full = count_equations(jax.make_jaxpr(full_model.core)(full_model.defaults(), g).jaxpr)
    print(f"jaxpr equations: minimal disney {ours}, hand-written {hand}, full disney {full}")
    assert ours <= hand
    np.testing.assert_allclose(  # same function: float64, a few reassociated ulps
        np.asarray(model.core(params, g)), np.asarray(minimal_reference(params, g)), rtol=1e-12
    )


def test_anisotropic_zero_equals_isotropic_form():
    iso, aniso = models.get("disney", anisotropic=False), models.get("disney")
    p = {k: jnp.asarray(v) for k, v in _DISNEY.items() if k != "anisotropic"}
    wi, wo = random_pairs(6, 64)
    a = np.asarray(aniso.eval({**p, "anisotropic": jnp.asarray(0.0)}, wi, wo))
    # float64; different but equivalent D and G forms: 1e-12 covers their rounding.
    np.testing.assert_allclose(a, np.asarray(iso.eval(p, wi, wo)), rtol=1e-12)


def test_gtr1_at_and_near_alpha_one():
    one, gtr1 = jnp.ones(1), jax.jit(_terms.gtr1)
    # sin^2 = 1 gives t = 1: GTR1 = (u / log1p(u)) / pi exactly, 1/pi at alpha = 1.
    assert float(_terms.gtr1(one, jnp.asarray(1.0))[0]) == pytest.approx(1 / np.pi, 1e-15)
    for u in (-3e-4, -1.0001e-4, -0.9999e-4, -2e-5, 2e-5, 0.9999e-4, 1.0001e-4, 3e-4):
        alpha = np.sqrt(1 + u)
        exact = (alpha**2 - 1) / np.log1p(alpha**2 - 1) / np.pi  # u from the rounded alpha
        got = float(gtr1(one, jnp.asarray(alpha))[0])
        # the series truncation is |u|^3/24 < 6e-14 at the 1e-4 switch; float64 otherwise.
        assert got == pytest.approx(exact, rel=1e-13), u
    for dtype in (jnp.float32, jnp.float64):
        grad = jax.jit(jax.grad(lambda a, d=dtype: gtr1(one.astype(d), a)[0]))
        # d/dalpha (u/log1p(u))/pi = (1/2)(2 alpha)/pi = 1/pi at alpha = 1; float32 ulps.
        assert float(grad(jnp.asarray(1.0, dtype))) == pytest.approx(1 / np.pi, rel=1e-6)


@pytest.mark.parametrize("alpha", [0.001, 0.0109, 0.1, 0.5, 1.0])
def test_distributions_integrate_to_one(alpha):
    # int D cos(theta_h) d(omega_h) = pi int_0^1 D dx, x = cos^2; substitute y = sin^2 = 1 - x
    # and integrate over ln y in [-40, 0] (trapezoid, 40001 nodes): the peak width y ~ a^2 is
    # resolved at every scale, and y < e^-40 holds < 1e-11 of the mass even at a = 1e-3.
    lny = np.linspace(-40.0, 0.0, 40001)
    y = jnp.asarray(np.exp(lny))
    gtr1 = np.pi * np.trapezoid(np.asarray(_terms.gtr1(y, jnp.asarray(alpha))) * y, lny)
    gtr2 = np.pi * np.trapezoid(np.asarray(disney.gtr2(y, jnp.asarray(alpha**2))) * y, lny)
    print(f"alpha {alpha}: int GTR1 cos = {gtr1:.10f}, int GTR2 cos = {gtr2:.10f}")
    assert gtr1 == pytest.approx(1.0, abs=1e-6) and gtr2 == pytest.approx(1.0, abs=1e-6)


def test_directional_albedo_exceeds_one_so_not_energy_conserving():
    model = models.get("disney")
    p = {**{k: jnp.asarray(v) for k, v in _DISNEY.items()}, "base_color": jnp.ones(3)}
    p.update({k: jnp.asarray(v) for k, v in dict(metallic=0.0, roughness=1.0, sheen=1.0).items()})
    # midpoint rule on (theta_o, phi_o), 200 x 200: the integrand is smooth at roughness 1.
    th = (np.arange(200) + 0.5) * (np.pi / 2) / 200
    ph = (np.arange(200) + 0.5) * 2 * np.pi / 200
    T, P = np.meshgrid(th, ph, indexing="ij")  # noqa: N806
    wo = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    dw = (np.sin(T) * (np.pi / 2 / 200) * (2 * np.pi / 200)).reshape(-1)
    ti = np.radians(80.0)
    wi = np.broadcast_to([np.sin(ti), 0.0, np.cos(ti)], wo.shape)
    albedo = np.sum(np.asarray(jax.jit(model.eval)(p, wi, wo)) * (wo[:, 2] * dw)[:, None], axis=0)
    print(f"directional albedo at 80 degrees, white base colour, roughness 1: {albedo}")
    assert not model.energy_conserving and np.all(albedo > 1.05)  # quadrature error << 5%


# --- Mitsuba 3 principled: Disney 2012 + 2015 mixed; compared where the formulas coincide ---
def mitsuba_f(props: dict, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """``principled`` eval / cos(theta_o): Mitsuba returns f cos of the ``eval`` argument.

    ``si.wi`` takes our ``wi`` and ``eval``'s ``wo`` our ``wo`` (Mitsuba's si.wi is the
    direction toward the path's previous vertex; all compared lobes are reciprocal, so only
    the cosine's direction matters). Scalar RGB, float32.
    """
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    bsdf = mi.load_dict({"type": "principled", **props})
    si = mi.SurfaceInteraction3f()
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(si.n)
    out = []
    for a, b in zip(wi, wo, strict=True):
        si.wi = mi.Vector3f(*a)
        v = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*b))
        out.append([v[0], v[1], v[2]])
    return np.asarray(out) / wo[:, 2:3]


def _rgb(c):
    return {"type": "rgb", "value": list(c)}


C = [0.8, 0.5, 0.2]


def test_mitsuba_principled_metal_equals_disney_2012():
    # metallic = 1: Mitsuba's Fresnel is Schlick(base_color) (its dielectric and tint parts are
    # weighted by 1 - metallic), D is GGX with the same aspect/max(.001) mapping, G the
    # separable exact Smith GGX G1(wi) G1(wo), and diffuse/sheen are weighted by 1 - metallic.
    props = dict(base_color=_rgb(C), metallic=1.0, roughness=0.4, anisotropic=0.5)
    model = models.get("disney", clearcoat=False)
    p = {k: jnp.asarray(v) for k, v in _DISNEY.items() if k not in ("clearcoat", "clearcoat_gloss")}
    p.update(metallic=jnp.asarray(1.0), roughness=jnp.asarray(0.4), anisotropic=jnp.asarray(0.5))
    wi, wo = random_pairs(5, 64)
    ours, theirs = np.asarray(model.eval(p, wi, wo)), mitsuba_f(props, wi, wo)
    err = np.max(np.abs(theirs / ours - 1))
    print(f"metallic lobe vs Mitsuba principled: max relative difference {err:.2e}")
    assert err < 2e-5  # Mitsuba scalar_rgb is float32: a few ulps through D and G


def test_mitsuba_principled_diffuse_subsurface_sheen_equal_disney_2012():
    # Mitsuba splits the diffuse as (1 - F_i/2)(1 - F_o/2) + R_r (F_o + F_i + F_o F_i (R_r - 1)),
    # R_r = 2 r cos_d^2 (Disney 2015); expanded it is 1 + (R_r - 1/2)(F_i + F_o) + (R_r - 1/2)^2
    # F_i F_o, exactly the 2012 Fd. Its flatness is the 2012 subsurface (same Fss, ss) and its
    # sheen F_H sheen (1 - metallic). specular = 0 gives eta = 1 there, F_dielectric = 0: no
    # specular lobe. Not compared: the sheen TINT (Mitsuba's luminance uses .2127/.7152/.0722,
    # the shader .3/.6/.1) and the dielectric specular (exact Fresnel there, Schlick here).
    props = dict(base_color=_rgb(C), roughness=0.4, specular=0.0, flatness=0.3, sheen=0.6)
    model = models.get("disney", clearcoat=False, anisotropic=False, specular_tint=False)
    p = {k: jnp.asarray(v) for k, v in _DISNEY.items() if k in {q.name for q in model.parameters}}
    p.update({k: jnp.asarray(v) for k, v in dict(metallic=0.0, specular=0.0).items()})
    p.update(
        {k: jnp.asarray(v) for k, v in dict(subsurface=0.3, sheen=0.6, sheen_tint=0.0).items()}
    )
    # Our specular lobe at specular = 0 is F_H D_s G_s; remove it: the same model with no
    # base colour and no sheen is exactly that lobe.
    spec_only = {**p, "base_color": jnp.zeros(3), "sheen": jnp.asarray(0.0)}
    wi, wo = random_pairs(7, 64)
    ours = np.asarray(model.eval(p, wi, wo)) - np.asarray(model.eval(spec_only, wi, wo))
    err = np.max(np.abs(mitsuba_f(props, wi, wo) / ours - 1))
    print(f"diffuse + subsurface + sheen vs Mitsuba principled: max relative difference {err:.2e}")
    assert err < 2e-5  # float32 on Mitsuba's side


def test_mitsuba_principled_clearcoat_lacks_the_microfacet_jacobian():
    # Mitsuba's clear coat is clearcoat/4 F D_GTR1 G1(wi) G1(wo) (times cos_o), the shader's
    # clearcoat/4 F D G1 G1 / (4 cos_i cos_o): same F (Schlick .04), D (GTR1, same alpha map)
    # and G1 (Smith GGX, alpha .25) but without 1/(4 cos_i cos_o). Isolated on Mitsuba's side
    # with base colour 0 (no diffuse) and specular 0 (eta = 1: no main lobe; its clear-coat
    # Schlick then uses cos_t = cos_i, unchanged).
    props = dict(base_color=_rgb([0, 0, 0]), specular=0.0, clearcoat=0.8, clearcoat_gloss=0.7)
    model = models.get("disney", **{**_OFF, "clearcoat": True})
    p = {"base_color": jnp.zeros(3), "specular": jnp.asarray(0.5), "roughness": jnp.asarray(0.4)}
    p.update(clearcoat=jnp.asarray(0.8), clearcoat_gloss=jnp.asarray(0.7))
    wi, wo = random_pairs(8, 64)
    coat = np.asarray(model.eval(p, wi, wo)) - np.asarray(
        model.eval({**p, "clearcoat": jnp.asarray(0.0)}, wi, wo)
    )
    theirs = mitsuba_f(props, wi, wo)
    err = np.max(np.abs(theirs / (coat * 4 * wi[:, 2:3] * wo[:, 2:3]) - 1))
    print(f"clear coat x 4 cos_i cos_o vs Mitsuba principled: max relative difference {err:.2e}")
    assert err < 2e-5  # float32 on Mitsuba's side (GTR1's log)
