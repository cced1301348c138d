"""Burley 2012, "Physically-Based Shading at Disney" (SIGGRAPH course notes), exactly as the
BRDF Explorer reference shader ``src/brdfs/disney.brdf`` (wdas/brdf; seed 003):

    f = ((1/pi) mix(Fd, ss, subsurface) C + F_H sheen C_sheen) (1 - metallic)
        + G_s F_s D_s + clearcoat / 4 G_r F_r D_r

* ``C`` = ``base_color``, LINEAR RGB: mon2lin (x^2.2) of the shader's slider is skipped (shader
  value = base_color^(1/2.2)); ``C_lum = .3 C_r + .6 C_g + .1 C_b``, ``C_tint = C / C_lum``
  (1 if C_lum = 0), ``C_spec0 = mix(.08 specular mix(1, C_tint, specular_tint), C, metallic)``,
  ``C_sheen = mix(1, C_tint, sheen_tint)``; ``F_L, F_V, F_H = (1 - cos)^5`` of cos_i, cos_o, cos_d.
* Diffuse ``Fd = mix(1, Fd90, F_L) mix(1, Fd90, F_V)``, ``Fd90 = .5 + 2 cos_d^2 roughness``;
  Hanrahan-Krueger ``ss = 1.25 (Fss (1/(cos_i + cos_o) - .5) + .5)``, Fss: Fd90 -> cos_d^2 r.
* Specular: ``D_s`` = GTR2 (GGX), ``a_x = max(.001, roughness^2 / aspect)``, ``a_y = max(.001,
  roughness^2 aspect)``, ``aspect = sqrt(1 - .9 anisotropic)``; ``F_s = mix(C_spec0, 1, F_H)``;
  ``G_s = prod_v 1 / (v_z + sqrt((v_x a_x)^2 + (v_y a_y)^2 + v_z^2))``, v = wi, wo: Smith GGX
  ``G1 / (2 cos)`` with the same a_x, a_y (no (.5 + r/2)^2 remap, as in the shader).
* Clear coat: ``D_r`` = GTR1, ``alpha = mix(.1, .001, clearcoat_gloss)``, ``F_r = mix(.04, 1,
  F_H)``, ``G_r = smithG_GGX(cos_i, .25) smithG_GGX(cos_o, .25)``.

Static options ``subsurface``, ``sheen``, ``clearcoat``, ``anisotropic``, ``metallic``,
``specular_tint`` (all True: the full model) remove a feature, its parameters and operations;
the result equals the full model with that parameter at 0. Jointly affine (``linear``):
``specular``, ``sheen``, ``clearcoat``, and ``base_color`` unless a tint divides it by C_lum.
Not identifiable with metallic and specular_tint on: F0 = A + B C per channel, so base_color,
metallic, specular, specular_tint fix only C (1 - metallic), A, B (freeze one, e.g. the tint).

Guards: GTR1's ``(a^2 - 1) / log(a^2)`` is 0/0 at alpha = 1 (limit 1/pi): ``u / log1p(u)``,
``u = a^2 - 1``, series ``1 + u/2 - u^2/12`` for ``|u| < 1e-4``. GTR1/GTR2 use ``t = a^2 +
(1 - a^2) sin^2(theta_h)``, ``sin^2 = h_x^2 + h_y^2``, not ``1 + (a^2 - 1) cos_h^2`` (float32
cos_h has 6e-8 absolute error: 25% in D at the peak for a = .001). ``C_lum = 0``: double
where. ``1/(cos_i + cos_o)`` and G are finite: cosines > 0 above the horizon.

Reciprocal: every lobe is symmetric in (wi, wo) (F_L F_V, cos_i + cos_o, h, cos_d, separable
G). Not energy conserving: Fd90 <= 2.5 lifts the diffuse albedo above C at grazing angles
(Fd up to 6.25); sheen and clear coat are added on top without taking energy from the base.
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
from brdffit.models._terms import DIELECTRIC_F0, INV_PI, ggx_d

LUMINANCE = (0.3, 0.6, 0.1)
"""Disney 2012's luminance weights of the tint ``C_tint = C / C_lum``."""


def _unit(
    name: str, default: float, doc: str, linear: bool = False, neutral: float | None = None
) -> Parameter:
    return Parameter(name, (), (0.0, 1.0), default, "logit", doc, linear=linear, neutral=neutral)


BASE_COLOR = Parameter("base_color", (3,), (0.0, 1.0), 0.5, "logit", "base colour, linear RGB")
METALLIC = _unit("metallic", 0.1, "metallic blend, 0 dielectric .. 1 metal, unitless")
SUBSURFACE = _unit("subsurface", 0.1, "blend Burley diffuse -> Hanrahan-Krueger, unitless")
SPECULAR = _unit(
    "specular", 0.5, "dielectric specular, F0 = .08 specular, unitless", True,
    neutral=DIELECTRIC_F0 / 0.08,  # 0.5, the paper's default: F0 = 0.04
)  # fmt: skip
ROUGHNESS = Parameter(
    "roughness",
    (),
    (0.0, 1.0),
    0.5,
    "logit",
    "perceptual roughness, GGX alpha = roughness^2",
    solver="log",
)  # a width: alpha = roughness^2 spans decades near the mirror (fitted in ln roughness)
SPECULAR_TINT = _unit("specular_tint", 0.1, "tint of the dielectric F0 toward C_tint")
ANISOTROPIC = _unit("anisotropic", 0.1, "anisotropy, aspect = sqrt(1 - .9 anisotropic)")
SHEEN = _unit("sheen", 0.1, "sheen strength (grazing F_H lobe), unitless", True)
SHEEN_TINT = _unit("sheen_tint", 0.5, "tint of the sheen toward C_tint, unitless", neutral=0.0)
CLEARCOAT = _unit("clearcoat", 0.1, "clear-coat strength (lobe scaled by 1/4), unitless", True)
CLEARCOAT_GLOSS = _unit("clearcoat_gloss", 0.9, "clear-coat gloss, alpha = mix(.1, .001, .)")


def mix_product(f90_minus_1: jax.Array, f_l: jax.Array, f_v: jax.Array) -> jax.Array:
    """``mix(1, F90, F_L) mix(1, F90, F_V)`` from ``F90 - 1``: the Fd and Fss factors."""
    return (1.0 + f90_minus_1 * f_l) * (1.0 + f90_minus_1 * f_v)


def gtr2(sin2_h: jax.Array, a2: jax.Array) -> jax.Array:
    """Isotropic GTR2 (GGX) ``a^2 / (pi t^2)``, ``t = a^2 + (1 - a^2) sin^2(theta_h)`` (1/sr)."""
    t = a2 + (1.0 - a2) * sin2_h
    return a2 / (jnp.pi * t * t)


def smith_g_ggx(cos: jax.Array, a2: jax.Array | float) -> jax.Array:
    """Shader ``smithG_GGX``: ``1 / (cos + sqrt(a^2 + (1 - a^2) cos^2))`` = G1 / (2 cos)."""
    return 1.0 / (cos + jnp.sqrt(a2 + (1.0 - a2) * cos * cos))


def smith_gg(cos_i: jax.Array, cos_o: jax.Array, a2: jax.Array) -> jax.Array:
    """``smithG_GGX(cos_i) smithG_GGX(cos_o)`` with one division: G / (4 cos_i cos_o)."""
    b = 1.0 - a2
    return 1.0 / ((cos_i + jnp.sqrt(a2 + b * cos_i**2)) * (cos_o + jnp.sqrt(a2 + b * cos_o**2)))


def smith_g_ggx_aniso(v: jax.Array, ax: jax.Array, ay: jax.Array) -> jax.Array:
    """Shader ``smithG_GGX_aniso``: ``1 / (v_z + sqrt((v_x a_x)^2 + (v_y a_y)^2 + v_z^2))``."""
    return 1.0 / (v[:, 2] + jnp.sqrt((v[:, 0] * ax) ** 2 + (v[:, 1] * ay) ** 2 + v[:, 2] ** 2))


@final
class Disney(AbstractModel):
    """Disney "principled" BRDF of 2012 with optional lobes and mixes chosen statically."""

    subsurface: bool = eqx.field(static=True, default=True)
    sheen: bool = eqx.field(static=True, default=True)
    clearcoat: bool = eqx.field(static=True, default=True)
    anisotropic: bool = eqx.field(static=True, default=True)
    metallic: bool = eqx.field(static=True, default=True)
    specular_tint: bool = eqx.field(static=True, default=True)

    name: ClassVar[str] = "disney"
    reference: ClassVar[str] = "Burley 2012, Physically-Based Shading at Disney, SIGGRAPH course"
    energy_conserving: ClassVar[bool] = False

    @property
    def channel_separable(self) -> bool:  # type: ignore[override]
        """False while ``sheen`` or ``specular_tint`` is on: their tint ``C / C_lum``
        divides by the luminance of ``base_color``, so every channel depends on all three
        (:attr:`AbstractModel.channel_separable`)."""
        return not (self.sheen or self.specular_tint)

    def __check_init__(self) -> None:
        for k, v in self.options().items():
            if not isinstance(v, bool):
                raise ValueError(f"disney: option {k}={v!r} is not a bool")

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        base = dataclasses.replace(BASE_COLOR, linear=not (self.specular_tint or self.sheen))
        table = [base, METALLIC] if self.metallic else [base]
        table += [SUBSURFACE] if self.subsurface else []
        table += [SPECULAR, ROUGHNESS] + ([SPECULAR_TINT] if self.specular_tint else [])
        table += [ANISOTROPIC] if self.anisotropic else []
        table += [SHEEN, SHEEN_TINT] if self.sheen else []
        table += [CLEARCOAT, CLEARCOAT_GLOSS] if self.clearcoat else []
        return tuple(table)

    def specular_dg(self, params: Params, g: ShadingGeometry, sin2_h: jax.Array) -> jax.Array:
        """``D_s G_s`` of the main lobe (1/sr, the 1/(4 cos_i cos_o) included), (N,)."""
        r2 = params["roughness"] ** 2
        if self.anisotropic:
            aspect = jnp.sqrt(1.0 - 0.9 * params["anisotropic"])
            ax, ay = jnp.maximum(0.001, r2 / aspect), jnp.maximum(0.001, r2 * aspect)
            d = ggx_d(g.h, ax, ay)  # = the shader's GTR2_aniso
            return d * smith_g_ggx_aniso(g.wi, ax, ay) * smith_g_ggx_aniso(g.wo, ax, ay)
        a2 = jnp.maximum(0.001, r2) ** 2
        return gtr2(sin2_h, a2) * smith_gg(g.cos_i, g.cos_o, a2)

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        c = params["base_color"]
        f_l, f_v, f_h = (
            _terms.schlick_weight(g.cos_i),
            _terms.schlick_weight(g.cos_o),
            _terms.schlick_weight(g.cos_d),
        )
        fss90 = params["roughness"] * g.cos_d**2
        fd = mix_product(2.0 * fss90 - 0.5, f_l, f_v)  # Fd90 - 1 = 2 cos_d^2 r - .5
        if self.subsurface:
            ss = _terms.hanrahan_krueger(mix_product(fss90 - 1.0, f_l, f_v), g.cos_i + g.cos_o)
            fd = fd + params["subsurface"] * (ss - fd)
        out = c[None, :] * (INV_PI * fd)[:, None]
        tint = _terms.luminance_tint(c, LUMINANCE) if (self.sheen or self.specular_tint) else None
        if self.sheen:  # C_sheen = mix(1, C_tint, sheen_tint)
            c_sheen = 1.0 + params["sheen_tint"] * (tint - 1.0)
            out = out + (params["sheen"] * f_h)[:, None] * c_sheen[None, :]
        if self.metallic:
            out = out * (1.0 - params["metallic"])
        spec0 = 0.08 * params["specular"]
        if self.specular_tint:
            spec0 = spec0 * (1.0 + params["specular_tint"] * (tint - 1.0))
        if self.metallic:
            spec0 = spec0 + params["metallic"] * (c - spec0)
        sin2_h = g.h[:, 0] ** 2 + g.h[:, 1] ** 2  # from h_x, h_y: exact near the peak
        dg = self.specular_dg(params, g, sin2_h)  # D_s G_s
        if spec0.ndim == 0:  # grey F0: one Fresnel channel instead of three
            out = out + ((spec0 + (1.0 - spec0) * f_h) * dg)[:, None]
        else:
            out = out + (spec0[None, :] + (1.0 - spec0)[None, :] * f_h[:, None]) * dg[:, None]
        if self.clearcoat:
            alpha = 0.1 + params["clearcoat_gloss"] * (0.001 - 0.1)
            g_r = smith_g_ggx(g.cos_i, 0.0625) * smith_g_ggx(g.cos_o, 0.0625)  # alpha_g .25
            lobe = _terms.gtr1(sin2_h, alpha) * g_r * (0.04 + 0.96 * f_h)
            out = out + (0.25 * params["clearcoat"] * lobe)[:, None]
        return out
