"""The glTF 2.0 metallic-roughness material as a fittable model (Khronos, glTF 2.0
specification, Appendix B "BRDF Implementation", and the extensions
``KHR_materials_specular``, ``KHR_materials_ior``, ``KHR_materials_clearcoat``,
``KHR_materials_sheen``). Fitting it fits the renderer's own material: its glTF export
writes the parameters as they are (:mod:`brdffit.export.gltf`) and is exact by
construction. ``wi`` = L (light), ``wo`` = V (viewer), ``h`` the half vector:

    alpha = roughness^2                       (glTF's roughness is perceptual)
    DV    = D_GGX(alpha) G2 / (4 N.L N.V),  G2 = 1 / (1 + Lambda(L) + Lambda(V))
    w     = (1 - V.H)^5
    F_d   = specular (specular_f0 + (1 - specular_f0) w)     (KHR_materials_specular, _ior)
    dielectric = F_d DV + (1 - max_rgb F_d) base_color / pi
    metal      = (base_color + (1 - base_color) w) DV
    material   = (1 - metallic) dielectric + metallic metal
    + sheen:     material + sheen_color D_charlie V_ashikhmin
    + clearcoat: material (1 - Fc) + Fc DV(clearcoat_roughness^2),
                 Fc = clearcoat (0.04 + 0.96 (1 - N.V)^5)

* ``G2`` is the height-correlated Smith form of Appendix B (``V_GGX``), written with
  Lambda (:func:`~brdffit.models._terms.ggx_lambda`), free of cancellation at small alpha.
* ``specular_f0`` stands for ``min(((ior - 1)/(ior + 1))^2 specularColorFactor, 1)``: the
  data see only this product; the export writes it back as ``ior`` and
  ``specularColorFactor``. ``specular`` is ``specularFactor``. With ``specular=False``
  the core material's constants hold: ``specular = 1``, ``specular_f0 = 0.04`` (ior 1.5).
* Sheen: ``D_charlie = (2 + 1/a) sin(theta_h)^(1/a) / (2 pi)``, ``a =
  sheen_roughness^2`` (Estevez, Kulla 2017), integrating to 1 against ``cos theta_h``;
  ``V_ashikhmin = 1 / (4 (N.L + N.V - N.L N.V))``, the visibility the extension allows.
  The extension's albedo scaling of the base (``1 - max(sheen_color) E(N.V)``) needs
  Conty and Kulla's tabulated ``E`` and is left out (factor 1), exactly as
  :mod:`brdffit.export.gltf_brdf` evaluates the written material.
* Clear coat: the extension's ``fresnel_coat`` with IOR 1.5 at ``N.V``, the coat lobe
  ``DV`` without a Fresnel of its own, the coat normal the surface normal.

Bounds: ``roughness`` and ``clearcoat_roughness`` from 0.01 (alpha 1e-4, the floor of
``walter``'s alpha, so every GGX lobe it fits is reachable); the spec itself has none,
while real-time viewers clamp higher (Filament at 0.045), so a fit below that renders
sharper in a path tracer than in those viewers. ``sheen_roughness`` from 0.045, where
Filament clamps it (``MIN_PERCEPTUAL_ROUGHNESS``): ``1/a`` in ``D_charlie`` has no floor of
its own. Singularity guard: ``sin^2 theta_h = hx^2 + hy^2`` is floored at 1e-30
(:data:`~brdffit.models._terms.CHARLIE_FLOOR`), so ``d/d(sheen_roughness)`` (``log
sin^2``) never meets ``log 0`` at ``h`` = normal; the lobe gains below 1e-12 1/sr there,
where the spec's is 0 (Filament's floor, ``2^-7``, would change the BRDF the spec
defines).

Affine (linear least squares per start): ``base_color`` and ``sheen_color``, jointly:
``base_color`` enters ``(1 - metallic)(1 - max F_d) / pi + metallic (1 - w) DV`` times
itself, ``sheen_color`` a lobe of its own, and the coat scales both by ``1 - Fc``.
``metallic``, ``specular`` and ``clearcoat`` are each affine alone but multiply
``base_color``; ``specular_f0`` enters through ``max``.
Neutral values (:func:`brdffit.simplify`): ``metallic`` 0 (a dielectric), ``specular`` 1
and ``specular_f0`` 0.04 (glTF's defaults without the extensions). Clear coat and sheen
have none: their options remove them with their roughness, which a weight pinned at 0
would leave unidentifiable.
Not energy conserving (the diffuse is weighted by ``1 - max F`` at ``V.H``, not by the
specular albedo, and the sheen is added without albedo scaling). Reciprocal without the
clear coat; its ``Fc`` at ``N.V`` is not.
"""

from __future__ import annotations

from typing import ClassVar, final

import equinox as eqx
import jax
import jax.numpy as jnp

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models import _terms

COAT_F0 = 0.04
"""Normal-incidence reflectance of the clear coat, IOR 1.5 (KHR_materials_clearcoat)."""


def _unit(name: str, default: float, doc: str, neutral: float | None = None) -> Parameter:
    return Parameter(name, (), (0.0, 1.0), default, "logit", doc, neutral=neutral)


def _color(name: str, default: float, doc: str, **kw: object) -> Parameter:
    return Parameter(name, (3,), (0.0, 1.0), default, "logit", doc, **kw)  # type: ignore[arg-type]


def _rough(name: str, low: float, default: float, doc: str) -> Parameter:
    return Parameter(name, (), (low, 1.0), default, "log", doc)


BASE_COLOR = _color("base_color", 0.5, "baseColorFactor, RGB", linear=True)
METALLIC = _unit("metallic", 0.5, "metallicFactor (0 dielectric, 1 metal), unitless", 0.0)
ROUGHNESS = _rough("roughness", 0.01, 0.5, "roughnessFactor, perceptual: alpha = roughness^2")
# default 0.9 rather than glTF's 1: a start inside the box (the neutral value is 1)
SPECULAR = _unit("specular", 0.9, "specularFactor, weight of the dielectric specular", 1.0)
SPECULAR_F0 = _color(
    "specular_f0", _terms.DIELECTRIC_F0,
    "dielectric F0 = min(((ior - 1)/(ior + 1))^2 specularColorFactor, 1), RGB",
    neutral=_terms.DIELECTRIC_F0,
)  # fmt: skip
CLEARCOAT = _unit("clearcoat", 0.5, "clearcoatFactor, unitless")
CLEARCOAT_ROUGHNESS = _rough("clearcoat_roughness", 0.01, 0.2, "clearcoatRoughnessFactor")
SHEEN_COLOR = _color("sheen_color", 0.2, "sheenColorFactor, RGB", linear=True)
SHEEN_ROUGHNESS = _rough("sheen_roughness", 0.045, 0.5, "sheenRoughnessFactor, a = r^2")


def charlie_d(h: jax.Array, a: jax.Array) -> jax.Array:
    """Charlie sheen NDF ``(2 + 1/a) sin(theta_h)^(1/a) / (2 pi)`` (1/sr), (N,), of unit
    half vectors ``h`` (N, 3): :func:`~brdffit.models._terms.charlie_d` with
    :data:`~brdffit.models._terms.CHARLIE_FLOOR` (module docstring)."""
    return _terms.charlie_d(h, a, _terms.CHARLIE_FLOOR)


def charlie_sheen(g: ShadingGeometry, a: jax.Array) -> jax.Array:
    """``D_charlie(a) V_ashikhmin``, ``V_ashikhmin = 1 / (4 (N.L + N.V - N.L N.V))``
    (1/sr), (N,)."""
    return charlie_d(g.h, a) * 0.25 / (g.cos_i + g.cos_o - g.cos_i * g.cos_o)


@final
class GltfPbr(AbstractModel):
    """glTF 2.0 metallic-roughness with optional specular, clear coat and sheen."""

    specular: bool = eqx.field(static=True, default=True)
    clearcoat: bool = eqx.field(static=True, default=False)
    sheen: bool = eqx.field(static=True, default=False)

    name: ClassVar[str] = "gltf"
    reference: ClassVar[str] = (
        "Khronos glTF 2.0 Appendix B, KHR_materials_specular/_ior/_clearcoat/_sheen"
    )
    energy_conserving: ClassVar[bool] = False

    @property
    def reciprocal(self) -> bool:  # type: ignore[override]
        return not self.clearcoat

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        out = (BASE_COLOR, METALLIC, ROUGHNESS)
        out += (SPECULAR, SPECULAR_F0) if self.specular else ()
        out += (CLEARCOAT, CLEARCOAT_ROUGHNESS) if self.clearcoat else ()
        return out + ((SHEEN_COLOR, SHEEN_ROUGHNESS) if self.sheen else ())

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        base, m = params["base_color"][None, :], params["metallic"]
        dv = _terms.ggx_dv(g.h, g.wi, g.wo, params["roughness"] ** 2)[:, None]
        w = ((1.0 - g.cos_d) ** 5)[:, None]
        if self.specular:
            s, f0 = params["specular"], params["specular_f0"]
        else:
            s, f0 = 1.0, jnp.full(3, _terms.DIELECTRIC_F0, dv.dtype)
        f_d = s * (f0[None, :] + (1.0 - f0[None, :]) * w)
        max_f = s * (jnp.max(f0) * (1.0 - w) + w)  # max_rgb F_d: F_d rises with f0
        dielectric = f_d * dv + (1.0 - max_f) * base * _terms.INV_PI
        metal = (base + (1.0 - base) * w) * dv
        out = (1.0 - m) * dielectric + m * metal
        if self.sheen:
            lobe = charlie_sheen(g, params["sheen_roughness"] ** 2)
            out = out + params["sheen_color"][None, :] * lobe[:, None]
        if self.clearcoat:
            fc = params["clearcoat"] * (COAT_F0 + (1.0 - COAT_F0) * (1.0 - g.cos_o) ** 5)
            coat = _terms.ggx_dv(g.h, g.wi, g.wo, params["clearcoat_roughness"] ** 2)
            out = out * (1.0 - fc)[:, None] + (fc * coat)[:, None]
        return out
