"""Ribardière, Bringier, Meneveaux and Simonot 2017, "STD: Student's t-Distribution of slopes
for microfacet based BSDFs" (Computer Graphics Forum 36(2), Eurographics), reflection part,
with a Lambert term: the Cook-Torrance form the authors fit to MERL (supplemental, eq. 1):

    f(wi, wo) = kd / pi + ks F(wi . h) D(h) G(wi, wo) / (4 cos_i cos_o)

* ``D``: the slopes ``(p, q) = -(hx, hy) / hz`` follow a bivariate Student t,
  ``P22 = (1 / (pi ax ay)) (1 + ((p/ax)^2 + (q/ay)^2) / (gamma - 1))^-gamma``, so

      D(h) = 1 / (pi ax ay hz^4 (1 + tan^2 / (alpha(phi)^2 (gamma - 1)))^gamma)

  (``ax = ay = alpha`` unless ``anisotropic=True``). ``int D cos theta_h dw = 1`` for every
  ``gamma > 1``; ``gamma = 2`` is GGX (Walter eq. 33) and ``gamma -> inf`` is Beckmann with
  the same ``alpha``. ``gamma > 3/2`` is needed for a finite Smith ``Lambda`` (the paper's
  bound); the table stops at 1.51 and at 100 (D within 4% of Beckmann's up to
  ``tan = 2 alpha`` there; the difference is ``~(q - q^2/2)/gamma``, ``q = tan^2/alpha^2``).
* ``G``: Smith, uncorrelated ``G1(i) G1(o)`` as in the paper, or
  ``masking="height_correlated"`` (``1 / (1 + Li + Lo)``). With ``z = 1/(alpha(phi) tan)``
  and ``K = Gamma(gamma - 1/2) / (Gamma(gamma) sqrt(pi))`` the paper's eq. 13 reads
  ``Lambda = K [(gamma-1)^gamma / (2 gamma - 3) (gamma - 1 + z^2)^(3/2 - gamma) / z
  + sqrt(gamma - 1) S2(z)] - 1/2`` with ``S2 = int_0^z (1 + u^2/(gamma-1))^(1/2-gamma) du``
  (eq. 15, a 2F1; the paper then fits S2 by rationals, eqs. 22-23, which we do not use).
  ``1/2 - K sqrt(gamma-1) S2`` is the Student-t tail ``Q = I_x(gamma-1, 1/2) / 2``,
  ``x = s / (1 + s)``, ``s = (gamma - 1) / z^2``. We evaluate it exactly, from
  ``E = K (s / (1 + s))^(gamma-1) (1 + s)^(-1/2)`` and the continued fraction ``CF`` of the
  regularised incomplete beta (Numerical Recipes ``betacf``, 64 terms, bottom-up):

      Lambda = E [(gamma-1)(1+s)/(2 gamma-3) - CF(gamma-1, 1/2; s/(1+s)) / 2]    1.5 s <= gamma
      Lambda = (gamma-1) E [(1+s)/(2 gamma-3) + CF(1/2, gamma-1; 1/(1+s))] - 1/2 otherwise

  (the second by ``I_x(a, b) = 1 - I_{1-x}(b, a)``, each where its fraction converges). What
  cancels (``~1/(2 gamma)`` in the first line, ``1/2`` in the second where ``Lambda`` is
  small) costs digits of ``Lambda`` but not of ``G = 1/(1 + Lambda)``: measured against
  mpmath, ``|dLambda| <= 1e-13 (1 + Lambda)`` and 3e-12 relative at ``gamma = 100`` (the
  ``gammaln`` difference in ``K``), 2e-15 for ``gamma <= 2``.
* ``F``: the exact dielectric Fresnel with refractive index ``eta`` (the paper's ``n_i``)
  scaled by RGB ``ks`` (the paper's specular albedo ``rho_s``); or, with
  ``fresnel="schlick"``, Schlick with RGB ``f0`` and no ``ks``. Affine in ``kd``, ``ks``
  and ``f0``. ``diffuse=False`` removes ``kd``.

The denominator is Cook-Torrance's ``4 cos_i cos_o`` (Walter 2007 eq. 20); the text we
could read of the supplemental's eq. 1 prints ``4 |i.h| |o.h|``, taken as a typesetting slip.
Equation numbers are those of the paper as cited by the BBM library's STD implementation;
the paper's own text was not at hand, the formulas were re-derived and checked by quadrature.

Singularities and guards: ``D`` is evaluated as ``exp(log D)`` with
``log1p(tan^2 / (alpha^2 (gamma-1)))``, finite for every half vector above the horizon
(``hz > 0``). ``Lambda`` at normal incidence (``s = 0``): ``E ~ s^(gamma-1)`` vanishes; below
``s = sqrt(tiny)`` of the dtype ``Lambda`` (< 16 s^0.51) is set to 0, with ``s`` sanitised
first so that neither ``log s`` nor its gradient meets 0. ``log(s/(1+s))`` is
``log s - log1p s`` for ``s < 1`` and ``-log1p(1/s)`` above, each branch sanitised. At
grazing ``Lambda ~ sqrt(s)``: ``G`` cancels ``1/(cos_i cos_o)`` to first order.
``1/(2 gamma - 3)`` is at most 50 on the bounds. Reciprocal; not energy conserving
(``kd`` and the specular term are uncoupled, single scattering only).
"""

from __future__ import annotations

from typing import ClassVar, Literal, final

import equinox as eqx
import jax
import jax.numpy as jnp

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models import _terms

KD = Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo rho_d, RGB", linear=True)
KS = Parameter("ks", (3,), (0.0, 1.0), 0.5, "logit", "specular albedo rho_s, RGB", linear=True)
ETA = Parameter(
    "eta", (), (1.01, 50.0), 1.5, "log", "refractive index n_i for Fresnel",
    neutral=_terms.DIELECTRIC_ETA,
)  # fmt: skip
F0 = Parameter(
    "f0", (3,), (0.0, 1.0), 0.04, "logit", "Schlick reflectance at normal incidence, RGB",
    linear=True, neutral=_terms.DIELECTRIC_F0,
)  # fmt: skip
ALPHA = Parameter("alpha", (), (1e-4, 2.0), 0.2, "log", "roughness alpha, unitless")
ALPHA_X = Parameter("alpha_x", (), (1e-4, 2.0), 0.2, "log", "roughness along the tangent x")
ALPHA_Y = Parameter("alpha_y", (), (1e-4, 2.0), 0.2, "log", "roughness along the bitangent y")
GAMMA = Parameter(
    "gamma", (), (1.51, 100.0), 2.0, "log", "Student-t shape: 2 is GGX, large is Beckmann",
    neutral=2.0,  # STD with gamma = 2 is GGX (Ribardiere et al. 2017)
)  # fmt: skip

CF_PAIRS = 32
"""Pairs of terms of the incomplete-beta continued fraction (64 terms; converged to 1e-13
relative for ``gamma <= 100``, measured against mpmath)."""


def incbeta_fraction(a: jax.Array, b: jax.Array, x: jax.Array) -> jax.Array:
    """``1 / (1 + d1 / (1 + d2 / ...))``, the continued fraction of ``I_x(a, b)`` (N,).

    ``I_x(a, b) = x^a (1 - x)^b / (a B(a, b)) * fraction`` (Numerical Recipes ``betacf``):
    ``d_{2m+1} = -(a+m)(a+b+m) x / ((a+2m)(a+2m+1))``, ``d_{2m} = m(b-m) x /
    ((a+2m-1)(a+2m))``, evaluated from the 64th term up. Converges fast for
    ``x < (a + 1)/(a + b + 2)``, where it is used.
    """

    def pair(i, t):
        m = jnp.asarray(CF_PAIRS - i, x.dtype)  # m = 32, ..., 1
        t = 1.0 + m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)) / t
        return 1.0 - (a + m - 1) * (a + b + m - 1) * x / ((a + 2 * m - 2) * (a + 2 * m - 1)) / t

    return 1.0 / jax.lax.fori_loop(0, CF_PAIRS, pair, jnp.ones_like(x))


def std_d(h: jax.Array, alpha_x: jax.Array, alpha_y: jax.Array, gamma: jax.Array) -> jax.Array:
    """STD microfacet distribution ``D(h)`` in 1/sr (module docstring), (N,)."""
    hz2 = h[:, 2] ** 2
    tan2 = _terms.slope_norm2(h, alpha_x, alpha_y) / hz2  # stretched tan^2
    log_d = (
        -jnp.log(jnp.pi * alpha_x * alpha_y)
        - 2.0 * jnp.log(hz2)
        - gamma * jnp.log1p(tan2 / (gamma - 1.0))
    )
    return jnp.exp(log_d)


def _lambda_of_s(s: jax.Array, gamma: jax.Array) -> tuple[jax.Array, jax.Array]:
    """``Lambda`` and ``dLambda/ds`` as functions of ``s = (gamma - 1) / z^2`` (N,) each."""
    live = s > jnp.sqrt(jnp.finfo(s.dtype).tiny)
    s = jnp.where(live, s, 1.0)
    low = s < 1.0
    log_x = jnp.where(  # log(s / (1 + s)), both branches sanitised
        low,
        jnp.log(jnp.where(low, s, 0.5)) - jnp.log1p(jnp.where(low, s, 0.5)),
        -jnp.log1p(1.0 / jnp.where(low, 2.0, s)),
    )
    log_k = jax.scipy.special.gammaln(gamma - 0.5) - jax.scipy.special.gammaln(gamma)
    e = jnp.exp(log_k - 0.5 * jnp.log(jnp.pi) + (gamma - 1.0) * log_x - 0.5 * jnp.log1p(s))
    head = (1.0 + s) / (2.0 * gamma - 3.0)
    swap = 1.5 * s > gamma
    a = jnp.where(swap, 0.5, gamma - 1.0)
    b = jnp.where(swap, gamma - 1.0, 0.5)
    cf = incbeta_fraction(a, b, jnp.where(swap, 1.0 / (1.0 + s), s / (1.0 + s)))
    lam = jnp.where(
        swap,
        (gamma - 1.0) * e * (head + cf) - 0.5,
        e * ((gamma - 1.0) * head - 0.5 * cf),
    )
    slope = (gamma - 1.0) * e * head / (2.0 * s)  # dLambda/ds = T / (2 s), closed form
    return jnp.where(live, jnp.maximum(lam, 0.0), 0.0), jnp.where(live, slope, 0.0)


@jax.custom_jvp
def std_lambda_s(s: jax.Array, gamma: jax.Array) -> jax.Array:
    """Smith ``Lambda`` of STD as a function of ``s = (gamma - 1) alpha(phi)^2 tan^2``, (N,).

    Differentiable once in reverse mode, any order forward: ``dLambda/ds`` in closed form,
    ``dLambda/dgamma`` by one forward-mode pass through the continued fraction (so the
    Jacobian of a fit costs two evaluations of the fraction, not one per parameter).
    """
    return _lambda_of_s(s, gamma)[0]


@std_lambda_s.defjvp
def _std_lambda_s_jvp(primals, tangents):
    s, gamma = primals
    s_dot, gamma_dot = tangents
    (lam, slope), (dlam_dgamma, _) = jax.jvp(
        lambda g: _lambda_of_s(s, g), (gamma,), (jnp.ones_like(gamma),)
    )
    return lam, slope * s_dot + dlam_dgamma * gamma_dot


def std_lambda(v: jax.Array, alpha_x: jax.Array, alpha_y: jax.Array, gamma: jax.Array) -> jax.Array:
    """Exact Smith ``Lambda`` of direction ``v`` for STD (module docstring), (N,)."""
    s = (gamma - 1.0) * _terms.projected_roughness2_tan2(v, alpha_x, alpha_y)
    return std_lambda_s(s, gamma)


@final
class STD(AbstractModel):
    """Student-t microfacet BRDF (Ribardière et al. 2017) with Fresnel and Lambert."""

    masking: Literal["uncorrelated", "height_correlated"] = eqx.field(
        static=True, default="uncorrelated"
    )
    fresnel: Literal["dielectric", "schlick"] = eqx.field(static=True, default="dielectric")
    anisotropic: bool = eqx.field(static=True, default=False)
    diffuse: bool = eqx.field(static=True, default=True)

    name: ClassVar[str] = "std"
    reference: ClassVar[str] = "Ribardière, Bringier, Meneveaux, Simonot 2017, CGF 36(2)"
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    def __check_init__(self) -> None:
        if self.masking not in ("uncorrelated", "height_correlated"):
            raise ValueError(
                f"std: masking {self.masking!r} not 'uncorrelated' or 'height_correlated'"
            )
        if self.fresnel not in ("dielectric", "schlick"):
            raise ValueError(f"std: fresnel {self.fresnel!r} not 'dielectric' or 'schlick'")

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        spec = (KS, ETA) if self.fresnel == "dielectric" else (F0,)
        rough = (ALPHA_X, ALPHA_Y) if self.anisotropic else (ALPHA,)
        return ((KD,) if self.diffuse else ()) + spec + rough + (GAMMA,)

    def roughness(self, params: Params) -> tuple[jax.Array, jax.Array]:
        """(alpha_x, alpha_y) for either roughness parametrisation."""
        if self.anisotropic:
            return params["alpha_x"], params["alpha_y"]
        return params["alpha"], params["alpha"]

    def ndf(self, params: Params, h: jax.Array) -> jax.Array:
        """The STD distribution ``D(h)`` in 1/sr, (N,)."""
        return std_d(h, *self.roughness(params), params["gamma"])

    def lambda_(self, params: Params, v: jax.Array) -> jax.Array:
        """Smith ``Lambda`` of direction ``v``, (N,)."""
        return std_lambda(v, *self.roughness(params), params["gamma"])

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        gg = _terms.smith_g(
            self.lambda_(params, g.wi),
            self.lambda_(params, g.wo),
            height_correlated=self.masking == "height_correlated",
        )
        lobe = self.ndf(params, g.h) * gg / (4.0 * g.cos_i * g.cos_o)
        if self.fresnel == "dielectric":
            f = _terms.fresnel_dielectric(g.cos_d, params["eta"])
            spec = params["ks"][None, :] * (f * lobe)[:, None]
        else:
            spec = _terms.schlick_fresnel(params["f0"], g.cos_d) * lobe[:, None]
        if self.diffuse:
            spec = spec + _terms.lambert(params["kd"])
        return spec
