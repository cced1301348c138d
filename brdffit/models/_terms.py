"""Terms shared by several models: diffuse lobes, microfacet distributions, masking, Fresnel,
and the parameter rows of the seed table's weighted Fresnel ``rho_s F``.

Each is a small pure JAX function of cosines or half-vector components from
:class:`~brdffit.core.geometry.ShadingGeometry`; inputs below the horizon are already
replaced by safe placeholders there, so no guard here needs a ``where`` against them.
Roughness ``alpha`` follows Walter et al. 2007 (GGX ``alpha_g``, Beckmann ``alpha_b``).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from brdffit.core.parameters import Parameter, Params

INV_PI = 0.3183098861837907
DIELECTRIC_F0 = 0.04
"""Normal-incidence reflectance of a common dielectric, ``((1.5 - 1) / (1.5 + 1))^2``:
glass, plastics and paints reflect 2-5% (Hoffman, "Background: Physics and Math of
Shading", SIGGRAPH 2013 course notes, table of F0 values); the neutral value of every
Schlick ``F0`` (Disney's ``specular`` 0.5 and Filament's ``reflectance`` 0.5 mean it)."""
DIELECTRIC_ETA = 1.5
"""Relative index of refraction of that common dielectric: the neutral ``eta``."""

F0 = Parameter(
    "f0",
    (3,),
    (0.0, 1.0),
    0.04,
    "logit",
    "Fresnel reflectance at normal incidence, RGB",
    linear=True,
    neutral=DIELECTRIC_F0,
)
# With ks, f0 multiplies ks: the model is affine in each alone, not in both, so only
# ks is solved linearly.
F0_WEIGHTED = dataclasses.replace(F0, linear=False)
KS = Parameter("ks", (3,), (0.0, 1.0), 0.9, "logit", "specular weight rho_s, RGB", linear=True)


def fresnel_rows(weighted: bool) -> tuple[Parameter, ...]:
    """Table rows of the specular colour: ``(ks, f0)`` with the weight, else ``(f0,)``."""
    return (KS, F0_WEIGHTED) if weighted else (F0,)


def weighted_schlick(params: Params, cos_d: jax.Array, weighted: bool) -> jax.Array:
    """``ks F`` (or ``F``) with Schlick's ``F`` of RGB ``f0`` (:func:`schlick_fresnel`), (N, 3)."""
    f = schlick_fresnel(params["f0"], cos_d)
    return params["ks"][None, :] * f if weighted else f


def lambert(albedo: jax.Array) -> jax.Array:
    """Lambertian BRDF ``albedo / pi`` (1/sr), shape (1, 3); ``albedo`` RGB in [0, 1]."""
    return albedo[None, :] * INV_PI


def schlick_weight(cos: jax.Array) -> jax.Array:
    """Schlick's weight ``(1 - cos)^5`` (cos in [0, 1] above the horizon; no clamp needed);
    Disney's shader ``SchlickFresnel`` and Mitsuba's ``schlick_weight``."""
    return (1.0 - cos) ** 5


def luminance_tint(c: jax.Array, weights: tuple[float, float, float]) -> jax.Array:
    """``C / lum(C)`` with ``lum`` the ``weights`` of R, G, B, and 1 where ``lum = 0``; (3,).
    Disney 2012 uses (.3, .6, .1), Mitsuba's principled Rec. 709 (.212671, .715160, .072169)."""
    lum = weights[0] * c[0] + weights[1] * c[1] + weights[2] * c[2]
    return jnp.where(lum > 0, c / jnp.where(lum > 0, lum, 1.0), 1.0)


def hanrahan_krueger(fss: jax.Array, cos_sum: jax.Array) -> jax.Array:
    """Disney's subsurface shape ``1.25 (Fss (1 / (cos_i + cos_o) - .5) + .5)`` (Mitsuba's
    ``flatness`` target ``f_ss``)."""
    return 1.25 * (fss * (1.0 / cos_sum - 0.5) + 0.5)


def gtr1(sin2_h: jax.Array, alpha: jax.Array) -> jax.Array:
    """GTR1 ``(a^2 - 1) / (pi log(a^2) t)`` (1/sr) as ``u / log1p(u)``, with a series at u = 0."""
    a2 = alpha * alpha
    u = a2 - 1.0
    small = jnp.abs(u) < 1e-4  # series error u^3/24 < 5e-14
    u_safe = jnp.where(small, -0.5, u)
    ratio = jnp.where(small, 1.0 + u * (0.5 - u / 12.0), u_safe / jnp.log1p(u_safe))
    return INV_PI * ratio / (a2 - u * sin2_h)  # t = 1 + u cos^2 = a^2 - u sin^2


def ggx_dv(h: jax.Array, wi: jax.Array, wo: jax.Array, alpha: jax.Array) -> jax.Array:
    """Isotropic GGX ``D`` times height-correlated Smith ``G2 / (4 cos_i cos_o)`` (1/sr),
    (N,): glTF's ``D V`` (Appendix B), its clear coat's, and walter's coat."""
    g2 = smith_g(ggx_lambda(wi, alpha, alpha), ggx_lambda(wo, alpha, alpha), height_correlated=True)
    return ggx_d(h, alpha, alpha) * g2 / (4.0 * wi[:, 2] * wo[:, 2])


def schlick_fresnel(f0: jax.Array, cos_d: jax.Array) -> jax.Array:
    """Schlick (1994): ``F0 + (1 - F0)(1 - cos_d)^5``; ``f0`` (3,) and ``cos_d`` (N,) -> (N, 3)."""
    s = schlick_weight(cos_d)
    return f0[None, :] * (1.0 - s)[:, None] + s[:, None]


def slope_norm2(h: jax.Array, alpha_x: jax.Array, alpha_y: jax.Array) -> jax.Array:
    """``(hx/ax)^2 + (hy/ay)^2``, the squared slope of ``h`` stretched by the roughness."""
    return (h[:, 0] / alpha_x) ** 2 + (h[:, 1] / alpha_y) ** 2


def ggx_d(h: jax.Array, alpha_x: jax.Array, alpha_y: jax.Array) -> jax.Array:
    """GGX / Trowbridge-Reitz NDF (1/sr), anisotropic form (Heitz 2014, eq. 85).

    ``D = 1 / (pi ax ay ((hx/ax)^2 + (hy/ay)^2 + hz^2)^2)``; equals Walter et al. 2007
    eq. 33 ``a^2 / (pi cos^4 (a^2 + tan^2)^2)`` for ``ax = ay = a``, written without
    ``1 - cos^2`` so that it keeps its precision for alpha near 1e-4.
    """
    t = slope_norm2(h, alpha_x, alpha_y) + h[:, 2] ** 2
    return INV_PI / (alpha_x * alpha_y * t**2)


def beckmann_d(h: jax.Array, alpha_x: jax.Array, alpha_y: jax.Array) -> jax.Array:
    """Beckmann NDF (1/sr): ``exp(-((hx/ax)^2 + (hy/ay)^2)/hz^2) / (pi ax ay hz^4)``.

    Walter et al. 2007 eq. 25 in its anisotropic form; goes to 0 as ``hz -> 0``
    because the exponential wins (``hz`` is > 0 for every reflection half vector).
    """
    hz2 = h[:, 2] ** 2
    # Evaluated in log space: the float32 derivative of 1/(ax ay hz^4) underflows to
    # -inf at grazing h and would meet exp(...) = 0 as NaN. The total exponent is
    # floored at -700, where exp underflows (D < 1e-304), so the derivative is 0 there.
    log_d = (
        -slope_norm2(h, alpha_x, alpha_y) / hz2
        - jnp.log(jnp.pi * alpha_x * alpha_y)
        - 2.0 * jnp.log(hz2)
    )
    return jnp.exp(jnp.maximum(log_d, -700.0))


def projected_roughness2_tan2(v: jax.Array, alpha_x: jax.Array, alpha_y: jax.Array) -> jax.Array:
    """``alpha(phi)^2 tan^2(theta)`` of direction ``v``: ``(ax^2 vx^2 + ay^2 vy^2) / vz^2``."""
    return ((alpha_x * v[:, 0]) ** 2 + (alpha_y * v[:, 1]) ** 2) / v[:, 2] ** 2


def ggx_lambda(v: jax.Array, alpha_x: jax.Array, alpha_y: jax.Array) -> jax.Array:
    """Smith Lambda for GGX: ``(sqrt(1 + a^2 tan^2) - 1) / 2``, written cancellation-free."""
    x = projected_roughness2_tan2(v, alpha_x, alpha_y)
    return 0.5 * x / (jnp.sqrt(1.0 + x) + 1.0)


def beckmann_lambda(v: jax.Array, alpha_x: jax.Array, alpha_y: jax.Array) -> jax.Array:
    """Exact Smith Lambda for Beckmann: ``(exp(-a^2)/(a sqrt(pi)) - erfc(a)) / 2``.

    ``a = 1 / (alpha tan theta)``; ``a`` is capped at 30 (Lambda < 1e-390 there)
    so that normal incidence (``tan = 0``) stays finite in value and gradient.
    """
    x = projected_roughness2_tan2(v, alpha_x, alpha_y)
    a = jnp.minimum(jax.lax.rsqrt(jnp.maximum(x, 1.0 / 900.0)), 30.0)
    return 0.5 * (jnp.exp(-(a**2)) / (a * 1.7724538509055159) - jax.scipy.special.erfc(a))


def beckmann_lambda_rational(v: jax.Array, alpha_x: jax.Array, alpha_y: jax.Array) -> jax.Array:
    """Walter et al. 2007 eq. 27 rational fit of the Beckmann Lambda (error < 1e-2 in G1).

    ``Lambda = (1 - 1.259 a + 0.396 a^2) / (3.535 a + 2.181 a^2)`` for ``a < 1.6``, else 0.
    """
    x = projected_roughness2_tan2(v, alpha_x, alpha_y)
    a = jnp.minimum(jax.lax.rsqrt(jnp.maximum(x, 1.0 / 900.0)), 30.0)
    lam = (1.0 - 1.259 * a + 0.396 * a**2) / (3.535 * a + 2.181 * a**2)
    return jnp.where(a < 1.6, lam, 0.0)


def charlie_d(h: jax.Array, a: jax.Array, floor: float = 0.0) -> jax.Array:
    """Charlie sheen NDF (Estevez and Kulla 2017, "Production Friendly Microfacet Sheen
    BRDF", eq. 2), 1/sr, (N,): ``(2 + 1/a) (sin^2 theta_h)^(1/(2a)) / (2 pi)``.

    ``a`` is the sheen alpha (``sheen_roughness^2`` in Filament and glTF's
    ``KHR_materials_sheen``). ``sin^2 theta_h`` is floored at ``floor`` before the power
    (Filament's 2^-7 changes the lobe; glTF's sheen has none, 0). At ``sin^2 theta_h = 0``
    ``D`` is exactly 0 and the power is taken of 1 instead (a ``where`` on both sides), so
    no ``0 * log 0`` enters the derivative; a floor of 1e-30 used before added up to
    6e-7 1/sr to the lobe at a grazing mirror pair (through Neubelt's ``V``), 2e-8
    relative, which the 40-digit reference caught. It integrates to 1 against ``cos
    theta_h`` over the hemisphere for every ``a`` (the paper's normalisation;
    ``tests/models/test_lobes.py`` checks it by quadrature).
    """
    sin2 = jnp.maximum(h[:, 0] ** 2 + h[:, 1] ** 2, floor)
    positive = sin2 > 0.0
    power = jnp.exp(0.5 / a * jnp.log(jnp.where(positive, sin2, 1.0)))
    return jnp.where(positive, (2.0 + 1.0 / a) * power * (0.5 * INV_PI), 0.0)


def neubelt_v(cos_i: jax.Array, cos_o: jax.Array) -> jax.Array:
    """Neubelt and Pettineo 2013 cloth visibility ``1 / (4 (NoL + NoV - NoL NoV))``, (N,):
    the sheen visibility of Filament and of ``KHR_materials_sheen``'s reference."""
    return 0.25 / (cos_i + cos_o - cos_i * cos_o)


def smith_g(lambda_i: jax.Array, lambda_o: jax.Array, *, height_correlated: bool) -> jax.Array:
    """Masking-shadowing from Smith Lambdas: ``1/((1+Li)(1+Lo))`` or ``1/(1+Li+Lo)``."""
    if height_correlated:
        return 1.0 / (1.0 + lambda_i + lambda_o)
    return 1.0 / ((1.0 + lambda_i) * (1.0 + lambda_o))


def fresnel_dielectric(cos: jax.Array, eta: jax.Array) -> jax.Array:
    """Exact unpolarised Fresnel reflectance of a dielectric interface (Cook & Torrance 1982).

    ``F = 1/2 ((g - c)/(g + c))^2 (1 + ((c (g + c) - 1)/(c (g - c) + 1))^2)`` with
    ``c = cos`` (incidence cosine on the facet, in [0, 1]), ``g^2 = eta^2 - 1 + c^2`` and
    ``eta`` the relative index of refraction (inside over outside). Arrays broadcast
    elementwise. ``g - c`` is written ``(eta^2 - 1)/(g + c)`` so that it keeps its precision
    for ``eta`` near 1. ``g^2 <= 0`` (total internal reflection, possible only for
    ``eta < 1``) gives 1; ``g`` is sanitised first so the discarded branch stays finite.
    """
    g2 = eta**2 - 1.0 + cos**2
    tir = g2 <= 0.0
    g = jnp.sqrt(jnp.where(tir, 1.0, g2))
    g_plus = jnp.maximum(g + cos, 1e-30)
    g_minus = (eta**2 - 1.0) / g_plus
    r = 0.5 * (g_minus / g_plus) ** 2 * (1.0 + ((cos * g_plus - 1.0) / (cos * g_minus + 1.0)) ** 2)
    return jnp.where(tir, 1.0, r)


def fresnel_conductor(cos: jax.Array, eta: jax.Array, k: jax.Array) -> jax.Array:
    """Exact unpolarised Fresnel reflectance of a conductor with complex index ``eta + i k``.

    With ``c = cos``, ``s2 = 1 - c^2`` and ``a + i b = sqrt(eta^2 - k^2 - s2 + 2 i eta k)``
    (so ``a^2 + b^2 = sqrt((eta^2 - k^2 - s2)^2 + 4 eta^2 k^2)``):
    ``Rs = ((a - c)^2 + b^2) / ((a + c)^2 + b^2)``,
    ``Rp = Rs ((a c - s2)^2 + c^2 b^2) / ((a c + s2)^2 + c^2 b^2)``, ``F = (Rs + Rp) / 2``
    (the form of pbrt and Mitsuba, written as sums of squares so that F >= 0 exactly).
    ``a^2`` and ``b^2`` are taken each from the cancellation-free side (``a^2 b^2 =
    eta^2 k^2``). Arrays broadcast elementwise (e.g. ``cos[:, None]`` with RGB ``eta[None]``).
    At normal incidence ``F = ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2)``.
    """
    s2 = 1.0 - cos**2
    t0 = eta**2 - k**2 - s2
    ek2 = (eta * k) ** 2
    norm = jnp.sqrt(t0**2 + 4.0 * ek2)
    pos = t0 >= 0.0
    big = jnp.maximum(norm + jnp.abs(t0), 1e-30)  # the side without cancellation
    a2 = jnp.where(pos, 0.5 * big, 2.0 * ek2 / big)
    b2 = jnp.where(pos, 2.0 * ek2 / big, 0.5 * big)
    a = jnp.sqrt(jnp.maximum(a2, 1e-30))
    rs = ((a - cos) ** 2 + b2) / ((a + cos) ** 2 + b2)
    cb2 = cos**2 * b2
    rp = rs * ((a * cos - s2) ** 2 + cb2) / ((a * cos + s2) ** 2 + cb2)
    return 0.5 * (rs + rp)


def v_cavity_g(cos_h: jax.Array, cos_i: jax.Array, cos_o: jax.Array, cos_d: jax.Array) -> jax.Array:
    """Torrance-Sparrow V-cavity masking-shadowing (Cook and Torrance 1982), (N,).

    ``G = min(1, 2 cos_h cos_i / cos_d, 2 cos_h cos_o / cos_d)`` with ``cos_d = wi.h = wo.h``.
    ``cos_d`` is floored at 1e-30 before the division; it is > 0 for every reflection pair
    above the horizon, and where it is tiny the ratio is huge and the ``min`` returns 1.
    """
    ratio = 2.0 * cos_h * jnp.minimum(cos_i, cos_o) / jnp.maximum(cos_d, 1e-30)
    return jnp.minimum(1.0, ratio)


def log_cos_theta_h(h: jax.Array) -> jax.Array:
    """``log(h.z)`` of unit half vectors ``h`` (N, 3), accurate for ``h`` near the normal.

    Lobes ``cos_h^n`` with ``n`` up to 1e5 need ``log cos_h`` to relative precision where
    ``cos_h`` rounds to 1: there it is ``log1p(-(hx^2 + hy^2)) / 2`` from the tangential
    components; elsewhere (``hx^2 + hy^2 >= 1/2``) ``log(hz)``, with ``hz`` floored at
    1e-30 (it is > 0 for every reflection pair above the horizon). Both branches are
    sanitised before the ``where``, so values and gradients are finite everywhere.
    """
    s2 = h[:, 0] ** 2 + h[:, 1] ** 2
    near = s2 < 0.5
    return jnp.where(
        near,
        0.5 * jnp.log1p(-jnp.where(near, s2, 0.0)),
        jnp.log(jnp.maximum(h[:, 2], 1e-30)),
    )


FUJII_C1 = 0.5 - 2.0 / (3.0 * jnp.pi)
"""Fujii's constant of the FON ``A = 1 / (1 + C1 sigma)`` (``1/2 - 2/(3 pi)``)."""
FUJII_C2 = 2.0 / 3.0 - 28.0 / (15.0 * jnp.pi)
"""Constant of the FON average albedo ``A (1 + C2 sigma)`` (``2/3 - 28/(15 pi)``)."""


def fujii_albedo(cos: jax.Array, sigma: jax.Array) -> jax.Array:
    """Directional albedo of Fujii's Oren-Nayar (FON), exact (Portsmouth, Kutz, Hill 2025,
    "EON: A practical energy-preserving rough diffuse BRDF", JCGT 14(1), eq. 11), (N,):
    ``A + B G(cos) / pi``, ``A = 1 / (1 + C1 sigma)``, ``B = sigma A``, ``G = S (acos(c) -
    S c) + 2 ((S / c)(1 - S^3) - S) / 3``, ``S = sin = sqrt(1 - c^2)``.

    ``(S / c)(1 - S^3)`` is written ``S c (1 + S + S^2) / (1 + S)`` (``1 - S = c^2 /
    (1 + S)``): equal, without the cancellation of ``1 - S^3`` near grazing or the
    division by ``c``. ``cos`` in (0, 1].
    """
    a = 1.0 / (1.0 + FUJII_C1 * sigma)
    s = jnp.sqrt(jnp.maximum(1.0 - cos**2, 0.0))
    g = s * (jnp.arccos(jnp.clip(cos, -1.0, 1.0)) - s * cos)
    g = g + 2.0 * (s * cos * (1.0 + s + s * s) / (1.0 + s) - s) / 3.0
    return a + sigma * a * g * INV_PI


def eon_diffuse(
    cos_i: jax.Array,
    cos_o: jax.Array,
    cos_io: jax.Array,
    sigma: jax.Array,
    color: jax.Array,
    floor: float,
) -> jax.Array:
    """Energy-preserving Oren-Nayar (EON, Portsmouth et al. 2025, the diffuse of OpenPBR
    Surface), BRDF times pi (unitless), (N, 3): ``f pi = rho A (1 + sigma s/t) + f_ms``.

    ``s = cos_io - cos_i cos_o`` (``cos_io = wi.wo``), ``s/t = s / max(cos_i, cos_o)``
    where ``s > 0`` else ``s`` (FON, Fujii 2013); ``A = 1 / (1 + C1 sigma)``; the
    multiple-scattering lobe ``f_ms = rho_ms (1 - E(cos_i)) (1 - E(cos_o)) / (1 -
    E_avg)``, ``rho_ms = rho^2 E_avg / (1 - rho (1 - E_avg))``, ``E`` of
    :func:`fujii_albedo`, ``E_avg = A (1 + C2 sigma)``. Each ``1 - E`` is floored at
    ``floor`` (MaterialX's ``M_FLOAT_EPS``, 1e-8), which keeps ``0 / 0`` out at ``sigma =
    0``, where the lobe is Lambert's. ``sigma`` the roughness in [0, 1]; ``color`` (3,).
    """
    s = cos_io - cos_i * cos_o
    s_over_t = jnp.where(s > 0.0, s / jnp.maximum(cos_i, cos_o), s)
    a = 1.0 / (1.0 + FUJII_C1 * sigma)
    single = (a * (1.0 + sigma * s_over_t))[:, None] * color[None, :]
    e_avg = a * (1.0 + FUJII_C2 * sigma)
    rho_ms = color**2 * e_avg / (1.0 - color * jnp.maximum(0.0, 1.0 - e_avg))
    shape = (
        jnp.maximum(floor, 1.0 - fujii_albedo(cos_i, sigma))
        * jnp.maximum(floor, 1.0 - fujii_albedo(cos_o, sigma))
        / jnp.maximum(floor, 1.0 - e_avg)
    )
    return single + shape[:, None] * rho_ms[None, :]


F82_COS = 1.0 / 7.0
"""``mu-bar``, the cosine (about 82 degrees) at which the F82 tint is specified."""


def f82_schlick(f0: jax.Array, tint: jax.Array, cos: jax.Array) -> jax.Array:
    """Schlick's Fresnel with Hoffman's F82 tint (Hoffman 2019, "Generalization of Adobe's
    Fresnel Model"; the metal Fresnel of OpenPBR Surface and of MaterialX's
    ``generalized_schlick_bsdf`` with ``F90 = 1``, exponent 5), (N, 3):
    ``F = F_s(c) - c (1 - c)^6 a``, ``F_s(c) = f0 + (1 - f0)(1 - c)^5``, ``a = F_s(mu) (1 -
    tint) / (mu (1 - mu)^6)``, ``mu = 1/7``. ``tint = 1`` is plain Schlick. ``f0``, ``tint``
    (3,); ``cos`` (N,) in [0, 1].
    """
    mu = F82_COS
    a = (f0 + (1.0 - f0) * (1.0 - mu) ** 5) * (1.0 - tint) / (mu * (1.0 - mu) ** 6)
    x = 1.0 - cos
    return schlick_fresnel(f0, cos) - (cos * x**6)[:, None] * a[None, :]


def zeltner_albedo(cos: jax.Array, r: jax.Array) -> jax.Array:
    """Directional albedo of Zeltner's sheen (Zeltner, Burley, Chiang 2022, "Practical
    Multiple-Scattering Sheen Using Linearly Transformed Cosines", their Gaussian fit, as
    in github.com/tizian/ltc-sheen and MaterialX's ``mx_zeltner_sheen_dir_albedo``), (N,):
    ``exp(-((c - m)/s)^2 / 2) / (s sqrt(2 pi)) + o`` with rational ``s, m, o`` of ``r``.
    ``cos`` (N,); ``r`` the sheen roughness in [0.01, 1] (the fit's range)."""
    s = r * (0.0206607 + 1.58491 * r) / (0.0379424 + r * (1.32227 + r))
    m = r * (-0.193854 + r * (-1.14885 + r * (1.7932 - 0.95943 * r * r))) / (0.046391 + r)
    o = r * (0.000654023 + (-0.0207818 + 0.119681 * r) * r) / (1.26264 + r * (-1.92021 + r))
    return jnp.exp(-0.5 * ((cos - m) / s) ** 2) / (s * jnp.sqrt(2.0 * jnp.pi)) + o


def zeltner_sheen(wi: jax.Array, wo: jax.Array, cos_o: jax.Array, r: jax.Array) -> jax.Array:
    """Zeltner's LTC sheen lobe without its albedo: ``D_ltc(wi) / cos_i`` (1/sr), (N,), so
    that the sheen BRDF is ``color E(cos_o) D_ltc / cos_i`` (:func:`zeltner_albedo`).

    ``cos_o`` is ``N.V`` as the caller takes it (MaterialX clamps it to [1e-8, 1]). The
    frame has ``x`` along ``t = wo - n cos_o`` (the tangential part of ``wo``; ``x``, ``y``
    of the shading frame where ``t = 0``) and ``y = n x x``; ``w = M^-1 wi = (a wx + b wz, a
    wy, wz)`` with ``a, b`` the paper's rational fits of ``(cos_o, r)``; ``D_ltc = (wz / pi)
    (a / |w|^2)^2``, so ``D_ltc / cos_i = (a / |w|^2)^2 / pi``. ``r`` in [0.01, 1].
    """
    c = cos_o
    a = (2.58126 * c + 0.813703 * r) * r / (1.0 + 0.310327 * c * c + 2.60994 * c * r)
    b = jnp.sqrt(jnp.maximum(1.0 - c, 0.0)) * (r - 1.0) * r**3
    b = b / (0.0000254053 + 1.71228 * c - 1.71506 * c * r + 1.34174 * r * r)
    t = wo - jnp.stack([jnp.zeros_like(c), jnp.zeros_like(c), c], axis=-1)
    t2 = jnp.sum(t * t, axis=-1)
    ok = t2 > 0.0
    inv = jnp.where(ok, jax.lax.rsqrt(jnp.where(ok, t2, 1.0)), 0.0)
    tx = jnp.where(ok, t[:, 0] * inv, 1.0)
    ty = jnp.where(ok, t[:, 1] * inv, 0.0)
    wx = wi[:, 0] * tx + wi[:, 1] * ty + wi[:, 2] * t[:, 2] * inv
    wy = wi[:, 1] * tx - wi[:, 0] * ty  # y = n x t
    wz = wi[:, 2]
    len2 = (a * wx + b * wz) ** 2 + (a * wy) ** 2 + wz**2
    return (a / len2) ** 2 * INV_PI
