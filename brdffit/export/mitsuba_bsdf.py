"""Mitsuba 3's reflection plugins ``diffuse``, ``roughconductor`` and ``principled``, in numpy.

Written from Mitsuba 3.x's sources (``src/bsdfs/{diffuse,roughconductor,principled}.cpp``,
``principledhelpers.h``, ``include/mitsuba/render/{microfacet,fresnel}.h``) so that an
export's error can be measured, and its parameters fitted, without Mitsuba installed;
``tests/export/test_export.py`` checks every function here against Mitsuba itself.

Convention: brdffit's (``wi`` toward the light, ``wo`` toward the viewer, f in 1/sr
without the cosine, (N, 3)). Mitsuba's ``si.wi`` is brdffit's ``wo`` and its ``wo`` is
brdffit's ``wi``; ``bsdf.eval`` returns ``f cos(theta_i)`` in brdffit's terms.

What Mitsuba does that the formulas below follow:

* ``alpha`` is the microfacet roughness itself (no squaring) in ``roughconductor``;
  ``principled`` squares its ``roughness`` (``alpha = max(0.001, roughness^2)``, stretched
  by ``aspect = sqrt(1 - 0.9 anisotropic)``: ``alpha_u = r^2 / aspect``, ``alpha_v = r^2
  aspect``).
* Masking is Smith's *separable* ``G1(wi) G1(wo)``; for Beckmann, ``G1`` is Walter et al.'s
  rational fit ``(3.535 a + 2.181 a^2) / (1 + 2.276 a + 2.577 a^2)`` (1 for ``a >= 1.6``).
  Distribution values with ``D cos(theta_h) <= 1e-20`` are set to 0.
* ``principled``: Fresnel is exact-dielectric for the untinted dielectric part
  (``eta = 2 / (1 - sqrt(0.08 specular)) - 1``), Schlick for the metallic and tinted parts;
  tints divide by Rec. 709 luminance (0.212671, 0.715160, 0.072169); the diffuse is Disney
  2012's (written as ``f_diff + f_retro``) blended toward Hanrahan-Krueger by ``flatness``;
  the clear coat is ``0.25 clearcoat F_schlick(0.04) GTR1 G1(wi) G1(wo)`` with GGX ``G1`` of
  alpha 0.25 and *without* the microfacet ``1 / (4 cos_i cos_o)``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

INV_PI = 1.0 / np.pi
REC709 = np.array([0.212671, 0.715160, 0.072169])


def half_vector(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Unit half vector ``normalize(wi + wo)``, (N, 3)."""
    h = wi + wo
    return h / np.linalg.norm(h, axis=-1, keepdims=True)


def distribution(kind: str, h: np.ndarray, ax: float, ay: float) -> np.ndarray:
    """Mitsuba's ``MicrofacetDistribution::eval``: GGX or Beckmann D (1/sr), (N,)."""
    hz2 = h[:, 2] ** 2
    slope = (h[:, 0] / ax) ** 2 + (h[:, 1] / ay) ** 2
    if kind == "ggx":
        d = INV_PI / (ax * ay * (slope + hz2) ** 2)
    else:
        d = np.exp(-slope / hz2) * INV_PI / (ax * ay * hz2**2)
    return np.where(d * h[:, 2] > 1e-20, d, 0.0)


def smith_g1(kind: str, v: np.ndarray, ax: float, ay: float) -> np.ndarray:
    """Mitsuba's ``smith_g1`` (exact for GGX, rational for Beckmann), (N,)."""
    xy = (ax * v[:, 0]) ** 2 + (ay * v[:, 1]) ** 2
    t = xy / v[:, 2] ** 2
    if kind == "ggx":
        g = 2.0 / (1.0 + np.sqrt(1.0 + t))
    else:
        a = 1.0 / np.sqrt(np.maximum(t, 1e-300))
        g = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a**2) / (1 + 2.276 * a + 2.577 * a**2))
    return np.where(xy == 0.0, 1.0, g)


def fresnel_conductor(cos: np.ndarray, eta: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Mitsuba's ``fresnel_conductor`` (after Moeller's Optics); ``cos`` (N,), ``eta``, ``k`` (3,).

    Returns (N, 3); ``eta = 0, k = 1`` gives exactly 1 (Mitsuba's ``material = "none"``).
    """
    c2 = cos[:, None] ** 2
    s2 = 1.0 - c2
    t1 = eta**2 - k**2 - s2
    a2pb2 = np.sqrt(np.maximum(t1**2 + 4.0 * k**2 * eta**2, 0.0))
    a = np.sqrt(np.maximum(0.5 * (a2pb2 + t1), 0.0))
    term1, term2 = a2pb2 + c2, 2.0 * cos[:, None] * a
    rs = (term1 - term2) / (term1 + term2)
    term3, term4 = a2pb2 * c2 + s2**2, term2 * s2
    return 0.5 * (rs + rs * (term3 - term4) / (term3 + term4))


def fresnel_dielectric(cos: np.ndarray, eta: float) -> np.ndarray:
    """Unpolarised Fresnel reflectance from outside, ``eta >= 1`` (Mitsuba's ``fresnel``), (N,)."""
    cos_t = np.sqrt(1.0 - (1.0 - cos**2) / eta**2)
    a_s = (cos - eta * cos_t) / (cos + eta * cos_t)
    a_p = (eta * cos - cos_t) / (eta * cos + cos_t)
    return 0.5 * (a_s**2 + a_p**2)


def schlick_weight(cos: np.ndarray) -> np.ndarray:
    """``clip(1 - cos, 0, 1)^5``."""
    return np.clip(1.0 - cos, 0.0, 1.0) ** 5


def schlick(f0: np.ndarray | float, cos: np.ndarray) -> np.ndarray:
    """Schlick's Fresnel ``f0 + (1 - f0) w`` of RGB (or scalar) ``f0``, (N, 3)."""
    w = schlick_weight(cos)[:, None]
    return np.asarray(f0) * (1.0 - w) + w


def diffuse(reflectance: np.ndarray, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Mitsuba's ``diffuse``: ``reflectance / pi``, (N, 3)."""
    return np.broadcast_to(np.asarray(reflectance) * INV_PI, (wi.shape[0], 3))


def roughconductor(
    kind: str,
    ax: float,
    ay: float,
    eta: np.ndarray,
    k: np.ndarray,
    specular: np.ndarray,
    wi: np.ndarray,
    wo: np.ndarray,
) -> np.ndarray:
    """Mitsuba's ``roughconductor``: ``specular F(wi.h; eta + i k) D G / (4 cos_i cos_o)``."""
    h = half_vector(wi, wo)
    lobe = (
        distribution(kind, h, ax, ay)
        * smith_g1(kind, wi, ax, ay)
        * smith_g1(kind, wo, ax, ay)
        / (4.0 * wi[:, 2] * wo[:, 2])
    )
    cos_d = np.sum(wi * h, axis=-1)
    return np.asarray(specular) * fresnel_conductor(cos_d, eta, k) * lobe[:, None]


def principled_eta(specular: float) -> float:
    """The relative IOR ``principled`` derives from ``specular``: ``2 / (1 - sqrt(.08 s)) - 1``."""
    return 2.0 / (1.0 - np.sqrt(0.08 * specular)) - 1.0


def principled_alphas(roughness: float, anisotropic: float) -> tuple[float, float]:
    """``(alpha_u, alpha_v)`` of ``principled`` (Mitsuba's ``calc_dist_params``)."""
    aspect = np.sqrt(1.0 - 0.9 * anisotropic)
    r2 = roughness**2
    return max(0.001, r2 / aspect), max(0.001, r2 * aspect)


def gtr1(cos_h: np.ndarray, alpha: float) -> np.ndarray:
    """Mitsuba's ``GTR1Isotropic::eval`` (1/sr), (N,)."""
    a2 = alpha**2
    d = (a2 - 1.0) / (np.pi * np.log(a2) * (1.0 + (a2 - 1.0) * cos_h**2))
    return np.where(d * cos_h > 1e-20, d, 0.0)


def clearcoat_g1(v: np.ndarray) -> np.ndarray:
    """``smith_ggx1`` of the clear coat, alpha 0.25, (N,)."""
    c2 = v[:, 2] ** 2
    g = 2.0 / (1.0 + np.sqrt(1.0 + 0.0625 * (1.0 - c2) / c2))
    return np.where(v[:, 2] == 1.0, 1.0, g)


def principled(p: Mapping[str, object], wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Mitsuba's ``principled`` without transmission (``spec_trans = 0``), (N, 3).

    ``p``: ``base_color`` (3,), and the floats ``metallic``, ``roughness``,
    ``anisotropic``, ``specular``, ``spec_tint``, ``sheen``, ``sheen_tint``,
    ``flatness``, ``clearcoat``, ``clearcoat_gloss``; a missing one is 0 (the
    plugin's feature switched off), except ``specular`` (Mitsuba's default 0.5).
    """

    def get(name: str, default: float = 0.0) -> float:
        return float(p.get(name, default))

    base = np.asarray(p["base_color"], float)
    m, r = get("metallic"), get("roughness")
    eta = principled_eta(get("specular", 0.5))
    h = half_vector(wi, wo)
    cos_d = np.sum(wo * h, axis=-1)  # Mitsuba's dot(si.wi, wh)
    lum = float(base @ REC709)
    c_tint = base / lum if lum > 0 else np.ones(3)
    ax, ay = principled_alphas(r, get("anisotropic"))
    f_d = fresnel_dielectric(cos_d, eta)
    st = get("spec_tint")
    fresnel = (1 - m) * (1 - st) * f_d[:, None] + m * schlick(base, cos_d)
    fresnel = fresnel + (1 - m) * st * schlick(c_tint * ((eta - 1) / (eta + 1)) ** 2, cos_d)
    dg = distribution("ggx", h, ax, ay) * smith_g1("ggx", wi, ax, ay) * smith_g1("ggx", wo, ax, ay)
    spec = np.where(f_d > 0, dg / (4.0 * wi[:, 2] * wo[:, 2]), 0.0)[:, None] * fresnel
    out = spec
    cc = get("clearcoat")
    if cc > 0:
        alpha = 0.1 + get("clearcoat_gloss") * (0.001 - 0.1)
        coat = 0.25 * cc * (0.04 + 0.96 * schlick_weight(cos_d)) * gtr1(h[:, 2], alpha)
        out = out + (coat * clearcoat_g1(wi) * clearcoat_g1(wo))[:, None]
    if m < 1:
        fo, fi = schlick_weight(wi[:, 2]), schlick_weight(wo[:, 2])
        rr = 2.0 * r * cos_d**2
        lobe = (1 - 0.5 * fi) * (1 - 0.5 * fo) + rr * (fo + fi + fo * fi * (rr - 1))
        flat = get("flatness")
        if flat > 0:
            fss = (1 + (0.5 * rr - 1) * fo) * (1 + (0.5 * rr - 1) * fi)
            f_ss = 1.25 * (fss * (1.0 / (wi[:, 2] + wo[:, 2]) - 0.5) + 0.5)
            lobe = lobe + flat * (f_ss - lobe)
        out = out + (1 - m) * INV_PI * base * lobe[:, None]
        sheen = get("sheen")
        if sheen > 0:
            c_sheen = 1.0 + get("sheen_tint") * (c_tint - 1.0)
            out = out + sheen * (1 - m) * schlick_weight(np.abs(cos_d))[:, None] * c_sheen
    return out
