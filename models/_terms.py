"""Terms shared by several models: diffuse lobes, microfacet distributions, masking, Fresnel.

Each is a small pure JAX function of cosines or half-vector components from
:class:`~brdffit.geometry.ShadingGeometry`; inputs below the horizon are already
replaced by safe placeholders there, so no guard here needs a ``where`` against them.
Roughness ``alpha`` follows Walter et al. 2007 (GGX ``alpha_g``, Beckmann ``alpha_b``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

INV_PI = 0.3183098861837907


def lambert(albedo: jax.Array) -> jax.Array:
    """Lambertian BRDF ``albedo / pi`` (1/sr), shape (1, 3); ``albedo`` RGB in [0, 1]."""
    return albedo[None, :] * INV_PI


def schlick_fresnel(f0: jax.Array, cos_d: jax.Array) -> jax.Array:
    """Schlick (1994): ``F0 + (1 - F0)(1 - cos_d)^5``; ``f0`` (3,) and ``cos_d`` (N,) -> (N, 3)."""
    s = (1.0 - cos_d) ** 5
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


def smith_g(lambda_i: jax.Array, lambda_o: jax.Array, *, height_correlated: bool) -> jax.Array:
    """Masking-shadowing from Smith Lambdas: ``1/((1+Li)(1+Lo))`` or ``1/(1+Li+Lo)``."""
    if height_correlated:
        return 1.0 / (1.0 + lambda_i + lambda_o)
    return 1.0 / ((1.0 + lambda_i) * (1.0 + lambda_o))
