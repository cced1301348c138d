"""Löw, Kronander, Ynnerman and Unger 2012, "BRDF models for accurate and efficient
rendering of glossy surfaces", ACM Transactions on Graphics 31(1), article 9.

Both of the paper's models, chosen by the static option ``variant``; each adds a Lambert
term and uses the ABC (K-correlation) curve ``S(x) = (1 + B x)^-C`` with a normalising
factor that follows from ``B`` and ``C`` (below), so that ``ks`` is a specular albedo.

``variant="abc"`` (the microfacet model, paper eq. 15, with the V-cavity masking the
paper takes from Cook-Torrance):

    f = kd / pi + ks F(cos_d) / F(1) G D(h) / (4 cos_i cos_o)
    D(h) = A / (1 + B (1 - cos_h))^C,  G = min(1, 2 cos_h cos_i / cos_d, 2 cos_h cos_o / cos_d)
    1 / A = int D/A cos_h dw = 2 pi int_0^1 mu (1 + B (1 - mu))^-C dmu
          = (2 pi / B^2) [(1 + B) phi(1 - C) - phi(2 - C)],
    phi(k) = int_1^{1+B} u^(k-1) du = ((1 + B)^k - 1) / k = expm1(k ln(1 + B)) / k

so that ``int D cos_h dw = 1``. ``1 - cos_h`` is computed as ``(hx^2 + hy^2)/(1 + hz)``,
which keeps its precision at the peak for ``B`` up to 1e8.

``variant="smooth"`` (the smooth-surface model inspired by Rayleigh-Rice, eqs. 10-14,
no masking):

    f = kd / pi + ks F(cos_d') / F(1) S,   S = A' / (1 + B |wi_p + wo_p|^2)^C

``wi_p``, ``wo_p`` are the directions projected on the tangent plane (``|d_p - r_p|`` of
the paper with ``r`` the mirror direction of ``wi``), ``A' = B / (pi phi(1 - C))``
normalises ``S`` over the unit disk, so ``ks`` is the lobe's albedo at normal incidence
but for the Fresnel ratio (1 at the peak, growing away from it).
``cos_d' = sqrt(1 - |wi_p - wo_p|^2 / 4)`` is the paper's projected-vector expression
(eq. 14, as the bbm reference implementation reads it): it equals ``cos theta_d`` when
``theta_i = theta_o`` and exceeds it by ``(cos_i - cos_o)^2 / 4`` in its square otherwise.
It is evaluated as ``sqrt(|wi_p + wo_p|^2 + 2 cos_i^2 + 2 cos_o^2) / 2`` (same value,
no cancellation, > 0 above the horizon).

Fresnel: the paper's exact dielectric ``F(c, eta)`` (Cook-Torrance form), divided by
``F(1, eta) = ((eta - 1)/(eta + 1))^2``. The paper multiplies an unnormalised ``A`` by
``F``; there that scale and ``F(1, eta)`` are degenerate (only their product is seen),
which the division removes. The paper's scale is ``A_paper = ks A / (4 F(1))`` (abc; the
fits in its supplement divide by an extra ``pi``, i.e. list ``pi A_paper``) and
``A_paper = ks A' / F(1)`` (smooth); ``B``, ``C``, ``eta`` are the paper's.

Guards: ``phi(k)`` switches to its series ``x (1 + k x / 2 + (k x)^2 / 6)`` for
``|k x| < 1e-3`` (removable singularities at ``C = 1`` and ``C = 2``; the other branch
sees ``k = 1`` there); the curves are evaluated as ``exp(-C log1p(B x))``; ``1/(cos_i
cos_o)`` is cancelled to first order by the V-cavity ``G``. Not energy conserving
(``kd`` and ``ks`` uncoupled, ``F/F(1)`` reaches ``1/F(1)`` at grazing). Reciprocal,
isotropic.

Fitting: near the peak ``(1 + B x)^-C = exp(-BC x + (BC x)^2 / (2C) - ...)``, so the
data fix the product ``BC`` (the peak's width) long before ``C`` (the departure from a
Gaussian, through ``1/C`` only). The least-squares solver therefore works on
``(ln BC, 1/C)`` rather than ``(ln B, ln C)`` (:attr:`Parameter.product_with`); the
parameters and their errors are reported as the paper's ``B`` and ``C``.
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

PARAMETERS = (
    Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo, RGB", linear=True),
    Parameter(
        "ks",
        (3,),
        (0.0, 1.0),
        0.2,
        "logit",
        "specular scale, the lobe albedo at normal incidence without Fresnel, RGB",
        linear=True,
    ),
    Parameter("B", (), (0.1, 1e8), 100.0, "log", "ABC curve width parameter, unitless"),
    Parameter(
        "C",
        (),
        (1e-3, 10.0),
        1.5,
        "log",
        "ABC curve fall-off exponent, unitless",
        product_with="B",  # solved as (ln BC, 1/C): see the module docstring
    ),
    Parameter(
        "eta",
        (),
        (1.01, 100.0),
        1.5,
        "log",
        "relative index of refraction, unitless",
        neutral=_terms.DIELECTRIC_ETA,
    ),
)


def abc_phi(k: jax.Array, x: jax.Array) -> jax.Array:
    """``phi = (exp(k x) - 1) / k`` (``= int_1^{1+B} u^(k-1) du`` for ``x = ln(1+B)``)."""
    small = jnp.abs(k * x) < 1e-3
    k_safe = jnp.where(small, 1.0, k)
    series = x * (1.0 + k * x / 2.0 + (k * x) ** 2 / 6.0)
    return jnp.where(small, series, jnp.expm1(k_safe * x) / k_safe)


def abc_ndf_norm(b: jax.Array, c: jax.Array) -> jax.Array:
    """``A`` such that ``int A (1 + B (1 - cos))^-C cos dw = 1`` over the hemisphere."""
    x = jnp.log1p(b)
    integral = ((1.0 + b) * abc_phi(1.0 - c, x) - abc_phi(2.0 - c, x)) / b**2
    return 1.0 / (2.0 * jnp.pi * integral)


def abc_disk_norm(b: jax.Array, c: jax.Array) -> jax.Array:
    """``A'`` such that ``int A' (1 + B |p|^2)^-C d^2p = 1`` over the unit disk."""
    return b / (jnp.pi * abc_phi(1.0 - c, jnp.log1p(b)))


def abc_ndf(h: jax.Array, b: jax.Array, c: jax.Array) -> jax.Array:
    """Normalised ABC microfacet distribution ``A / (1 + B (1 - cos_h))^C`` (1/sr), (N,)."""
    one_minus_cos = (h[:, 0] ** 2 + h[:, 1] ** 2) / (1.0 + h[:, 2])
    return abc_ndf_norm(b, c) * jnp.exp(-c * jnp.log1p(b * one_minus_cos))


def smooth_lobe(wi: jax.Array, wo: jax.Array, b: jax.Array, c: jax.Array) -> jax.Array:
    """Normalised smooth-surface curve ``A' / (1 + B |wi_p + wo_p|^2)^C`` (1/sr), (N,)."""
    q = (wi[:, 0] + wo[:, 0]) ** 2 + (wi[:, 1] + wo[:, 1]) ** 2
    return abc_disk_norm(b, c) * jnp.exp(-c * jnp.log1p(b * q))


def projected_cos_d(wi: jax.Array, wo: jax.Array) -> jax.Array:
    """The paper's ``sqrt(1 - |wi_p - wo_p|^2 / 4)``, written without cancellation, (N,)."""
    q = (wi[:, 0] + wo[:, 0]) ** 2 + (wi[:, 1] + wo[:, 1]) ** 2
    return 0.5 * jnp.sqrt(q + 2.0 * wi[:, 2] ** 2 + 2.0 * wo[:, 2] ** 2)


def normalised_fresnel(cos: jax.Array, eta: jax.Array) -> jax.Array:
    """``F(cos, eta) / F(1, eta)``: exact dielectric Fresnel relative to normal incidence."""
    f1 = ((eta - 1.0) / (eta + 1.0)) ** 2
    return _terms.fresnel_dielectric(cos, eta) / f1


@final
class Low(AbstractModel):
    """Löw et al. 2012: ABC microfacet or smooth-surface lobe, exact Fresnel, Lambert."""

    variant: Literal["abc", "smooth"] = eqx.field(static=True, default="abc")

    name: ClassVar[str] = "low"
    reference: ClassVar[str] = "Löw, Kronander, Ynnerman, Unger 2012, ACM TOG 31(1)"
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    def __check_init__(self) -> None:
        if self.variant not in ("abc", "smooth"):
            raise ValueError(f"low: variant {self.variant!r} not 'abc' or 'smooth'")

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return PARAMETERS

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        b, c, eta = params["B"], params["C"], params["eta"]
        if self.variant == "abc":
            gg = _terms.v_cavity_g(g.cos_h, g.cos_i, g.cos_o, g.cos_d)
            fres = normalised_fresnel(g.cos_d, eta)
            spec = fres * abc_ndf(g.h, b, c) * gg / (4.0 * g.cos_i * g.cos_o)
        else:
            fres = normalised_fresnel(projected_cos_d(g.wi, g.wo), eta)
            spec = fres * smooth_lobe(g.wi, g.wo, b, c)
        return _terms.lambert(params["kd"]) + params["ks"][None, :] * spec[:, None]
