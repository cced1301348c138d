"""He, Torrance, Sillion and Greenberg 1991, "A comprehensive physical model for light
reflection" (SIGGRAPH 1991), in the form Ngan et al. 2005 fitted to the MERL materials, as
bsdfbenchmark's ``bbm`` evaluates their published fits (``NganHe`` in ``bsdfmodel/ngan.h``:
``he_base<fresnel::cook, he_eq25::Errata, he_eq78::Westin, 4, 64, true, 18>``), plus Lambert.

    f(wi, wo) = kd / pi + ks rho_dd(wi, wo)
    rho_dd    = F(eta, wi.h) S(theta_i) S(theta_o) G D / (pi cos_i cos_o)            (Eq. 71)

Only the paper's directional-diffuse term: no specular delta (Eqs. 70, 73-74), and its
uniform-diffuse term is the Lambert ``kd``. ``ks`` is bbm's ``SpecularScale`` "albedo".

* Shadowing (Eqs. 24-25), with the errata's exponential in Eq. 25 (Pacanowski and
  Holzschuch's errata; Westin et al.'s code), ``c = tau cot(theta) / (2 sigma_0)``:

      S(theta) = (1 - erfc(c) / 2) / (Lambda + 1),
      Lambda   = (exp(-c^2) / (sqrt(pi) c) - erfc(c)) / 2.

* Geometry (Eq. 76), ``k_i = -wi``, ``k_r = wo``, ``v = k_r - k_i = wi + wo``:
  ``G = (v.v / v_z)^2 [(s_r.k_i)^2 + (p_r.k_i)^2][(s_i.k_r)^2 + (p_i.k_r)^2] / |k_i x k_r|^4``.
  ``(s, p, k)`` is an orthonormal triad for each direction, so each bracket is
  ``1 - (k_i.k_r)^2 = |k_i x k_r|^2`` and ``G = (v.v / v_z)^2`` exactly; bbm's ``G`` is that
  up to rounding (and 1 where ``|k_i x k_r|^4 <= eps``, which it also is), so the model
  uses the closed form, free of bbm's 0/0 at normal incidence.
* Apparent roughness (Eqs. 80, 82-83): ``sigma = sigma_0 / sqrt(1 + x^2)`` with ``x =
  z_0 / sigma_0`` the root of ``x exp(x^2 / 2) = (K_i + K_o) / sqrt(8 pi)``,
  ``K = tan(theta) erfc(c)`` (0 where ``tan(theta) <= eps``). As bbm (after Westin): start
  at ``x = f0`` for ``f0 <= 1``, else ``sqrt(2 ln f0)`` (both above the root of a convex
  increasing function), then exactly :data:`NEWTON_STEPS` Newton steps, written
  ``x -= (x - f0 exp(-x^2/2)) / (1 + x^2)`` (bbm's step divided through by ``exp(x^2/2)``:
  no overflow at grazing). Four steps leave ``sigma`` within 3e-5 of the root for ``f0`` up
  to 1e6 (grazing); bbm stops there too.
* Distribution (Eqs. 78-79, 84), per RGB channel with wavelength ``lambda``
  (:data:`WAVELENGTHS`, bbm's ``Config::wavelength()`` in micrometres):

      g = (2 pi sigma (cos_i + cos_o) / lambda)^2
      D = (pi^2 tau^2 / (4 lambda^2)) sum_{m >= 1} g^m e^-g / (m! m) exp(-a / m),
      a = pi^2 tau^2 v_xy^2 / lambda^2

  with ``v_xy^2 = |wi_xy + wo_xy|^2``: Westin's reading of Eq. 78 (the paper's ``v`` is a
  wave vector, ``2 pi / lambda`` times ours; bbm's ``he_eq78::Westin``). The series as bbm
  sums it: terms ``m = 1..`` :data:`TAYLOR_TERMS` at most, stopping after the first term
  (``m >= 2``) whose smallest channel value is below ``eps`` (2.2e-16) and below the previous
  term's smallest channel value; the terms are evaluated in log space, ``exp(-g - a/m + m ln g
  - ln m! - ln m)``, so ``g^m / m!`` never overflows, and the stop is decided on those logs
  (a term below float64's range is not read as 0; :func:`he_series`). Where ``g_min =
  min_rgb g > 18`` (:data:`ROUGH_G`) Beckmann and Spizzichino's rough limit (1963, Sec.
  5.3, Eq. 47) ``D = (pi^2 tau^2 / (4 lambda^2)) exp(-a / g) / g`` is blended in with weight
  ``clip(g_min - 18, 0, 1)``; above ``g_min = 19`` the series is not summed.
* Fresnel: Cook and Torrance's unpolarised dielectric formula with a real relative index
  ``eta`` (bbm's ``fresnel::cook``; not the paper's complex-index Eq. 75) at the half angle,
  ``cos = sqrt((1 + wi.wo) / 2)`` as bbm writes it (``wi.h`` for unit vectors).

Units: ``sigma`` (rms height sigma_0) and ``tau`` (autocorrelation length) in micrometres,
as the wavelengths (0.645, 0.526, 0.444) um of R, G, B: the published fit file's
``roughness`` and ``autocorrelation``. Only ``sigma / lambda``, ``tau / lambda`` and
``tau / sigma`` enter; in the rough limit ``D`` is Beckmann's distribution with rms slope
``2 sigma / tau`` (``sigma`` the apparent roughness).

Parameters and bounds hold every one of the 86 published Ngan fits (bbm ``fits/ngan_he.fit``:
``roughness`` 0.01-8.74, ``autocorrelation`` 3.97-103, ``eta`` 1.0-15, ``albedo`` up to
1.96e9 where ``eta = 1.0``, i.e. ``F`` = 0 as printed). ``kd`` and ``ks`` are affine.

Discontinuities (as in bbm): the series' adaptive cut is a decision on parameter values,
taken with masks: where it moves by one term the value jumps by that term (below ``eps`` in
the smallest channel) and the derivative ignores the jump. The Newton start switches at
``f0 = 1`` (``sigma`` jumps by 2e-6 relative). The rough blend is continuous (weight 0 at
``g_min = 18``, 1 at 19, where the series is dropped).

Guards: ``S`` is 1 and ``K`` is 0 at normal incidence (``where`` on both sides); ``ln g``,
the rough limit's ``1 / g`` and ``sqrt(2 ln f0)`` take safe stand-ins where their branch is
not used (double ``where``), so values and forward- and reverse-mode derivatives are finite
from normal incidence to grazing (cos 1e-6) over the bounds. ``1 / (cos_i cos_o)`` is
cancelled at grazing by ``S ~ sqrt(pi) tau cos / (2 sigma_0)``. Reciprocal, isotropic, not
energy conserving (``ks`` unbounded).
"""

from __future__ import annotations

import math
from typing import ClassVar, final

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import erfc

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models._terms import INV_PI, fresnel_dielectric, lambert

WAVELENGTHS = (0.645, 0.526, 0.444)
"""Wavelength of the R, G, B channels in micrometres (bbm's ``Config::wavelength()``)."""
NEWTON_STEPS = 4
"""Newton-Raphson steps for the apparent roughness (Eq. 80), as bbm's ``NganHe``."""
TAYLOR_TERMS = 64
"""Most terms of the series of Eq. 78 (bbm's ``NganHe``)."""
ROUGH_G = 18.0
"""``min_rgb g`` from which the rough limit is blended in (over ``[18, 19]``)."""
EPS = float(np.finfo(np.float64).eps)
"""bbm's ``Constants::Epsilon()`` of its double configuration: the series' stopping size
and the threshold of ``tan(theta)`` in ``K``."""
LOG_EPS = math.log(EPS)
SQRT_PI = math.sqrt(math.pi)
INV_SQRT_8PI = 1.0 / math.sqrt(8.0 * math.pi)

_M = np.arange(1, TAYLOR_TERMS + 1, dtype=float)
_LOG_M_FACT_M = tuple(float(math.lgamma(m + 1.0) + math.log(m)) for m in _M)
"""``ln(m! m)`` for ``m = 1..TAYLOR_TERMS``, the series' constant denominators."""

KD = Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "Lambert albedo (kd / pi), RGB", linear=True)
KS = Parameter(
    "ks",
    (3,),
    (0.0, math.inf),
    1.0,
    "log",
    "scale of the directional-diffuse term (bbm's NganHe albedo), RGB",
    linear=True,
)
SIGMA = Parameter("sigma", (), (1e-3, 20.0), 0.3, "log", "rms surface height sigma_0, um")
TAU = Parameter("tau", (), (0.1, 1000.0), 20.0, "log", "autocorrelation length tau, um")
ETA = Parameter("eta", (), (1.0, 20.0), 1.5, "log", "real relative index of refraction (Cook)")


def shadowing(c: jax.Array, sin: jax.Array, tau: jax.Array, sigma0: jax.Array) -> jax.Array:
    """``S(theta)`` of Eqs. 24-25 with the errata's ``exp(-c^2)``; 1 at normal incidence.

    ``c``, ``sin``: cosine and sine of the direction's polar angle, (N,).
    """
    normal = sin <= 0.0
    x = tau * c / (2.0 * sigma0 * jnp.where(normal, 1.0, sin))
    x = jnp.where(normal, 1.0, x)
    tail = erfc(x)
    lam = 0.5 * (jnp.exp(-(x**2)) / (SQRT_PI * x) - tail)
    return jnp.where(normal, 1.0, (1.0 - 0.5 * tail) / (lam + 1.0))


def apparent_roughness(
    ci: jax.Array, si: jax.Array, co: jax.Array, so: jax.Array, tau: jax.Array, sigma0: jax.Array
) -> jax.Array:
    """``sigma = sigma_0 / sqrt(1 + x^2)`` of Eq. 80 by :data:`NEWTON_STEPS` Newton steps."""

    def k_term(c: jax.Array, s: jax.Array) -> jax.Array:  # Eqs. 82-83
        tan = s / c
        ok = tan > EPS
        tan_safe = jnp.where(ok, tan, 1.0)
        return jnp.where(ok, tan_safe * erfc(tau / (2.0 * sigma0 * tan_safe)), 0.0)

    f0 = INV_SQRT_8PI * (k_term(ci, si) + k_term(co, so))
    big = f0 > 1.0
    x = jnp.where(big, jnp.sqrt(2.0 * jnp.log(jnp.where(big, f0, math.e))), f0)
    for _ in range(NEWTON_STEPS):
        x = x - (x - f0 * jnp.exp(-0.5 * x * x)) / (1.0 + x * x)
    return sigma0 / jnp.sqrt(1.0 + x * x)


def he_series(g: jax.Array, a: jax.Array) -> jax.Array:
    """``sum_m g^m e^-g exp(-a / m) / (m! m)`` as bbm sums it (module docstring), (N, 3).

    ``g``, ``a``: (N, 3) per channel, ``a = pi^2 tau^2 v_xy^2 / lambda^2``. Samples whose
    ``min_rgb g`` exceeds ``ROUGH_G + 1`` sum nothing (0). A ``lax.scan`` over the
    :data:`TAYLOR_TERMS` terms carries the sum, the stop flag and the log of the last term's
    smallest channel. The stop is decided on the logs of the terms, as in exact arithmetic:
    a term below float64's range (or flushed to zero as a subnormal by XLA) would otherwise
    read as 0, never "below the previous one", and the series would run on in the other
    channels (bbm, with subnormals but no range below 5e-324, does so where the smallest
    channel's term is 0: its values differ from the exact rule there only where they are
    far below 1e-200).
    """
    skip = jnp.min(g, axis=-1) > ROUGH_G + 1.0
    positive = g > 0.0
    use = positive & ~skip[:, None]
    g_s = jnp.where(use, g, 1.0)
    a_s = jnp.where(use, a, 0.0)
    log_g = jnp.log(g_s)

    def step(carry, xs):
        total, stopped, last = carry
        m, log_denominator = xs
        log_term = -g_s - a_s / m + m * log_g - log_denominator
        total = total + jnp.where(use & ~stopped[:, None], jnp.exp(log_term), 0.0)
        smallest = jnp.min(log_term, axis=-1)  # the stop, decided on logs: no underflow
        stopped = stopped | ((smallest < LOG_EPS) & (smallest < last))
        return (total, stopped, smallest), None

    dtype = g.dtype
    init = (jnp.zeros_like(g), skip, jnp.full(g.shape[:-1], -jnp.inf, dtype))
    xs = (jnp.asarray(_M, dtype), jnp.asarray(_LOG_M_FACT_M, dtype))
    (total, _, _), _ = jax.lax.scan(step, init, xs)
    return total


def he_distribution(
    sigma: jax.Array, cos_sum: jax.Array, vxy2: jax.Array, tau: jax.Array
) -> jax.Array:
    """``D`` of Eq. 78 (Westin's exponent) with the rough limit blended in, (N, 3)."""
    lam = jnp.asarray(WAVELENGTHS, cos_sum.dtype)[None, :]
    g = (2.0 * jnp.pi * (sigma * cos_sum)[:, None] / lam) ** 2  # Eq. 79
    tau_lam2 = (tau / lam) ** 2
    a = jnp.pi**2 * tau_lam2 * vxy2[:, None]
    norm = 0.25 * jnp.pi**2 * tau_lam2
    g_min = jnp.min(g, axis=-1)
    weight = jnp.clip(g_min - ROUGH_G, 0.0, 1.0)[:, None]
    rough_on = (g_min > ROUGH_G)[:, None]
    g_r = jnp.where(rough_on, g, ROUGH_G + 1.0)
    rough = jnp.where(rough_on, jnp.exp(-a / g_r) / g_r, 0.0)
    series = he_series(g, a)
    return norm * ((1.0 - weight) * series + weight * rough)


@final
class He(AbstractModel):
    """He et al. 1991 directional-diffuse term as bbm's NganHe (Ngan et al. 2005), plus Lambert."""

    name: ClassVar[str] = "he"
    reference: ClassVar[str] = (
        "He, Torrance, Sillion, Greenberg 1991, A comprehensive physical model for light "
        "reflection (SIGGRAPH); as fitted by Ngan et al. 2005 (bbm NganHe)"
    )
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return (KD, KS, SIGMA, TAU, ETA)

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        sigma0, tau = params["sigma"], params["tau"]
        wi, wo = g.wi, g.wo
        ci, co = g.cos_i, g.cos_o
        si = jnp.sqrt(wi[:, 0] ** 2 + wi[:, 1] ** 2)
        so = jnp.sqrt(wo[:, 0] ** 2 + wo[:, 1] ** 2)
        shadow = shadowing(ci, si, tau, sigma0) * shadowing(co, so, tau, sigma0)
        v = wi + wo
        geometry = (jnp.sum(v * v, axis=-1) / v[:, 2]) ** 2  # Eq. 76
        vxy2 = v[:, 0] ** 2 + v[:, 1] ** 2  # Eq. 84
        sigma = apparent_roughness(ci, si, co, so, tau, sigma0)
        d = he_distribution(sigma, ci + co, vxy2, tau)
        cos_half = jnp.sqrt(jnp.maximum(0.5 * (1.0 + jnp.sum(wi * wo, axis=-1)), 0.0))
        fresnel = fresnel_dielectric(cos_half, params["eta"])
        lobe = fresnel * shadow * geometry * INV_PI / (ci * co)
        return lambert(params["kd"]) + params["ks"][None, :] * lobe[:, None] * d
