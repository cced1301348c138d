"""Filament's lit shading models (Google, "Physically Based Rendering in Filament",
google.github.io/filament/Filament.html, and its shaders ``brdf.fs``,
``shading_model_standard.fs``, ``shading_model_cloth.fs``, ``common_lighting.fs``).

``shading="standard"``, with ``alpha = roughness^2`` (``roughness`` is perceptual):

    f = (1 - Fc) [c_diff Fd + D V F + sheen] + clear coat
    c_diff = base_color (1 - metallic)
    f0 = 0.16 reflectance^2 (1 - metallic) + base_color metallic
    F = f0 + (1 - f0)(1 - LoH)^5  (Schlick, f90 = 1)
    D = alpha^2 / (pi ((NoH alpha)^2 + 1 - NoH^2)^2)                        (GGX)
    V = 0.5 / (NoL sqrt(NoV^2 (1 - a2) + a2) + NoV sqrt(NoL^2 (1 - a2) + a2)),  a2 = alpha^2
    Fd = 1/pi (lambert) or (1 + (f90 - 1)(1 - NoL)^5)(1 + (f90 - 1)(1 - NoV)^5) / pi,
         f90 = 0.5 + 2 alpha LoH^2 (burley, with alpha as Filament passes it)

* ``anisotropy``: ``at = max(alpha (1 + anisotropy), 0.002025)``, ``ab = max(alpha (1 -
  anisotropy), 0.002025)`` (Filament's desktop ``MIN_ROUGHNESS``), anisotropic GGX and
  ``V = 0.5 / (NoL |(at ToV, ab BoV, NoV)| + NoV |(at ToL, ab BoL, NoL)|)``; t = x, b = y.
* ``clearcoat``: ``Fc = clear_coat F_schlick(0.04, LoH)`` (IOR 1.5), lobe
  ``D_GGX(clear_coat_roughness^2) 0.25 / LoH^2 Fc`` (Kelemen), base scaled by ``1 - Fc``.
  As Filament does by default, the base ``f0`` becomes ``mix(f0, f0_under_coat(f0),
  clear_coat)`` (its cubic fit of the IOR change, clamped to [0, 1]) and the base
  perceptual roughness ``mix(r, max(r, clear_coat_roughness), clear_coat)``.
* ``sheen``: ``sheen_color D_charlie V_neubelt`` with ``D_charlie = (2 + 1/a) (sin^2
  theta_h)^(1/(2a)) / (2 pi)``, ``a = sheen_roughness^2``, ``V_neubelt = 1 / (4 (NoL + NoV -
  NoL NoV))``. Filament's energy scaling of the base, ``1 - max(sheen_color) DFG_z(NoV)``,
  needs its precomputed DFG table and is left out (scaling 1).
* ``shading="cloth"``: ``f = base_color Fd + sheen_color D_charlie(alpha) V_neubelt``, no
  Fresnel; with ``subsurface`` Filament's wrap diffuse ``Fd (NoL + 0.5) / 2.25 sat(
  subsurface_color + NoL) / NoL`` (its lighting omits ``NoL`` there, divided out here).

Left out: Filament's multiple-scattering energy compensation (needs the DFG table, i.e.
factor 1), its high-quality ``f90 = sat(16.5 sum f0)`` specular occlusion (f90 = 1, as its
low-quality path and Filament.md), the ``NoV >= 1e-4`` clamp (cosines are > 0 here, and
the clamp would break reciprocity). Filament's other clamps (perceptual roughness >= 0.045,
``sin^2 theta_h >= 2^-7`` in Charlie) are kept: the first as parameter bounds, the second
because it also keeps the derivative of ``sin^(1/a)`` finite at ``theta_h = 0``.
``LoH`` is floored at 1e-12 in Kelemen's ``1/LoH^2``. Reciprocal except cloth with
subsurface; not energy conserving (``f0`` up to 1 and the diffuse are added uncoupled).
"""

from __future__ import annotations

import math
from typing import ClassVar, Literal, final

import equinox as eqx
import jax
import jax.numpy as jnp

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models import _terms

MIN_ROUGHNESS = 0.002025  # Filament's desktop MIN_ROUGHNESS = MIN_PERCEPTUAL_ROUGHNESS^2


def _rough(name: str, default: float, doc: str) -> Parameter:
    return Parameter(name, (), (0.045, 1.0), default, "log", doc)


def _color(name: str, default: float, doc: str, linear: bool = True) -> Parameter:
    return Parameter(name, (3,), (0.0, 1.0), default, "logit", doc, linear=linear)


def _unit(
    name: str, default: float, doc: str, low: float = 0.0, neutral: float | None = None
) -> Parameter:
    return Parameter(name, (), (low, 1.0), default, "logit", doc, neutral=neutral)


ROUGHNESS = _rough("roughness", 0.5, "perceptual roughness, alpha = roughness^2")
METALLIC = _unit("metallic", 0.5, "metallic (0 dielectric, 1 conductor), unitless", neutral=0.0)
REFLECTANCE = _unit(
    "reflectance", 0.5, "dielectric reflectance, f0 = 0.16 reflectance^2",
    neutral=math.sqrt(_terms.DIELECTRIC_F0 / 0.16),  # 0.5, Filament's default: f0 = 0.04
)  # fmt: skip
ANISOTROPY = _unit("anisotropy", 0.0, "anisotropy, > 0 stretches along x, unitless", -1.0)
CLEAR_COAT = _unit("clear_coat", 0.5, "clear coat strength, unitless")
CLEAR_COAT_ROUGHNESS = _rough("clear_coat_roughness", 0.2, "clear coat perceptual roughness")
SHEEN_COLOR = _color("sheen_color", 0.2, "sheen (cloth specular) color, RGB")
SHEEN_ROUGHNESS = _rough("sheen_roughness", 0.5, "sheen perceptual roughness")
SUBSURFACE_COLOR = _color("subsurface_color", 0.2, "cloth subsurface color, RGB", linear=False)


SHEEN_FLOOR = 0.0078125
"""Filament's floor ``sin^2 theta_h >= 2^-7`` in its Charlie ``D`` (``brdf.fs``)."""


def charlie_d(h: jax.Array, a: jax.Array) -> jax.Array:
    """Charlie sheen NDF (:func:`~brdffit.models._terms.charlie_d`) with Filament's floor."""
    return _terms.charlie_d(h, a, SHEEN_FLOOR)


def smith_ggx_v(wi: jax.Array, wo: jax.Array, at: jax.Array, ab: jax.Array) -> jax.Array:
    """Height-correlated Smith-GGX visibility ``G2 / (4 NoL NoV)`` (Heitz 2014), (N,)."""
    lam_v = wi[:, 2] * jnp.sqrt((at * wo[:, 0]) ** 2 + (ab * wo[:, 1]) ** 2 + wo[:, 2] ** 2)
    lam_l = wo[:, 2] * jnp.sqrt((at * wi[:, 0]) ** 2 + (ab * wi[:, 1]) ** 2 + wi[:, 2] ** 2)
    return 0.5 / (lam_v + lam_l)


def burley_fd(alpha: jax.Array, g: ShadingGeometry) -> jax.Array:
    """Filament's ``Fd_Burley(alpha, NoV, NoL, LoH)`` (1/sr), (N,)."""
    f90 = 0.5 + 2.0 * alpha * g.cos_d**2
    return (
        (1.0 + (f90 - 1.0) * (1.0 - g.cos_i) ** 5)
        * (1.0 + (f90 - 1.0) * (1.0 - g.cos_o) ** 5)
        * _terms.INV_PI
    )


def f0_under_coat(f0: jax.Array) -> jax.Array:
    """Filament's ``f0ClearCoatToSurface``: f0 of the base seen through an IOR 1.5 coat."""
    return jnp.clip(f0 * (f0 * (0.941892 - 0.263008 * f0) + 0.346479) - 0.0285998, 0.0, 1.0)


@final
class Filament(AbstractModel):
    """Filament's standard (optional clear coat, anisotropy, sheen) or cloth model."""

    shading: Literal["standard", "cloth"] = eqx.field(static=True, default="standard")
    diffuse: Literal["lambert", "burley"] = eqx.field(static=True, default="lambert")
    clearcoat: bool = eqx.field(static=True, default=False)
    anisotropy: bool = eqx.field(static=True, default=False)
    sheen: bool = eqx.field(static=True, default=False)
    subsurface: bool = eqx.field(static=True, default=False)

    name: ClassVar[str] = "filament"
    reference: ClassVar[str] = "Google Filament, Physically Based Rendering in Filament (2018-)"
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    def __check_init__(self) -> None:
        if self.shading not in ("standard", "cloth"):
            raise ValueError(f"filament: shading {self.shading!r} not 'standard' or 'cloth'")
        if self.diffuse not in ("lambert", "burley"):
            raise ValueError(f"filament: diffuse {self.diffuse!r} not 'lambert' or 'burley'")
        if self.shading == "cloth" and (self.clearcoat or self.anisotropy or self.sheen):
            raise ValueError("filament: clearcoat, anisotropy, sheen need shading='standard'")
        if self.shading == "standard" and self.subsurface:
            raise ValueError("filament: subsurface needs shading='cloth'")

    @property
    def reciprocal(self) -> bool:  # type: ignore[override]
        return not self.subsurface

    @property
    def isotropic(self) -> bool:  # type: ignore[override]
        return not self.anisotropy

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        if self.shading == "cloth":
            extra = (SUBSURFACE_COLOR,) if self.subsurface else ()
            return (_color("base_color", 0.5, "diffuse color, RGB"), SHEEN_COLOR, ROUGHNESS) + extra
        base = _color("base_color", 0.5, "base color, RGB", linear=not self.clearcoat)
        out = (base, METALLIC, REFLECTANCE, ROUGHNESS)
        out += (ANISOTROPY,) if self.anisotropy else ()
        out += (CLEAR_COAT, CLEAR_COAT_ROUGHNESS) if self.clearcoat else ()
        return out + ((SHEEN_COLOR, SHEEN_ROUGHNESS) if self.sheen else ())

    def fd(self, alpha: jax.Array, g: ShadingGeometry) -> jax.Array:
        """Diffuse lobe per unit color (1/sr), (N,)."""
        if self.diffuse == "burley":
            return burley_fd(alpha, g)
        return jnp.full_like(g.cos_i, _terms.INV_PI)

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        pr = params["roughness"]
        if self.shading == "cloth":
            fd = self.fd(pr**2, g)
            if self.subsurface:
                wrap = (g.cos_i + 0.5) / 2.25
                ss = jnp.clip(params["subsurface_color"][None, :] + g.cos_i[:, None], 0.0, 1.0)
                diffuse = params["base_color"][None, :] * ss * (fd * wrap / g.cos_i)[:, None]
            else:
                diffuse = params["base_color"][None, :] * fd[:, None]
            lobe = charlie_d(g.h, pr**2) * _terms.neubelt_v(g.cos_i, g.cos_o)
            return diffuse + params["sheen_color"][None, :] * lobe[:, None]
        m, bc = params["metallic"], params["base_color"]
        f0 = 0.16 * params["reflectance"] ** 2 * (1.0 - m) + bc * m
        if self.clearcoat:
            cc, ccr = params["clear_coat"], params["clear_coat_roughness"]
            pr = pr + cc * jnp.maximum(ccr - pr, 0.0)
            f0 = f0 + cc * (f0_under_coat(f0) - f0)
        alpha = pr**2
        at, ab = alpha, alpha
        if self.anisotropy:
            at = jnp.maximum(alpha * (1.0 + params["anisotropy"]), MIN_ROUGHNESS)
            ab = jnp.maximum(alpha * (1.0 - params["anisotropy"]), MIN_ROUGHNESS)
        dv = _terms.ggx_d(g.h, at, ab) * smith_ggx_v(g.wi, g.wo, at, ab)
        color = (bc * (1.0 - m))[None, :] * self.fd(alpha, g)[:, None]
        color = color + _terms.schlick_fresnel(f0, g.cos_d) * dv[:, None]
        if self.sheen:
            lobe = charlie_d(g.h, params["sheen_roughness"] ** 2) * _terms.neubelt_v(
                g.cos_i, g.cos_o
            )
            color = color + params["sheen_color"][None, :] * lobe[:, None]
        if self.clearcoat:
            fc = cc * (0.04 + 0.96 * (1.0 - g.cos_d) ** 5)
            kelemen = 0.25 / jnp.maximum(g.cos_d, 1e-12) ** 2
            coat = _terms.ggx_d(g.h, ccr**2, ccr**2) * kelemen * fc
            color = color * (1.0 - fc)[:, None] + coat[:, None]
        return color
