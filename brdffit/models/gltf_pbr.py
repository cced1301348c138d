"""The glTF 2.0 metallic-roughness material as a fittable model (Khronos, glTF 2.0
specification, Appendix B "BRDF Implementation", and the extensions
``KHR_materials_specular``, ``KHR_materials_ior``, ``KHR_materials_clearcoat``,
``KHR_materials_sheen``, ``KHR_materials_iridescence``). Fitting it fits the renderer's
own material: its glTF export writes the parameters as they are
(:mod:`brdffit.export.gltf`) and is exact by construction. ``wi`` = L (light), ``wo`` =
V (viewer), ``h`` the half vector:

    alpha = roughness^2                       (glTF's roughness is perceptual)
    DV    = D_GGX(alpha) G2 / (4 N.L N.V),  G2 = 1 / (1 + Lambda(L) + Lambda(V))
    w     = (1 - V.H)^5
    F_d   = specular (specular_f0 + (1 - specular_f0) w)     (KHR_materials_specular, _ior)
    F_m   = base_color + (1 - base_color) w
    + iridescence (k = iridescence, the film's Fresnel F_film at V.H):
            F_d = mix(F_d, F_film(specular specular_f0), k),  F_m = mix(F_m, F_film(base_color), k)
    dielectric = F_d DV + (1 - max_rgb F_d) base_color / pi
    metal      = F_m DV
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
* Iridescence (``KHR_materials_iridescence``; Belcour and Barla 2017, "A Practical
  Extension to Microfacet Theory for the Modeling of Varying Iridescence", TOG 36(4)): a
  dielectric thin film of index ``iridescence_ior`` and thickness
  ``iridescence_thickness`` (nm; the extension's ``iridescenceThicknessMaximum``, the
  thickness without a thickness texture) between the air and the base. ``F_film(f0)``
  is :func:`~brdffit.models._films.thin_film_fresnel` (Schlick at both interfaces, the
  Airy sum's terms ``m <= 2`` integrated over the spectrum in Fourier space, optical path
  difference ``2 iridescence_ior thickness cos(theta_2)`` with the refracted angle
  ``theta_2``, as the extension's text since 2024 and its sample viewer), the base read
  as a dielectric of index ``(1 + sqrt f0)/(1 - sqrt f0)``. Dielectric: the extension's
  ``iridescent_dielectric_layer`` with ``KHR_materials_specular``, ``rgb_mix(base,
  specular_brdf, mix(specular fr, iridescent_fresnel(specular f0), k))``, whose base is
  weighted by ``1 - max_rgb`` of that mixed Fresnel; metal: its
  ``iridescent_conductor_layer``, ``mix(conductor_fresnel, specular_brdf
  iridescent_fresnel(baseColor), k)``. Sheen and clear coat lie on top unchanged (the
  extension ignores the coat-film interface).

  Choices where the sources differ (the extension's text is followed in each):

  - the film's Fresnel is evaluated at ``V.H``, the cosine on the microfacet, where the
    text mixes it with ``fr`` at ``|V.H|`` and where Belcour and Barla evaluate it; the
    glTF sample viewer (and three.js, Babylon) evaluate it once per pixel at ``N.V``,
    which agrees at the mirror direction (``h = n``) and departs across a wide lobe
    (and is not reciprocal);
  - the dielectric's diffuse weight is ``1 - max_rgb(mix(specular fr, F_film, k))`` (the
    text's form with ``KHR_materials_specular``; its form without that extension,
    ``mix(fresnel_mix, rgb_mix, k)``, is the same function for a grey ``fr``); the
    sample viewer mixes ``(1 - F) base`` per channel with ``rgb_mix``'s ``(1 - max
    F_film) base``, which differs for a coloured ``specular_f0``;
  - the dielectric's film sits on ``specular specular_f0`` (the text's ``specular_weight
    * base_f0``); the sample viewer passes ``specular_f0`` alone;
  - ``F_film``'s guards are the sample viewer's (``iridescence.glsl``): the film's index
    goes to 1 as the thickness goes to 0 (smoothstep over 0.03 nm) and the base ``f0``
    is clamped to 0.9999, where the text adds 1e-4 to ``f0``; brdffit also floors ``f0``
    at 1e-12 (:func:`~brdffit.models._films.thin_film_fresnel`). The sample viewer
    switches the film off at a thickness of exactly 0, the text does not: a fit on the
    lower bound renders without the film there.

Bounds: ``roughness`` and ``clearcoat_roughness`` from 0.01 (alpha 1e-4, the floor of
``walter``'s alpha, so every GGX lobe it fits is reachable); the spec itself has none,
while real-time viewers clamp higher (Filament at 0.045), so a fit below that renders
sharper in a path tracer than in those viewers. ``sheen_roughness`` from 0.045, where
Filament clamps it (``MIN_PERCEPTUAL_ROUGHNESS``): ``1/a`` in ``D_charlie`` has no floor of
its own. Singularity guard: at ``h`` = normal ``D_charlie`` is exactly 0 and its
power is taken of 1 instead (:func:`~brdffit.models._terms.charlie_d`), so
``d/d(sheen_roughness)`` (``log sin^2``) never meets ``log 0``; no floor changes the lobe
(Filament's, ``2^-7``, would change the BRDF the spec defines). ``iridescence_ior`` in
[1, 2.5] (the schema's minimum 1, the air above, so
the film has no total internal reflection; up to titanium dioxide) and
``iridescence_thickness`` in [0, 1200] nm (the range of the extension's figures, where
the colours have faded to pastels): those of walter's ``thin_film``, so every film it
fits is reachable. The loss is periodic in the thickness (the hue cycles every
``lambda / (2 iridescence_ior)``): a fit relies on the start screen spreading starts
over the range.

Affine (linear least squares per start): ``base_color`` and ``sheen_color``, jointly:
``base_color`` enters ``(1 - metallic)(1 - max F_d) / pi + metallic (1 - w) DV`` times
itself, ``sheen_color`` a lobe of its own, and the coat scales both by ``1 - Fc``.
``metallic``, ``specular`` and ``clearcoat`` are each affine alone but multiply
``base_color``; ``specular_f0`` enters through ``max``. With iridescence only
``sheen_color`` is affine: the metal's film sits on ``base_color``, the dielectric's on
``specular specular_f0``, and the base's weight takes the max of the mixed Fresnel.
Neutral values (:func:`brdffit.simplify`): ``metallic`` 0 (a dielectric), ``specular`` 1
and ``specular_f0`` 0.04 (glTF's defaults without the extensions). Clear coat, sheen and
iridescence have none: their options remove them with their other parameters, which a
weight pinned at 0 would leave unidentifiable (no film index or thickness is neutral
either: at a thickness of 0 the film's formula is not Schlick's, its first interface
keeps Schlick's ``(1 - cos)^5`` and the interference terms stay; on ``f0 = 0.04`` it
reflects 2.8 times Schlick's value at ``cos_d = 0.3``).
Not energy conserving (the diffuse is weighted by ``1 - max F`` at ``V.H``, not by the
specular albedo, and the sheen is added without albedo scaling). Reciprocal without the
clear coat (the film's Fresnel at ``V.H = L.H`` keeps it so); its ``Fc`` at ``N.V`` is not.
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
from brdffit.models import _films, _terms

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
# default 0.9 rather than the extension's typical 1: a start inside the box
IRIDESCENCE = _unit("iridescence", 0.9, "iridescenceFactor, weight of the film's Fresnel")
IRIDESCENCE_IOR = Parameter(
    "iridescence_ior", (), (1.0, 2.5), 1.3, "logit", "iridescenceIor, the film's index"
)
IRIDESCENCE_THICKNESS = Parameter(
    "iridescence_thickness", (), (0.0, 1200.0), 400.0, "logit",
    "iridescenceThicknessMaximum, the film's thickness without a texture, nm",
)  # fmt: skip


def charlie_d(h: jax.Array, a: jax.Array) -> jax.Array:
    """Charlie sheen NDF ``(2 + 1/a) sin(theta_h)^(1/a) / (2 pi)`` (1/sr), (N,), of unit
    half vectors ``h`` (N, 3): :func:`~brdffit.models._terms.charlie_d`, no floor (module
    docstring)."""
    return _terms.charlie_d(h, a)


def charlie_sheen(g: ShadingGeometry, a: jax.Array) -> jax.Array:
    """``D_charlie(a) V_ashikhmin``, ``V_ashikhmin = 1 / (4 (N.L + N.V - N.L N.V))``
    (1/sr), (N,)."""
    return charlie_d(g.h, a) * 0.25 / (g.cos_i + g.cos_o - g.cos_i * g.cos_o)


def film_mix(params: Params, g: ShadingGeometry, f: jax.Array, f0: jax.Array) -> jax.Array:
    """``mix(f, F_film(f0), iridescence)``, (N, 3): a Fresnel ``f`` (N, 3) mixed with the
    reflectance of the film on a base of normal reflectance ``f0`` (3,), at ``V.H``
    (:func:`~brdffit.models._films.thin_film_fresnel`; module docstring)."""
    film = _films.thin_film_fresnel(
        g.cos_d, params["iridescence_thickness"], params["iridescence_ior"], f0
    )
    return f + params["iridescence"] * (film - f)


@final
class GltfPbr(AbstractModel):
    """glTF 2.0 metallic-roughness with optional specular, clear coat, sheen and
    iridescence."""

    specular: bool = eqx.field(static=True, default=True)
    clearcoat: bool = eqx.field(static=True, default=False)
    sheen: bool = eqx.field(static=True, default=False)
    iridescence: bool = eqx.field(static=True, default=False)

    name: ClassVar[str] = "gltf"
    reference: ClassVar[str] = (
        "Khronos glTF 2.0 Appendix B, KHR_materials_specular/_ior/_clearcoat/_sheen/_iridescence"
    )
    energy_conserving: ClassVar[bool] = False

    @property
    def channel_separable(self) -> bool:  # type: ignore[override]
        """False while ``specular`` is on: the dielectric's diffuse weight
        ``1 - max_rgb(F_d)`` is a maximum over the channels of ``specular_f0``
        (:attr:`AbstractModel.channel_separable`)."""
        return not self.specular

    @property
    def reciprocal(self) -> bool:  # type: ignore[override]
        return not self.clearcoat

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        # with the film, the metal's Fresnel is not affine in base_color
        base = dataclasses.replace(BASE_COLOR, linear=False) if self.iridescence else BASE_COLOR
        out = (base, METALLIC, ROUGHNESS)
        out += (SPECULAR, SPECULAR_F0) if self.specular else ()
        out += (CLEARCOAT, CLEARCOAT_ROUGHNESS) if self.clearcoat else ()
        out += (SHEEN_COLOR, SHEEN_ROUGHNESS) if self.sheen else ()
        return out + (
            (IRIDESCENCE, IRIDESCENCE_IOR, IRIDESCENCE_THICKNESS) if self.iridescence else ()
        )

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        base, m = params["base_color"][None, :], params["metallic"]
        dv = _terms.ggx_dv(g.h, g.wi, g.wo, params["roughness"] ** 2)[:, None]
        w = ((1.0 - g.cos_d) ** 5)[:, None]
        if self.specular:
            s, f0 = params["specular"], params["specular_f0"]
        else:
            s, f0 = 1.0, jnp.full(3, _terms.DIELECTRIC_F0, dv.dtype)
        f_d = s * (f0[None, :] + (1.0 - f0[None, :]) * w)
        f_m = base + (1.0 - base) * w
        if self.iridescence:
            f_d = film_mix(params, g, f_d, s * f0)  # the text's specular_weight * base_f0
            f_m = film_mix(params, g, f_m, params["base_color"])
            max_f = jnp.max(f_d, axis=1, keepdims=True)
        else:
            max_f = s * (jnp.max(f0) * (1.0 - w) + w)  # max_rgb F_d: F_d rises with f0
        dielectric = f_d * dv + (1.0 - max_f) * base * _terms.INV_PI
        metal = f_m * dv
        out = (1.0 - m) * dielectric + m * metal
        if self.sheen:
            lobe = charlie_sheen(g, params["sheen_roughness"] ** 2)
            out = out + params["sheen_color"][None, :] * lobe[:, None]
        if self.clearcoat:
            fc = params["clearcoat"] * (COAT_F0 + (1.0 - COAT_F0) * (1.0 - g.cos_o) ** 5)
            coat = _terms.ggx_dv(g.h, g.wi, g.wo, params["clearcoat_roughness"] ** 2)
            out = out * (1.0 - fc)[:, None] + (fc * coat)[:, None]
        return out
