"""Ashikhmin and Shirley 2000, "An anisotropic Phong BRDF model" (J. Graphics Tools 5(2)).

    f(wi, wo) = p_h(h) F(wi . h) / (4 (wi . h) max(cos_i, cos_o))                 (spec)
              + 28 Rd / (23 pi) (1 - Rs) (1 - (1 - cos_i/2)^5) (1 - (1 - cos_o/2)^5)  (diff)

    p_h(h) = sqrt((nu + 1)(nv + 1)) / (2 pi) (n . h)^e,   e = (nu hx^2 + nv hy^2) / (1 - hz^2)

with Schlick's ``F = Rs + (1 - Rs)(1 - wi . h)^5``; RGB ``Rs`` and ``Rd``. The paper's
specular constant ``sqrt((nu+1)(nv+1))/(8 pi)`` is ``p_h/4``; ``p_h`` is the exact pdf of
the half vector (``int p_h dw_h = 1``), which is what the paper samples. ``e`` is
``nu cos^2 phi_h + nv sin^2 phi_h``; ``anisotropic=False`` uses one exponent ``n``.

Linear parameters: ``f`` is affine in ``Rd`` and, separately, in ``Rs``, but the coupled
diffuse term holds the product ``Rd (1 - Rs)``: the model is not jointly affine in both, so
only ``rd`` is flagged ``linear`` (the albedo a variable-projection solve recovers).

Singularities: ``e`` is 0/0 at ``h = n``; it is written ``(nu hx^2 + nv hy^2)/(hx^2 + hy^2)``
with the denominator replaced by 1 where it is below 1e-30 (the base ``n . h`` is 1 there, so
any finite exponent gives the right value). ``(n . h)^e`` is ``exp(e log cos_h)`` with
``log cos_h`` from the tangential components near the normal (exponents reach 1e5).
``1/((wi . h) max(cos_i, cos_o))`` grows to ~1e12 at grazing mirror pairs but stays finite.
The diffuse factors ``1 - (1 - cos/2)^5 ~ 5 cos/2`` cancel at grazing angles when written as
printed (relative error ~1e-16/cos: 1e-6 at cos 1e-10): they are ``-expm1(5 log1p(-cos/2))``.
Option ``diffuse="lambert"`` is the form Ngan et al. 2005 and Löw et al. 2012 fitted to
the MERL materials (their published fits): the specular lobe alone, scaled by an RGB
``ks``, plus a Lambertian ``kd / pi`` instead of the coupled term,

    f(wi, wo) = kd / pi + ks p_h(h) F(wi . h) / (4 (wi . h) max(cos_i, cos_o))

with Schlick's ``F`` of a reflectance ``rs`` (Ngan) or, with ``fresnel="dielectric"``, the
exact unpolarised Fresnel of a dielectric of index ``eta`` (Löw; ``F(1) = ((eta - 1)/(eta +
1))^2``, so ``ks`` runs to 10). This variant is not energy conserving (``kd`` and ``ks``
are independent), unlike the paper's coupled form; ``energy_conserving`` describes the latter.
Reciprocal (``max`` and ``wi . h = wo . h`` are symmetric). Energy conserving, as the paper
claims: checked by quadrature over ``Rs``, ``n`` and incidence with ``Rd = 1``
(``tests/models/test_ashikhmin_shirley.py``); the largest albedo, 0.99996, is at ``Rs = 1``,
``n = 1e5``, normal incidence, where ``albedo <= int p_h dw_h = 1`` holds exactly because
``F = 1`` and ``cos_o / max(cos_i, cos_o) <= 1``.
"""

from __future__ import annotations

from typing import ClassVar, Literal, final

import equinox as eqx
import jax
import jax.numpy as jnp

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models._terms import (
    DIELECTRIC_ETA,
    DIELECTRIC_F0,
    INV_PI,
    fresnel_dielectric,
    lambert,
    log_cos_theta_h,
    schlick_fresnel,
)

RD = Parameter("rd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo Rd, RGB", linear=True)
RS = Parameter(
    "rs", (3,), (0.0, 1.0), 0.05, "logit", "specular reflectance at normal incidence Rs, RGB",
    neutral=DIELECTRIC_F0,
)  # fmt: skip
N = Parameter("n", (), (0.1, 1e5), 100.0, "log", "Phong exponent, unitless")
NU = Parameter("nu", (), (0.1, 1e5), 100.0, "log", "Phong exponent along the tangent x")
NV = Parameter("nv", (), (0.1, 1e5), 100.0, "log", "Phong exponent along the bitangent y")
# The Lambertian variant (Ngan et al. 2005, Löw et al. 2012): kd / pi plus the lobe scaled by ks.
KD = Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "Lambertian diffuse albedo, RGB", linear=True)
KS = Parameter("ks", (3,), (0.0, 1.0), 0.5, "logit", "specular lobe scale, RGB", linear=True)
# With an exact dielectric Fresnel, F(1) = ((eta - 1)/(eta + 1))^2 is small (0.04 at 1.5), so
# the lobe's scale goes past 1 while its normal-incidence albedo ks F(1) stays small: Löw et
# al.'s published fits reach ks = 1.82. The bound 10 is not physical (ks F(1) reaches 1 at
# eta = 1.92); it leaves room for what the published fits use.
KS_DIELECTRIC = Parameter(
    "ks", (3,), (0.0, 10.0), 1.0, "logit", "specular lobe scale, RGB", linear=True
)
ETA = Parameter(
    "eta", (), (1.01, 10.0), 1.5, "log", "relative index of refraction, unitless",
    neutral=DIELECTRIC_ETA,
)  # fmt: skip
DIFFUSE = ("coupled", "lambert")
FRESNEL = ("schlick", "dielectric")


def exponent(h: jax.Array, nu: jax.Array, nv: jax.Array) -> jax.Array:
    """``e = (nu hx^2 + nv hy^2) / (hx^2 + hy^2)``, (N,); any finite value at ``h = n``."""
    s2 = h[:, 0] ** 2 + h[:, 1] ** 2
    safe = jnp.where(s2 > 1e-30, s2, 1.0)
    return (nu * h[:, 0] ** 2 + nv * h[:, 1] ** 2) / safe


def half_vector_pdf(h: jax.Array, nu: jax.Array, nv: jax.Array, e: jax.Array) -> jax.Array:
    """``p_h = sqrt((nu+1)(nv+1))/(2 pi) cos_h^e`` (1/sr), (N,): integrates to 1 over ``h``."""
    return jnp.sqrt((nu + 1.0) * (nv + 1.0)) * (0.5 * INV_PI) * jnp.exp(e * log_cos_theta_h(h))


def one_minus_fifth_power(x: jax.Array) -> jax.Array:
    """``1 - (1 - x)^5`` for ``x`` in (0, 1/2], as ``-expm1(5 log1p(-x))``: no cancellation."""
    return -jnp.expm1(5.0 * jnp.log1p(-x))


def coupled_diffuse(rd: jax.Array, rs: jax.Array, g: ShadingGeometry) -> jax.Array:
    """``28 Rd/(23 pi) (1 - Rs)(1 - (1 - cos_i/2)^5)(1 - (1 - cos_o/2)^5)`` (1/sr), (N, 3)."""
    shape = one_minus_fifth_power(0.5 * g.cos_i) * one_minus_fifth_power(0.5 * g.cos_o)
    return (28.0 / 23.0 * INV_PI) * (rd * (1.0 - rs))[None, :] * shape[:, None]


@final
class AshikhminShirley(AbstractModel):
    """Anisotropic Phong lobe with Schlick Fresnel and the coupled (energy-sharing) diffuse."""

    anisotropic: bool = eqx.field(static=True, default=False)
    diffuse: Literal["coupled", "lambert"] = eqx.field(static=True, default="coupled")
    fresnel: Literal["schlick", "dielectric"] = eqx.field(static=True, default="schlick")

    name: ClassVar[str] = "ashikhmin_shirley"
    reference: ClassVar[str] = "Ashikhmin, Shirley 2000, J. Graphics Tools 5(2)"
    energy_conserving: ClassVar[bool] = True  # the paper's coupled form; see the module text
    channel_separable: ClassVar[bool] = True

    def __check_init__(self) -> None:
        if self.diffuse not in DIFFUSE:
            raise ValueError(f"ashikhmin_shirley: diffuse {self.diffuse!r} not one of {DIFFUSE}")
        if self.fresnel not in FRESNEL:
            raise ValueError(f"ashikhmin_shirley: fresnel {self.fresnel!r} not one of {FRESNEL}")
        if self.fresnel == "dielectric" and self.diffuse == "coupled":
            raise ValueError(
                "ashikhmin_shirley: fresnel='dielectric' needs diffuse='lambert' (the coupled "
                "diffuse term is written in the Schlick reflectance Rs)"
            )

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        lobe = (NU, NV) if self.anisotropic else (N,)
        if self.diffuse == "coupled":
            return (RD, RS) + lobe
        if self.fresnel == "schlick":
            return (KD, KS, RS) + lobe
        return (KD, KS_DIELECTRIC, ETA) + lobe

    def lobe(self, params: Params, h: jax.Array) -> jax.Array:
        """The half-vector pdf ``p_h(h)`` for either exponent parametrisation, (N,)."""
        if self.anisotropic:
            nu, nv = params["nu"], params["nv"]
            return half_vector_pdf(h, nu, nv, exponent(h, nu, nv))
        n = params["n"]
        return half_vector_pdf(h, n, n, n)

    def fresnel_term(self, params: Params, cos_d: jax.Array) -> jax.Array:
        """F at the facet incidence cosine ``wi . h``: (N, 3) Schlick, (N, 1) dielectric."""
        if self.fresnel == "schlick":
            return schlick_fresnel(params["rs"], cos_d)
        return fresnel_dielectric(cos_d, params["eta"])[:, None]

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        denom = 4.0 * g.cos_d * jnp.maximum(g.cos_i, g.cos_o)
        spec = self.fresnel_term(params, g.cos_d) * (self.lobe(params, g.h) / denom)[:, None]
        if self.diffuse == "coupled":
            return spec + coupled_diffuse(params["rd"], params["rs"], g)
        return params["ks"][None, :] * spec + lambert(params["kd"])
