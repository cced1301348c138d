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


CHARLIE_FLOOR = 1e-30
"""Floor of ``sin^2 theta_h`` in :func:`charlie_d` for the glTF sheen (walter's and the glTF
model's): keeps ``0 log 0`` out of the derivative at ``theta_h = 0``, where ``D`` is 0;
the value it adds there, ``(1e-30)^(1/(2a))`` times the normalisation, is below 1e-12
1/sr for every ``a <= 1``. (Filament's own floor, 2^-7, changes the lobe.)"""


def charlie_d(h: jax.Array, a: jax.Array, floor: float) -> jax.Array:
    """Charlie sheen NDF (Estevez and Kulla 2017, "Production Friendly Microfacet Sheen
    BRDF", eq. 2), 1/sr, (N,): ``(2 + 1/a) (sin^2 theta_h)^(1/(2a)) / (2 pi)``.

    ``a`` is the sheen alpha (``sheen_roughness^2`` in Filament and glTF's
    ``KHR_materials_sheen``). ``sin^2 theta_h`` is floored at ``floor`` > 0 before the
    power, which keeps the derivative of ``sin^(1/a)`` finite at ``theta_h = 0``
    (``0 * log 0``); each caller gives its floor and its reason. It integrates to 1
    against ``cos theta_h`` over the hemisphere for every ``a`` (the paper's
    normalisation; ``tests/models/test_lobes.py`` checks it by quadrature).
    """
    sin2 = jnp.maximum(h[:, 0] ** 2 + h[:, 1] ** 2, floor)
    return (2.0 + 1.0 / a) * jnp.exp(0.5 / a * jnp.log(sin2)) * (0.5 * INV_PI)


XYZ_TO_REC709 = (
    (3.2404542, -1.5371385, -0.4985314),
    (-0.9692660, 1.8760108, 0.0415560),
    (0.0556434, -0.2040259, 1.0572252),
)
"""CIE XYZ to linear Rec. 709 / sRGB primaries (D65), rows R, G, B."""


def _sensitivity(opd: jax.Array, shift: jax.Array) -> jax.Array:
    """Belcour and Barla's (2017) Fourier-space XYZ colour matching functions, in linear RGB.

    ``integral of cmf(lambda) cos(2 pi opd / lambda + shift) d lambda / integral of y-bar``
    for an optical path difference ``opd`` (nm, (N, 1)) and a phase ``shift`` (radians,
    (N, 3)), from their Gaussian fits of the CIE 1931 2-degree functions (their
    supplemental code; the constants of ``KHR_materials_iridescence``'s reference).
    Against the CIE tables integrated numerically over wavelength: XYZ within 0.02 up to
    ``opd`` = 600 nm, RGB within 0.05 to 300 nm and 0.12 to 1000 nm (the fits' error,
    grown by the matrix; ``tests/models/test_lobes.py``). The reflectance weighs these
    terms by ``C_m = (R_s - T_121) sqrt(R_12 R_23)^m``, small unless both interfaces
    reflect strongly, so its error is smaller.
    """
    phase = 2.0 * jnp.pi * opd * 1e-9  # (N, 1)
    val = jnp.array([[5.4856e-13, 4.4201e-13, 5.2481e-13]], opd.dtype)
    pos = jnp.array([[1.6810e06, 1.7953e06, 2.2084e06]], opd.dtype)
    var = jnp.array([[4.3278e09, 9.3046e09, 6.6121e09]], opd.dtype)
    xyz = val * jnp.sqrt(2.0 * jnp.pi * var) * jnp.cos(pos * phase + shift)
    xyz = xyz * jnp.exp(-(phase**2) * var)
    extra = (
        9.7470e-14 * jnp.sqrt(2.0 * jnp.pi * 4.5282e09) * jnp.cos(2.2399e06 * phase + shift[:, :1])
    )
    extra = extra * jnp.exp(-4.5282e09 * phase**2)
    xyz = (xyz + jnp.concatenate([extra, jnp.zeros_like(xyz[:, 1:])], axis=1)) / 1.0685e-7
    return xyz @ jnp.asarray(XYZ_TO_REC709, xyz.dtype).T


def thin_film_fresnel(
    cos1: jax.Array, thickness: jax.Array, film_ior: jax.Array, base_f0: jax.Array
) -> jax.Array:
    """Reflectance (N, 3) of a dielectric thin film on a base, Belcour and Barla 2017 ("A
    Practical Extension to Microfacet Theory for the Modeling of Varying Iridescence",
    TOG 36(4)), in the form of glTF's ``KHR_materials_iridescence`` reference: air above.

    ``cos1`` (N,) the cosine on the facet (``cos_d``); ``thickness`` of the film in nm;
    ``film_ior`` its index (>= 1, so no total internal reflection); ``base_f0`` (3,) the
    base's normal reflectance, read as a dielectric of index ``(1 + sqrt f0)/(1 - sqrt
    f0)`` (an approximation for metals, as the extension says). Schlick reflectances at
    both interfaces (``R12`` at ``theta_1``, ``R23`` at the refracted ``theta_2``), phase
    shifts 0 or pi by the order of the indices, optical path difference ``OPD = 2
    film_ior thickness cos(theta_2)`` (Belcour's code and the glTF sample viewer; the
    extension's text writes ``cos(theta_1)``), the Airy sum's terms ``m = 0, 1, 2``
    integrated over the spectrum analytically (:func:`_sensitivity`), negatives clamped to 0.
    As the reference: the film's index goes to 1 as its thickness goes to 0 (smoothstep
    over 0.03 nm), ``f0`` is clamped to 0.9999 and ``R12 R23`` to [1e-5, 0.9999]; ``f0``
    is floored at 1e-12 (``sqrt f0`` at 1e-6) so that the derivative of ``sqrt f0`` stays
    finite at ``f0 = 0``.
    """
    t = jnp.clip(thickness / 0.03, 0.0, 1.0)
    eta2 = 1.0 + (film_ior - 1.0) * t * t * (3.0 - 2.0 * t)
    # >= cos1^2 exactly (eta2 >= 1); the floor keeps float32 rounding off sqrt(0)
    cos2 = jnp.sqrt(jnp.maximum(1.0 - (1.0 - cos1**2) / eta2**2, cos1**2))
    r12 = schlick_fresnel(jnp.broadcast_to(((eta2 - 1.0) / (eta2 + 1.0)) ** 2, (1,)), cos1)
    t121 = 1.0 - r12  # (N, 1), as r12
    root = jnp.sqrt(jnp.clip(base_f0, 1e-12, 0.9999))
    base_ior = (1.0 + root) / (1.0 - root)
    r23 = schlick_fresnel(((base_ior - eta2) / (base_ior + eta2)) ** 2, cos2)  # (N, 3)
    phi = jnp.pi + jnp.where(base_ior < eta2, jnp.pi, 0.0)[None, :]  # phi21 + phi23
    opd = (2.0 * eta2 * thickness * cos2)[:, None]
    r123 = jnp.clip(r12 * r23, 1e-5, 0.9999)
    rs = t121**2 * r23 / (1.0 - r123)
    out, cm = r12 + rs, rs - t121
    for m in (1.0, 2.0):
        cm = cm * jnp.sqrt(r123)
        out = out + cm * 2.0 * _sensitivity(m * opd, m * jnp.broadcast_to(phi, out.shape))
    return jnp.maximum(out, 0.0)


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
