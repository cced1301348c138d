"""Walter, Marschner, Li and Torrance 2007, "Microfacet models for refraction through
rough surfaces" (EGSR), reflection part, plus a Lambert diffuse term.

    f(wi, wo) = kd / pi + ks F(wi . h) G(wi, wo) D(h) / (4 cos_i cos_o)

* ``D``: GGX (eq. 33) or Beckmann (eq. 25), isotropic ``alpha`` or, with
  ``anisotropic=True``, ``alpha_x`` / ``alpha_y`` along the tangent / bitangent
  (Heitz 2014, eqs. 82 and 85). Both integrate to 1 against ``cos theta_h``.
* ``G``: Smith, from the exact Lambda of the chosen distribution (GGX eq. 34;
  Beckmann via erfc), or Walter's rational approximation (eq. 27) for Beckmann
  (``smith="rational"``). ``masking="uncorrelated"`` is ``G1(i) G1(o)`` (Walter eq. 23);
  ``"height_correlated"`` is ``1 / (1 + Lambda_i + Lambda_o)`` (Heitz 2014, eq. 99).
* ``F``: Schlick with RGB ``f0`` (the table's common Fresnel).
* ``ks``: the comparison table's specular weight rho_s (RGB, in [0, 1]), as in its
  microfacet rows ``rho_d/pi + rho_s D G F / (pi (N.L)(N.V))`` (the table's ``pi`` is
  the ``4`` of a normalised ``D``). It lets the lobe be weaker than Fresnel allows (a
  dielectric coating that covers part of the surface, a lobe that loses energy to
  multiple scattering). ``specular_weight=False`` removes it (``ks = 1``, Walter's
  paper).
* ``ks`` against ``f0``: per channel the lobe's colour is ``ks (f0 + (1 - f0) w)`` with
  Schlick's ``w = (1 - cos_d)^5``, i.e. ``a + b w`` with ``a = ks f0`` and
  ``b = ks (1 - f0)``: any ``(a, b)`` with ``a, b >= 0`` and ``a + b <= 1`` is one
  ``(ks, f0)``. Near normal incidence (``w`` ~ 0) only the product ``ks f0`` shows; the
  two separate through the Fresnel rise toward grazing ``cos_d``, where ``F -> 1`` and
  the lobe tends to ``ks`` alone. So the data must contain cells along that rise
  (``theta_d`` from ~40 degrees, where ``w`` reaches 1e-3, to grazing); with fewer of
  them, or noisier ones, the standard errors of ``ks`` and ``f0`` widen together.
* ``ks`` at its bound 1 on measured materials: the bound is ``F <= 1`` at grazing
  ``cos_d`` (``ks`` is the lobe's grazing reflectance), not an artefact of the product
  ``ks f0``. Refitting RGL-EPFL files (stride 3 3 5, ``low_e2``) with the bound widened
  to 4 moved ``ks`` to 1.1-1.4 on cc_ibiza_sunset (loss -7%), 1.7-1.9 on satin_rosaline
  (-32%) and 1.8-2.0 on paper_white (-12%); the normal-incidence product ``ks f0``
  moved 15-19% on the two films and 60% on the paper, far less than ``ks``: the data
  reflect more toward grazing than one
  single-scattering lobe with Schlick's Fresnel can, a sheen or grazing-rise term this
  model lacks. A fitted ``ks`` on its bound therefore says "the model is short of
  grazing reflection here"; its standard error is undefined, as for any parameter
  held on a bound.
* Affine parameters (solved by linear least squares for each start of a fit): ``kd``,
  each lobe's ``ks`` and ``sheen_color``; with ``specular_weight=False``, ``kd``, each
  ``f0`` and ``sheen_color``. The coat multiplies the base by a factor free of them, so
  the model stays jointly affine in them with the coat on.
* ``diffuse=False`` removes ``kd`` and the Lambert term.

Layers and lobes the data may ask for (static options; off by default, and a feature
that is off has no parameter and no operation):

* ``n_lobes`` (>= 1): the specular lobe repeated, each lobe ``k`` with its own colour
  (``ks_k``, ``f0_k``) and roughness (``alpha_k``; ``alpha_x_k``, ``alpha_y_k``), summed:
  ``f = kd / pi + sum_k ks_k F_k D_k G_k / (4 cos_i cos_o)``. Ngan et al. 2005 (EGSR,
  "Experimental analysis of BRDF models", section 5) and Löw et al. 2012 (TOG, section 6)
  fitted two lobes to the MERL materials one lobe could not hold (metallic paints: a
  narrow peak inside a wide halo). With one lobe the names carry no index (``ks``,
  ``f0``, ``alpha``), as without the option. The default roughness of lobe ``k`` of
  ``n`` is ``0.05 * 10^((k - 1)/(n - 1))``, a decade from the narrowest to the widest:
  a start with equal lobes is a saddle of the loss (the gradient with respect to their
  difference is zero there), so the defaults separate a narrow lobe from a wide one.
  The lobes are exchangeable: the loss is the same with two lobes' labels swapped, so
  an MCMC run may visit both labellings (each lobe's marginal then has two modes).
* ``sheen``: Estevez and Kulla's (2017) Charlie sheen, the cloth lobe of Filament and of
  glTF's ``KHR_materials_sheen``, added to the base:
  ``sheen_color D_charlie(a) V_neubelt``, ``a = sheen_roughness^2``, ``D_charlie = (2 +
  1/a) sin(theta_h)^(1/a) / (2 pi)``, ``V_neubelt = 1 / (4 (cos_i + cos_o - cos_i
  cos_o))`` (Neubelt and Pettineo 2013). As in ``KHR_materials_sheen``'s reference without
  its optional albedo scaling of the base (which needs a tabulated albedo), so a glTF
  export carries the lobe as it is. No floor on ``sin^2 theta_h``: ``D`` is exactly 0 at
  ``h`` = normal (:func:`~brdffit.models._terms.charlie_d`).
* ``clearcoat``: glTF's ``KHR_materials_clearcoat`` layer over everything above:
  ``f = (1 - c F_c) f_base + c F_c D_c V_c``, ``F_c = 0.04 + 0.96 (1 - cos_o)^5`` (an
  IOR 1.5 coat, Schlick at the viewer's ``N.V`` as the extension's reference writes it:
  not reciprocal), ``D_c`` GGX and ``V_c`` height-correlated Smith GGX ``G / (4 cos_i
  cos_o)`` of ``clearcoat_alpha`` (the coat's GGX alpha, glTF's ``clearcoatRoughness^2``).

* ``thin_film``: a dielectric film over the lobes' base (Belcour and Barla 2017, the
  model of glTF's ``KHR_materials_iridescence``), for colour-shift foils and flake
  paints whose hue turns with angle: each lobe's Fresnel becomes ``mix(F_schlick(f0),
  F_film(cos_d), film_weight)`` with ``F_film`` the film's reflectance in RGB
  (:func:`~brdffit.models._films.thin_film_fresnel`: ``film_thickness`` in nm, its index
  ``film_ior``, the base read from ``f0``), as the extension mixes them. The loss is
  periodic in ``film_thickness`` (the hue cycles every ``lambda / (2 film_ior)``), so a
  fit depends on the start screen spreading starts over the whole range.

The ``chi+`` factors of the paper are 1 for every reflection pair above the horizon.
Singularities: ``1/(cos_i cos_o)`` grows at grazing angles but ``G`` cancels it to
first order; cosines are > 0 for every sample the geometry marks above the horizon.
Not energy conserving in the strict sense (``kd`` and the specular lobe are added
uncoupled; single scattering loses energy at high roughness). Reciprocal without the
clear coat.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar, Literal, final

import equinox as eqx
import jax

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models import _films, _terms

KD = Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo, RGB", linear=True)
ALPHA = Parameter("alpha", (), (1e-4, 2.0), 0.2, "log", "roughness alpha, unitless")
ALPHA_X = Parameter("alpha_x", (), (1e-4, 2.0), 0.2, "log", "roughness along the tangent x")
ALPHA_Y = Parameter("alpha_y", (), (1e-4, 2.0), 0.2, "log", "roughness along the bitangent y")
SHEEN_COLOR = Parameter(
    "sheen_color", (3,), (0.0, 1.0), 0.1, "logit", "sheen colour, RGB", linear=True
)
SHEEN_ROUGHNESS = Parameter(
    "sheen_roughness", (), (0.045, 1.0), 0.5, "log", "sheen roughness, a = roughness^2"
)
"""Lower bound: Filament's ``MIN_PERCEPTUAL_ROUGHNESS`` (0.045), below which its float
shaders lose ``a = roughness^2``; ``KHR_materials_sheen`` allows [0, 1], and 0 is a
delta the Charlie normalisation ``2 + 1/a`` cannot hold."""
CLEARCOAT = Parameter("clearcoat", (), (0.0, 1.0), 0.5, "logit", "clear coat weight, unitless")
CLEARCOAT_ALPHA = Parameter(
    "clearcoat_alpha", (), (0.045**2, 1.0), 0.01, "log", "clear coat GGX alpha, unitless"
)
"""Bounds: glTF's ``clearcoatRoughness`` in [0.045, 1] squared (the sheen's floor)."""
FILM_WEIGHT = Parameter("film_weight", (), (0.0, 1.0), 1.0, "logit", "thin-film weight, unitless")
FILM_THICKNESS = Parameter(
    "film_thickness", (), (0.0, 1200.0), 400.0, "logit", "thin-film thickness, nm"
)
"""Default and range: ``KHR_materials_iridescence``'s default maximum thickness (400 nm)
and the range of its figures (to 1200 nm, where the colours have faded to pastels)."""
FILM_IOR = Parameter("film_ior", (), (1.0, 2.5), 1.3, "logit", "thin-film index, unitless")
"""Default ``KHR_materials_iridescence``'s 1.3; up to 2.5 (titanium dioxide); >= 1, the
index of the air above, so the film has no total internal reflection."""
COAT_F0 = 0.04
"""Normal-incidence reflectance of the coat: ``KHR_materials_clearcoat``'s IOR 1.5."""


def lobe_alpha_default(k: int, n: int) -> float:
    """Default roughness of lobe ``k`` (1-based) of ``n``: 0.2 for one lobe, else a decade
    spread ``0.05 * 10^((k - 1)/(n - 1))`` (module docstring)."""
    return 0.2 if n == 1 else 0.05 * 10.0 ** ((k - 1) / (n - 1))


def _indexed(p: Parameter, suffix: str, **change: object) -> Parameter:
    if not suffix:
        return dataclasses.replace(p, **change)
    doc = f"{p.doc}, lobe {suffix[1:]}"
    return dataclasses.replace(p, name=p.name + suffix, doc=doc, **change)


@final
class Walter(AbstractModel):
    """Microfacet BRDF (GGX by default) with Smith masking, Schlick Fresnel, a specular
    weight and Lambert; optionally several lobes, a thin film, a sheen and a clear coat."""

    distribution: Literal["ggx", "beckmann"] = eqx.field(static=True, default="ggx")
    masking: Literal["uncorrelated", "height_correlated"] = eqx.field(
        static=True, default="uncorrelated"
    )
    smith: Literal["exact", "rational"] = eqx.field(static=True, default="exact")
    anisotropic: bool = eqx.field(static=True, default=False)
    diffuse: bool = eqx.field(static=True, default=True)
    specular_weight: bool = eqx.field(static=True, default=True)
    n_lobes: int = eqx.field(static=True, default=1)
    sheen: bool = eqx.field(static=True, default=False)
    clearcoat: bool = eqx.field(static=True, default=False)
    thin_film: bool = eqx.field(static=True, default=False)

    name: ClassVar[str] = "walter"
    reference: ClassVar[str] = "Walter, Marschner, Li, Torrance 2007, EGSR"
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    def __check_init__(self) -> None:
        if self.distribution not in ("ggx", "beckmann"):
            raise ValueError(f"walter: distribution {self.distribution!r} not 'ggx' or 'beckmann'")
        if self.masking not in ("uncorrelated", "height_correlated"):
            raise ValueError(
                f"walter: masking {self.masking!r} not 'uncorrelated' or 'height_correlated'"
            )
        if self.smith not in ("exact", "rational"):
            raise ValueError(f"walter: smith {self.smith!r} not 'exact' or 'rational'")
        if self.smith == "rational" and self.distribution != "beckmann":
            raise ValueError("walter: smith='rational' exists for distribution='beckmann' only")
        n = self.n_lobes
        if not isinstance(n, int) or isinstance(n, bool) or n < 1:
            raise ValueError(f"walter: n_lobes {n!r} is not an integer >= 1")

    @property
    def reciprocal(self) -> bool:  # type: ignore[override]
        """False with the clear coat, whose Fresnel weight reads the viewer's ``N.V``."""
        return not self.clearcoat

    def suffix(self, lobe: int) -> str:
        """The index the names of lobe ``lobe`` (1-based) carry: none with one lobe."""
        return "" if self.n_lobes == 1 else f"_{lobe}"

    def lobe_parameters(self, lobe: int) -> tuple[Parameter, ...]:
        """Table rows of specular lobe ``lobe`` (1-based): colour, then roughness."""
        s, a = self.suffix(lobe), lobe_alpha_default(lobe, self.n_lobes)
        rough = (ALPHA_X, ALPHA_Y) if self.anisotropic else (ALPHA,)
        spec = _terms.fresnel_rows(self.specular_weight)
        if self.thin_film:  # the film's reflectance is not affine in f0
            spec = tuple(
                dataclasses.replace(p, linear=False) if p.name == "f0" else p for p in spec
            )
        return tuple(_indexed(p, s) for p in spec) + tuple(_indexed(p, s, default=a) for p in rough)

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        out = (KD,) if self.diffuse else ()
        for lobe in range(1, self.n_lobes + 1):
            out += self.lobe_parameters(lobe)
        out += (FILM_WEIGHT, FILM_THICKNESS, FILM_IOR) if self.thin_film else ()
        out += (SHEEN_COLOR, SHEEN_ROUGHNESS) if self.sheen else ()
        return out + ((CLEARCOAT, CLEARCOAT_ALPHA) if self.clearcoat else ())

    def roughness(self, params: Params, lobe: int = 1) -> tuple[jax.Array, jax.Array]:
        """(alpha_x, alpha_y) of lobe ``lobe`` for either roughness parametrisation."""
        s = self.suffix(lobe)
        if self.anisotropic:
            return params[f"alpha_x{s}"], params[f"alpha_y{s}"]
        return params[f"alpha{s}"], params[f"alpha{s}"]

    def ndf(self, params: Params, h: jax.Array, lobe: int = 1) -> jax.Array:
        """The microfacet distribution D(h) of lobe ``lobe`` in 1/sr, (N,)."""
        ax, ay = self.roughness(params, lobe)
        return (
            _terms.ggx_d(h, ax, ay) if self.distribution == "ggx" else _terms.beckmann_d(h, ax, ay)
        )

    def lambda_(self, params: Params, v: jax.Array, lobe: int = 1) -> jax.Array:
        """Smith Lambda of direction ``v`` for lobe ``lobe``'s distribution, (N,)."""
        ax, ay = self.roughness(params, lobe)
        if self.distribution == "ggx":
            return _terms.ggx_lambda(v, ax, ay)
        if self.smith == "rational":
            return _terms.beckmann_lambda_rational(v, ax, ay)
        return _terms.beckmann_lambda(v, ax, ay)

    def lobe(self, params: Params, g: ShadingGeometry, lobe: int = 1) -> jax.Array:
        """Specular lobe ``lobe``: ``ks F D G / (4 cos_i cos_o)`` (1/sr), (N, 3)."""
        s = self.suffix(lobe)
        gg = _terms.smith_g(
            self.lambda_(params, g.wi, lobe),
            self.lambda_(params, g.wo, lobe),
            height_correlated=self.masking == "height_correlated",
        )
        f = _terms.schlick_fresnel(params["f0" + s], g.cos_d)
        if self.thin_film:
            film = _films.thin_film_fresnel(
                g.cos_d, params["film_thickness"], params["film_ior"], params["f0" + s]
            )
            f = f + params["film_weight"] * (film - f)
        if self.specular_weight:
            f = params["ks" + s][None, :] * f
        return f * (self.ndf(params, g.h, lobe) * gg / (4.0 * g.cos_i * g.cos_o))[:, None]

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        f = self.lobe(params, g, 1)
        for k in range(2, self.n_lobes + 1):
            f = f + self.lobe(params, g, k)
        if self.diffuse:
            f = f + _terms.lambert(params["kd"])
        if self.sheen:
            a = params["sheen_roughness"] ** 2
            d = _terms.charlie_d(g.h, a) * _terms.neubelt_v(g.cos_i, g.cos_o)
            f = f + params["sheen_color"][None, :] * d[:, None]
        if self.clearcoat:
            coat = _terms.ggx_dv(g.h, g.wi, g.wo, params["clearcoat_alpha"])
            fc = params["clearcoat"] * (COAT_F0 + (1.0 - COAT_F0) * (1.0 - g.cos_o) ** 5)
            f = f * (1.0 - fc)[:, None] + (fc * coat)[:, None]
        return f
