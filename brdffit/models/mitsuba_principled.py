"""Mitsuba 3's ``principled`` BSDF, reflection only (``spec_trans = 0``), as a model to fit:
a fit of it is exported to Mitsuba by copying its parameters (exact by construction).

Follows Mitsuba 3's ``src/bsdfs/principled.cpp`` and ``principledhelpers.h`` (commit
b45b0a9, 2026), itself after Burley 2012/2015 (Disney's principled BRDF); checked value by
value against Mitsuba's own ``BSDF.eval`` in ``tests/models/test_mitsuba_principled.py``.
Mitsuba's ``si.wi`` is brdffit's ``wo``; ``cos_d = wi.h = wo.h``, ``w(x) = (1 - x)^5``:

    f = F D G / (4 cos_i cos_o)
        + (1 - metallic) (base_color / pi lerp(f_diff + f_retro, f_ss, flatness)
                          + sheen w(cos_d) C_sheen)
        + 0.25 clearcoat (0.04 + 0.96 w(cos_d)) D_cc G1_cc(wi) G1_cc(wo)

* Specular: ``D`` GGX (:func:`~brdffit.models._terms.ggx_d`), ``G`` separable Smith GGX, with
  ``alpha_x = max(.001, roughness^2 / aspect)``, ``alpha_y = max(.001, roughness^2 aspect)``,
  ``aspect = sqrt(1 - .9 anisotropic)`` (``alpha = max(.001, roughness^2)`` without the
  ``anisotropic`` option). ``F = (1 - metallic) ((1 - spec_tint) F_d + spec_tint
  Schlick(.08 specular C_tint)) + metallic Schlick(base_color)`` per channel, ``F_d`` the exact
  dielectric Fresnel of ``eta = 2 / (1 - sqrt(.08 specular)) - 1`` (so that ``((eta - 1) /
  (eta + 1))^2 = .08 specular``), Schlick ``F0 + (1 - F0) w(cos_d)``.
* ``C_tint = base_color / lum``, ``lum`` the Rec. 709 luminance (.212671, .715160, .072169)
  (1 where ``lum = 0``); ``C_sheen = lerp(1, C_tint, sheen_tint)`` (1 without ``sheen_tint``).
* Diffuse: ``f_diff = (1 - w_i / 2)(1 - w_o / 2)``, ``f_retro = R (w_i + w_o + w_i w_o (R - 1))``,
  ``R = 2 roughness cos_d^2``, ``w_i, w_o = w(cos_i), w(cos_o)`` (Disney 2012's diffuse,
  rewritten); ``f_ss = 1.25 (F_ss (1 / (cos_i + cos_o) - .5) + .5)``, ``F_ss = (1 + (R/2 - 1)
  w_i)(1 + (R/2 - 1) w_o)`` (Hanrahan-Krueger).
* Clear coat: ``D_cc`` GTR1 ``(a^2 - 1) / (pi ln(a^2) (a^2 cos_h^2 + sin_h^2))``, ``a =
  lerp(.1, .001, clearcoat_gloss)``; ``G1_cc`` Smith GGX of alpha .25; no ``1 / (4 cos_i
  cos_o)`` (as Mitsuba 3 writes it; Disney 2012 has it).

Static options (Mitsuba's own switches, on when the property is given and not 0):
``metallic`` (default on), ``spec_tint``, ``anisotropic``, ``sheen``, ``sheen_tint`` (needs
``sheen``), ``flatness``, ``clearcoat`` (with ``clearcoat_gloss``). A feature that is off is
Mitsuba's plugin without that property: the value 0. Parameters carry Mitsuba's names and
ranges. Jointly affine (``linear``): ``sheen``, ``clearcoat``, and ``base_color`` unless a tint
divides it by ``lum``. ``specular``'s neutral value is Mitsuba's default .5 (F0 = .04).

Where Mitsuba does something a fit would not want, the model follows it and says so:
``specular = 0`` gives ``eta = 1`` and Mitsuba drops the whole specular lobe (its mask
``F_dielectric > 0``), metallic part included: a jump at the bound, kept (``specular`` is
replaced before the square root there, so the gradient stays finite). Mitsuba zeroes ``D``
where ``D cos_h <= 1e-20``; the model does not (an absolute difference below 1e-20 1/sr).
The roughness floor ``max(.001, .)`` is flat below ``roughness = .032`` (.001^.5 / aspect).

Guards: GTR1 is written with ``sin_h^2 = h_x^2 + h_y^2`` (``a`` <= .1, never the 0/0 at
``a = 1``); cosines are > 0 above the horizon, so ``1 / (4 cos_i cos_o)`` (cancelled by
``G`` to first order) and ``1 / (cos_i + cos_o)`` are finite. Reciprocal (every term is
symmetric in wi, wo). Not energy conserving (``f_retro`` lifts the diffuse albedo above
``base_color`` at grazing angles; sheen and clear coat are added on top).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar, final

import equinox as eqx
import jax
import jax.numpy as jnp

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models import _terms
from brdffit.models._terms import (
    INV_PI,
    fresnel_dielectric,
    ggx_d,
    ggx_lambda,
    schlick_fresnel,
    smith_g,
)

REC709 = (0.212671, 0.715160, 0.072169)
"""Mitsuba's ``luminance`` weights of linear RGB (Rec. 709 primaries)."""
CLEARCOAT_ALPHA = 0.25
"""The GGX alpha of the clear coat's Smith masking (Mitsuba's ``clearcoat_G``)."""


def _unit(
    name: str, default: float, doc: str, linear: bool = False, neutral: float | None = None
) -> Parameter:
    return Parameter(name, (), (0.0, 1.0), default, "logit", doc, linear=linear, neutral=neutral)


BASE_COLOR = Parameter("base_color", (3,), (0.0, 1.0), 0.5, "logit", "base colour, linear RGB")
METALLIC = _unit("metallic", 0.1, "metallic blend, 0 dielectric .. 1 metal, unitless")
ROUGHNESS = Parameter(
    "roughness",
    (),
    (0.0, 1.0),
    0.5,
    "logit",
    "roughness, GGX alpha = max(.001, roughness^2)",
    solver="log",
)  # a width: alpha = roughness^2 spans decades near the mirror (fitted in ln roughness)
SPECULAR = Parameter(
    "specular", (), (1e-3, 1.0), 0.5, "logit",
    "dielectric F0 = .08 specular, eta = 2 / (1 - sqrt(F0)) - 1", neutral=0.5,
)  # fmt: skip
"""Default: Mitsuba's (F0 = 0.04, eta = 1.5). Lower bound 1e-3, not 0: at exactly 0
Mitsuba drops the whole specular lobe, metal part included, so a fit that ran to 1e-40
(a dark dielectric) was written as 0 and lost its metal lobe (RGL ilm_solo_m_68: export
error 0.9999); at 1e-3 the dielectric F0 is 8e-5, below any measurement."""
SPEC_TINT = _unit("spec_tint", 0.1, "tint of the dielectric lobe toward C_tint, unitless")
ANISOTROPIC = _unit("anisotropic", 0.1, "anisotropy, aspect = sqrt(1 - .9 anisotropic)")
SHEEN = _unit("sheen", 0.1, "sheen strength (grazing w(cos_d) lobe), unitless", linear=True)
SHEEN_TINT = _unit("sheen_tint", 0.5, "tint of the sheen toward C_tint, unitless")
FLATNESS = _unit("flatness", 0.1, "blend diffuse -> Hanrahan-Krueger f_ss, unitless")
CLEARCOAT = _unit("clearcoat", 0.1, "clear-coat strength (lobe scaled by 1/4)", linear=True)
CLEARCOAT_GLOSS = _unit("clearcoat_gloss", 0.5, "clear-coat gloss, alpha = lerp(.1, .001, .)")


def principled_diffuse(
    g: ShadingGeometry, roughness: jax.Array, flatness: jax.Array | None
) -> jax.Array:
    """``lerp(f_diff + f_retro, f_ss, flatness)`` (unitless, (N,)); no ``f_ss`` when ``None``."""
    w_i, w_o = _terms.schlick_weight(g.cos_i), _terms.schlick_weight(g.cos_o)
    rr = 2.0 * roughness * g.cos_d**2
    lobe = (1.0 - 0.5 * w_i) * (1.0 - 0.5 * w_o) + rr * (w_i + w_o + w_i * w_o * (rr - 1.0))
    if flatness is None:
        return lobe
    fss = (1.0 + (0.5 * rr - 1.0) * w_i) * (1.0 + (0.5 * rr - 1.0) * w_o)
    f_ss = _terms.hanrahan_krueger(fss, g.cos_i + g.cos_o)
    return lobe + flatness * (f_ss - lobe)


@final
class MitsubaPrincipled(AbstractModel):
    """Mitsuba 3's ``principled`` BSDF without transmission, features chosen statically."""

    metallic: bool = eqx.field(static=True, default=True)
    spec_tint: bool = eqx.field(static=True, default=False)
    anisotropic: bool = eqx.field(static=True, default=False)
    sheen: bool = eqx.field(static=True, default=False)
    sheen_tint: bool = eqx.field(static=True, default=False)
    flatness: bool = eqx.field(static=True, default=False)
    clearcoat: bool = eqx.field(static=True, default=False)

    name: ClassVar[str] = "principled"
    reference: ClassVar[str] = (
        "Mitsuba 3 principled BSDF (principled.cpp), after Burley 2012 and 2015"
    )
    energy_conserving: ClassVar[bool] = False

    @property
    def channel_separable(self) -> bool:  # type: ignore[override]
        """False while ``spec_tint`` or ``sheen_tint`` is on: ``C_tint = base_color / lum``
        divides by the luminance of ``base_color`` (:attr:`AbstractModel.channel_separable`)."""
        return not (self.spec_tint or self.sheen_tint)

    def __check_init__(self) -> None:
        for k, v in self.options().items():
            if not isinstance(v, bool):
                raise ValueError(f"principled: option {k}={v!r} is not a bool")
        if self.sheen_tint and not self.sheen:
            raise ValueError("principled: option sheen_tint=True needs sheen=True")

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        tinted = self.spec_tint or self.sheen_tint
        table = [dataclasses.replace(BASE_COLOR, linear=not tinted)]
        table += [METALLIC] if self.metallic else []
        table += [ROUGHNESS, SPECULAR] + ([SPEC_TINT] if self.spec_tint else [])
        table += [ANISOTROPIC] if self.anisotropic else []
        if self.sheen:
            table += [SHEEN, SHEEN_TINT] if self.sheen_tint else [SHEEN]
        table += [FLATNESS] if self.flatness else []
        table += [CLEARCOAT, CLEARCOAT_GLOSS] if self.clearcoat else []
        return tuple(table)

    def alphas(self, params: Params) -> tuple[jax.Array, jax.Array]:
        """GGX ``(alpha_x, alpha_y)`` of the specular lobe (Mitsuba's ``calc_dist_params``)."""
        r2 = params["roughness"] ** 2
        if not self.anisotropic:
            a = jnp.maximum(0.001, r2)
            return a, a
        aspect = jnp.sqrt(1.0 - 0.9 * params["anisotropic"])
        return jnp.maximum(0.001, r2 / aspect), jnp.maximum(0.001, r2 * aspect)

    def fresnel(
        self,
        params: Params,
        g: ShadingGeometry,
        eta: jax.Array,
        f0: jax.Array,
        tint: jax.Array | None,
    ) -> jax.Array:
        """Mitsuba's ``principled_fresnel`` on the front side, (N, 1) or (N, 3).

        ``eta`` and ``f0 = ((eta - 1) / (eta + 1))^2 = .08 specular`` of the dielectric part.
        """
        f = fresnel_dielectric(g.cos_d, eta)[:, None]
        if self.spec_tint:
            st = params["spec_tint"]
            f = (1.0 - st) * f + st * schlick_fresnel(f0 * tint, g.cos_d)
        if self.metallic:
            m = params["metallic"]
            f = (1.0 - m) * f + m * schlick_fresnel(params["base_color"], g.cos_d)
        return f

    def specular_lobe(
        self, params: Params, g: ShadingGeometry, tint: jax.Array | None
    ) -> jax.Array:
        """``F D G / (4 cos_i cos_o)`` (1/sr), (N, 1) or (N, 3); 0 at ``specular = 0``."""
        on = params["specular"] > 0  # Mitsuba's mask F_dielectric > 0: eta = 1 only there
        f0 = 0.08 * jnp.where(on, params["specular"], 0.5)
        q = jnp.sqrt(f0)
        eta = (1.0 + q) / (1.0 - q)  # = 2 / (1 - sqrt(.08 specular)) - 1
        ax, ay = self.alphas(params)
        dg = ggx_d(g.h, ax, ay) * smith_g(
            ggx_lambda(g.wi, ax, ay), ggx_lambda(g.wo, ax, ay), height_correlated=False
        )
        lobe = self.fresnel(params, g, eta, f0, tint) * (dg / (4.0 * g.cos_i * g.cos_o))[:, None]
        return jnp.where(on, lobe, 0.0)

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        c = params["base_color"]
        tint = _terms.luminance_tint(c, REC709) if (self.spec_tint or self.sheen_tint) else None
        flat = params["flatness"] if self.flatness else None
        body = c[None, :] * (INV_PI * principled_diffuse(g, params["roughness"], flat))[:, None]
        if self.sheen:
            w = (params["sheen"] * _terms.schlick_weight(g.cos_d))[:, None]
            if self.sheen_tint:  # C_sheen = lerp(1, C_tint, sheen_tint)
                w = w * (1.0 + params["sheen_tint"] * (tint - 1.0))[None, :]
            body = body + w
        if self.metallic:
            body = body * (1.0 - params["metallic"])
        out = body + self.specular_lobe(params, g, tint)
        if self.clearcoat:
            alpha = 0.1 + params["clearcoat_gloss"] * (0.001 - 0.1)
            a = jnp.asarray(CLEARCOAT_ALPHA, g.wi.dtype)
            g_cc = smith_g(ggx_lambda(g.wi, a, a), ggx_lambda(g.wo, a, a), height_correlated=False)
            sin2_h = g.h[:, 0] ** 2 + g.h[:, 1] ** 2
            coat = (
                _terms.gtr1(sin2_h, alpha) * g_cc * (0.04 + 0.96 * _terms.schlick_weight(g.cos_d))
            )
            out = out + (0.25 * params["clearcoat"] * coat)[:, None]
        return out
