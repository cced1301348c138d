"""Thin films: the reflectance of a dielectric film over a base (Belcour and Barla 2017,
"A Practical Extension to Microfacet Theory for the Modeling of Varying Iridescence",
TOG 36(4)), in the two forms brdffit fits: glTF's ``KHR_materials_iridescence``
(:func:`thin_film_fresnel`, Schlick at both interfaces, Rec. 709 output; walter's and the
gltf model's film) and MaterialX's ``mx_fresnel_airy`` (:func:`airy_fresnel`, exact
polarised Fresnel, CIE RGB output; the openpbr model's film), sharing Belcour and Barla's
Fourier-space colour matching functions (:func:`sensitivity_xyz`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from brdffit.models._terms import f82_schlick, schlick_fresnel


def sqrt0(x: jax.Array) -> jax.Array:
    """``sqrt(x)`` of ``x >= 0`` (negatives read as 0) with a zero, not infinite,
    derivative at 0 (the double where)."""
    pos = x > 0.0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


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
    return sensitivity_xyz(opd, shift) @ jnp.asarray(XYZ_TO_REC709, opd.dtype).T


def sensitivity_xyz(opd: jax.Array, shift: jax.Array) -> jax.Array:
    """The CIE XYZ terms of :func:`_sensitivity`, before any conversion to RGB (N, 3): Belcour
    and Barla's Gaussian fits over ``integral of y-bar`` (1.0685e-7); ``opd`` in nm (N, 1),
    ``shift`` (N, 3). MaterialX's ``mx_eval_sensitivity`` (``opd`` in metres there)."""
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
    return (xyz + jnp.concatenate([extra, jnp.zeros_like(xyz[:, 1:])], axis=1)) / 1.0685e-7


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
    film_ior thickness cos(theta_2)`` (Belcour's code, the glTF sample viewer and the
    extension's text since 2024; earlier revisions wrote ``cos(theta_1)``), the Airy
    sum's terms ``m = 0, 1, 2`` integrated over the spectrum analytically
    (:func:`_sensitivity`), negatives clamped to 0.
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


def _atan2(y: jax.Array, x: jax.Array) -> jax.Array:
    """``atan2(y, x)`` with ``atan2(0, 0) = 0`` and a finite (zero) derivative there: the
    phases of a film whose index equals its base's, where ``R23 = 0`` multiplies them."""
    zero = (y == 0.0) & (x == 0.0)
    return jnp.arctan2(jnp.where(zero, 0.0, y), jnp.where(zero, 1.0, x))


XYZ_TO_CIE_RGB = (
    (2.3706743, -0.9000405, -0.4706338),
    (-0.5138850, 1.4253036, 0.0885814),
    (0.0052982, -0.0146949, 1.0093968),
)
"""CIE XYZ to CIE 1931 RGB (illuminant E), rows R, G, B: the matrix of MaterialX's
``mx_fresnel_airy`` (not Rec. 709's)."""


def _polarized(cos: jax.Array, n: jax.Array) -> tuple[jax.Array, jax.Array]:
    """``(R_p, R_s)`` of a dielectric interface of relative index ``n`` at ``cos``
    (``mx_fresnel_dielectric_polarized``, or ``mx_fresnel_conductor_polarized`` with
    ``k = 0``: 1 under total internal reflection).

    MaterialX writes ``R_s = (t1 - t2) / (t1 + t2)``, ``t1 = t0 + cos^2``, ``t2 = 2 sqrt(t0)
    cos``, ``t0 = n^2 - sin^2``: at ``n`` = 1 the two cancel to ~1e-16 where ``R_s`` is 0,
    and the Airy sum's ``sqrt(R12 R23)`` turns that into 1e-8 (the 40-digit reference
    found it). Where ``t0 >= 0`` the same quantities are taken without the difference:
    ``t1 - t2 = (sqrt(t0) - cos)^2`` and ``sqrt(t0) - cos = (n^2 - 1) / (sqrt(t0) + cos)``,
    so ``R_s = ((n^2 - 1) / (sqrt(t0) + cos)^2)^2`` and ``R_p = R_s ((cos sqrt(t0) -
    sin^2) / (cos sqrt(t0) + sin^2))^2``."""
    c2 = cos**2
    s2 = 1.0 - c2
    t0 = n**2 - s2
    root = sqrt0(t0)
    rs_exact = ((n**2 - 1.0) / (root + cos) ** 2) ** 2
    rp_exact = rs_exact * ((cos * root - s2) / (cos * root + s2)) ** 2
    t1 = jnp.abs(t0) + c2  # under total internal reflection, MaterialX's form
    t2 = 2.0 * root * cos
    rs = (t1 - t2) / (t1 + t2)
    t3 = c2 * jnp.abs(t0) + s2 * s2
    t4 = t2 * s2
    above = t0 >= 0.0
    return jnp.where(above, rp_exact, rs * (t3 - t4) / (t3 + t4)), jnp.where(above, rs_exact, rs)


def airy_fresnel(
    cos: jax.Array,
    film_ior: jax.Array,
    thickness_nm: jax.Array,
    base_ior: jax.Array,
    schlick: tuple[jax.Array, jax.Array] | None,
) -> jax.Array:
    """MaterialX's thin-film Fresnel ``mx_fresnel_airy`` (Belcour and Barla 2017), RGB (N, 3).

    Air above a film of ``film_ior`` (floored at 1) and ``thickness_nm`` on a base of index
    ``base_ior`` (3,); ``cos`` on the facet (N,). Polarised Airy sum: ``R12``, ``T121 = 1 -
    R12`` at the top (exact dielectric), ``R23`` at the base at the refracted ``cos_t``,
    phases ``phi21`` (0 below Brewster's angle, else pi; pi for s) and ``phi23``, optical
    path ``2 film_ior cos_t d``, terms ``m = 0, 1, 2`` integrated over the spectrum
    (:func:`sensitivity_xyz`); the mean of the two polarisations
    goes from XYZ to CIE RGB (:data:`XYZ_TO_CIE_RGB`), clamped to [0, 1].

    Dielectric base (``schlick`` None): exact polarised ``R23`` and its phases (the
    conductor forms with ``k = 0``). Metal (``schlick = (f0, tint)``): ``base_ior`` is
    ``(1 + sqrt f0) / (1 - sqrt f0)`` of ``f0`` clamped to [.01, .99], ``R23_p = R23_s =
    F82(cos_t) / 2`` (:func:`~brdffit.models._terms.f82_schlick`) and ``phi23 = pi`` where
    ``base_ior < film_ior``, else 0. MaterialX halves ``R23`` there and sums the metal's RGB
    as if it were XYZ, so even a film of index 1 gives ``M F82 / 2`` (``M`` the matrix), not
    ``F82``: half as bright and shifted in colour (``tests/models/test_openpbr.py``).
    """
    n2 = jnp.maximum(film_ior, 1.0)
    # >= cos^2 exactly (n2 >= 1): the floor keeps float32 rounding off sqrt(0)
    cos_t = jnp.sqrt(jnp.maximum(1.0 - (1.0 - cos**2) / n2**2, cos**2))
    r12p, r12s = _polarized(cos, n2)
    brewster = 1.0 / jnp.sqrt(1.0 + n2**2)  # cos(atan(n2))
    phi21 = (jnp.where(cos < brewster, 0.0, jnp.pi)[:, None], jnp.pi)
    n3 = base_ior[None, :]
    if schlick is None:
        r23p, r23s = _polarized(cos_t[:, None], n3 / n2)
        a = n3**2 - n2**2 * (1.0 - cos_t[:, None] ** 2)  # A of the phase, with k = 0
        u2, v = jnp.maximum(a, 0.0), sqrt0(-a)
        ct = cos_t[:, None]
        phi23s = _atan2(2.0 * n2 * v * ct, u2 + v * v - (n2 * ct) ** 2)
        phi23p = _atan2(2.0 * n2 * n3**2 * ct * (0.0 - v), (n3**2 * ct) ** 2 - n2**2 * (u2 + v * v))
    else:
        half = 0.5 * f82_schlick(*schlick, cos_t)
        r23p = r23s = half
        phi23p = phi23s = jnp.broadcast_to(jnp.where(n3 < n2, jnp.pi, 0.0), half.shape)
    opd = (2.0 * n2 * cos_t * thickness_nm)[:, None]
    total = jnp.zeros(cos.shape + (3,), cos.dtype)
    parts = ((r12p, r23p, phi23p, phi21[0]), (r12s, r23s, phi23s, phi21[1]))
    for r12, r23, phi23, p21 in parts:
        r12 = r12[:, None]
        t121 = 1.0 - r12
        # 1 - R12 R23 >= T121, so the floor 1e-18 (its square a float32 normal; met only where
        # float32 rounds both to 1 at grazing) leaves rs <= T121 and keeps 0/0 out
        rs = t121**2 * r23 / jnp.maximum(1.0 - r12 * r23, 1e-18)
        r123 = sqrt0(r12 * r23)
        total = total + r12 + rs
        cm = rs - t121
        for k in (1.0, 2.0):
            cm = cm * r123
            total = total + cm * 2.0 * sensitivity_xyz(k * opd, k * (phi23 + p21))
    rgb = (0.5 * total) @ jnp.asarray(XYZ_TO_CIE_RGB, total.dtype).T
    return jnp.clip(rgb, 0.0, 1.0)
