"""High-precision reference for ``brdffit/models/mitsuba_principled.py``: Mitsuba 3's
``principled`` BSDF (reflection, front side) in mpmath.

Transcribed from Mitsuba 3's ``src/bsdfs/principled.cpp`` (``eval``) and
``principledhelpers.h`` (``calc_dist_params``, ``principled_fresnel``, ``calc_schlick``,
``schlick_R0_eta``, ``GTR1Isotropic``, ``smith_ggx1``), ``microfacet.h`` (GGX ``eval``,
``smith_g1``) and ``fresnel.h`` (``fresnel``), as written there: ``eta = 2 / (1 - sqrt(.08
specular)) - 1``, the Fresnel amplitudes ``a_s``, ``a_p`` with ``cos_t``, GTR1 with ``1 + (a^2
- 1) cos^2``, ``tan^2 = (1 - cos^2) / cos^2``; ``eval``'s ``f cos_o`` divided by that cosine
(Mitsuba's ``wo`` is brdffit's ``wi``). A feature the model's options switch off is the
plugin without that property (its value 0). Nothing here calls ``brdffit/models/``.
"""

from __future__ import annotations

import mpmath as mp

from tests.references import Reference, num, per_pair, rgb


def _schlick_weight(c):
    return min(max(1 - c, mp.mpf(0)), mp.mpf(1)) ** 5


def _fresnel(c, eta):
    """``fresnel.h``: unpolarised dielectric reflectance, 0 when index-matched."""
    if eta == 1:
        return mp.mpf(0)
    ct = mp.sqrt(1 - (1 - c**2) / eta**2)
    a_s = (c - eta * ct) / (c + eta * ct)
    a_p = (ct - eta * c) / (ct + eta * c)
    return (a_s**2 + a_p**2) / 2


def _smith_g1(v, ax, ay):
    xy = (ax * v[0]) ** 2 + (ay * v[1]) ** 2
    return 2 / (1 + mp.sqrt(1 + xy / v[2] ** 2)) if xy != 0 else mp.mpf(1)


def _smith_ggx1(v, alpha):
    c2 = v[2] ** 2
    return 2 / (1 + mp.sqrt(1 + alpha**2 * (1 - c2) / c2)) if v[2] != 1 else mp.mpf(1)


@per_pair
def principled_ref(model, p, g):
    """Mitsuba 3 ``principled`` with ``spec_trans = 0``, brdffit's ``wi``/``wo``, 1/sr."""

    def get(name, flag):
        return p[name] if flag else mp.mpf(0)

    base = rgb(p["base_color"])
    rough, specular = p["roughness"], p["specular"]
    metallic = get("metallic", model.metallic)
    spec_tint = get("spec_tint", model.spec_tint)
    aniso = get("anisotropic", model.anisotropic)
    sheen = get("sheen", model.sheen)
    sheen_tint = get("sheen_tint", model.sheen_tint)
    flatness = get("flatness", model.flatness)
    clearcoat = get("clearcoat", model.clearcoat)
    gloss = get("clearcoat_gloss", model.clearcoat)
    eta = 2 / (1 - mp.sqrt(num("0.08") * specular)) - 1
    r2 = rough**2
    if model.anisotropic:  # calc_dist_params
        aspect = mp.sqrt(1 - num("0.9") * aniso)
        ax, ay = max(num("0.001"), r2 / aspect), max(num("0.001"), r2 * aspect)
    else:
        ax = ay = max(num("0.001"), r2)
    h, cd = g.h, g.cd
    d = 1 / (mp.pi * ax * ay * ((h[0] / ax) ** 2 + (h[1] / ay) ** 2 + h[2] ** 2) ** 2)
    gg = _smith_g1(g.wi, ax, ay) * _smith_g1(g.wo, ax, ay)
    f_d = _fresnel(cd, eta)
    lum = num("0.212671") * base[0] + num("0.715160") * base[1] + num("0.072169") * base[2]
    c_tint = [x / lum for x in base] if lum > 0 else [mp.mpf(1)] * 3
    r0 = ((eta - 1) / (eta + 1)) ** 2  # schlick_R0_eta
    w_d = _schlick_weight(abs(cd))
    out = []
    for k in range(3):
        f_schlick = metallic * (base[k] * (1 - w_d) + w_d)  # lerp(w, 1, R0)
        f_schlick += (1 - metallic) * spec_tint * (c_tint[k] * r0 * (1 - w_d) + w_d)
        fresnel = (1 - metallic) * (1 - spec_tint) * f_d + f_schlick
        value = fresnel * d * gg / (4 * g.ci * g.co) if f_d > 0 else mp.mpf(0)
        out.append(value)
    if model.clearcoat:
        alpha = num("0.1") * (1 - gloss) + num("0.001") * gloss  # lerp(.1, .001, gloss)
        a2 = alpha**2
        dcc = (a2 - 1) / (mp.pi * mp.log(a2) * (1 + (a2 - 1) * h[2] ** 2))
        fcc = num("0.04") * (1 - w_d) + w_d
        coat = clearcoat * num("0.25") * fcc * dcc * _smith_ggx1(g.wi, num("0.25"))
        coat *= _smith_ggx1(g.wo, num("0.25"))
        out = [v + coat for v in out]
    brdf = 1 - metallic
    fo, fi = _schlick_weight(g.ci), _schlick_weight(g.co)  # Mitsuba's wo = brdffit's wi
    f_diff = (1 - fi / 2) * (1 - fo / 2)
    rr = 2 * rough * cd**2
    f_retro = rr * (fo + fi + fo * fi * (rr - 1))
    lobe = f_diff + f_retro
    if model.flatness:
        fss90 = rr / 2
        fss = (1 + (fss90 - 1) * fo) * (1 + (fss90 - 1) * fi)
        f_ss = num("1.25") * (fss * (1 / (g.co + g.ci) - num("0.5")) + num("0.5"))
        lobe = lobe * (1 - flatness) + f_ss * flatness
    for k in range(3):
        out[k] += brdf * base[k] / mp.pi * lobe
        if model.sheen:
            c_sheen = 1 - sheen_tint + c_tint[k] * sheen_tint  # lerp(1, c_tint, sheen_tint)
            out[k] += sheen * brdf * w_d * c_sheen
    return out


REFERENCES: dict[str, Reference] = {"principled": principled_ref}
