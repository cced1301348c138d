"""OpenPBR Surface, opaque, as MaterialX 1.39 evaluates it in GLSL: the renderer's own
material as a fittable model, whose MaterialX export (:mod:`brdffit.export.materialx`)
writes the parameters as they are and is exact by construction.

References: Andersson, Hill, Kutz, Portsmouth, Stone, Tamura et al., "OpenPBR Surface"
specification 1.1 (Academy Software Foundation, 2024/2025); the ``open_pbr_surface``
nodegraph of MaterialX 1.39.5 (``libraries/bxdf/open_pbr_surface.mtlx``) and the GLSL
closures it calls (``libraries/pbrlib/genglsl/mx_{oren_nayar_diffuse,dielectric,
generalized_schlick,sheen}_bsdf.glsl``, ``lib/mx_microfacet{,_diffuse,_specular,_sheen}.glsl``,
and the generator's ``mx_layer_bsdf``, ``mx_add_bsdf``, ``mx_multiply_bsdf_*``), with
``DIRECTIONAL_ALBEDO_METHOD 0`` (analytic fits), the generator's default. This is that
code, not the specification's ideal: where they differ the model follows MaterialX.

Every closure returns ``response = f cos_i`` and a ``throughput``; ``layer(top, base) =
top + base * throughput(top)``. ``wi`` = L, ``wo`` = V, ``c_v = cos_o``, ``c_d = wi.h``,
``eps = M_FLOAT_EPS = 1e-8``; in 1/sr (the response over ``cos_i``):

    f = fuzz + (1 - fuzz_weight E_z(c_v)) (coat + T_coat(c_v, c_d) B)
    B = k_dark [m metal + (1 - m)(spec_d specular_color + T_d(c_v, c_d) diffuse)]

* Roughness: ``r = specular_roughness``, with the coat ``r = lerp(r, min(1, 2
  coat_roughness^4 + r^4)^(1/4), coat_weight)``; ``alpha_x = r^2 sqrt(2 / (1 + (1 -
  a)^2))``, ``alpha_y = (1 - a) alpha_x`` (``a = specular_roughness_anisotropy``, along the
  tangent ``x``), each clamped to ``[eps, 1]``; ``alpha = sqrt(alpha_x alpha_y)``.
* Microfacet lobe ``DG = D(alpha_x, alpha_y) G2(alpha) / (4 cos_i cos_o)``: anisotropic GGX
  ``D``, *isotropic* height-correlated Smith ``G2`` of the mean ``alpha`` (as MaterialX).
* Directional albedo (MaterialX's rational fit): ``E(c_v, alpha, F0, F90) = F0 A + F90 B``
  (:func:`ggx_albedo`); energy compensation ``comp(F) = 1 + F (1 - E_ss) / E_ss``, ``E_ss =
  A + B``, with ``F`` the Fresnel at ``c_d`` (Turquin 2019, eq. 14, 16).
* Dielectric: ``eta_s = lerp(specular_ior, n_ratio, coat_weight)``, ``n_ratio =
  specular_ior / coat_ior`` if above 1 else its inverse; ``specular_weight`` modulates it,
  ``e = sqrt(specular_weight) (eta_s - 1) / (eta_s + 1)``, ``eta = (1 + e) / (1 - e)``
  (MaterialX's ``sign(eta_s - 1) sqrt(clamp(specular_weight F0(eta_s), 0, .99999))``; with
  ``eta_s >= 1`` and the bounds below the two are equal). ``spec_d = F(c_d) DG comp``, ``F``
  the exact dielectric Fresnel of ``eta``; ``T_d = max(0, 1 - E(c_v, alpha, e^2, 1) comp)``.
* Diffuse: EON (:func:`~brdffit.models._terms.eon_diffuse`) of ``base_color``, ``sigma =
  base_diffuse_roughness``, ``/ pi``; MaterialX clamps ``wi.wo`` to ``[eps, 1]`` first.
* Metal: ``metal = specular_weight F82(c_d) DG comp``, ``F82`` Hoffman's tinted Schlick
  (:func:`~brdffit.models._terms.f82_schlick`) with ``F0 = base_color`` and tint
  ``specular_color``, floored at 0. The one departure from MaterialX: its ``F82`` is
  negative at middle angles where a low tint meets a dark ``F0`` (``tint < 0.51`` at
  ``F0 = 0``, ``< 0.14`` at 0.2, ``< 0.03`` at 0.5: 8% of the square), and so is its
  metal lobe; a BRDF is not. The option ``negative_f82`` keeps MaterialX's value (then
  not a BRDF: the export measures with it what MaterialX renders).
* Coat (option ``coat``): ``coat = coat_weight F_c(c_d) DG_c comp_c`` with ``alpha =
  coat_roughness^2``, ``F_c`` the dielectric Fresnel of ``coat_ior``; ``T_coat = 1 -
  coat_weight E(c_v, alpha_c, F0_c, 1) comp_c`` (per light, through ``comp_c``). Darkening
  ``k_dark = lerp(1, (1 - K) / (1 - E_b K), coat_weight)``, ``K = 1 - (1 - F0_c) /
  coat_ior^2``, ``E_b = lerp(base_color, specular_weight base_color, m)``. Without the
  option ``k_dark = 1``, ``T_coat = 1``, ``coat = 0``.
* Fuzz (option ``fuzz``): Zeltner's LTC sheen, ``fuzz = fuzz_weight fuzz_color E_z(c_v)
  D_ltc / cos_i`` (:func:`~brdffit.models._terms.zeltner_sheen`, ``zeltner_albedo``), the
  roughness clamped to ``[0.01, 1]`` as MaterialX does.
* Thin film (option ``thin_film``): MaterialX's Airy Fresnel
  (:func:`~brdffit.models._films.airy_fresnel`, RGB)
  in place of ``F`` in the dielectric and metal lobes and their ``comp``, blended by
  ``w = thin_film_weight``: ``spec_d = lerp(spec_d, spec_d^tf, w)``, ``metal`` likewise,
  ``T_d = max(0, 1 - w E comp^tf - (1 - w) E comp)`` (``E`` keeps ``F0 = e^2``: MaterialX
  puts the film into the throughput only through ``comp``). The film's thickness is
  ``thin_film_thickness`` micrometres (written to the closures in nm).
* A closure whose weight is below ``eps`` returns nothing (``metal`` at ``specular_weight
  < eps``, the coat, the fuzz, each thin-film half).

Fixed inputs: ``base_weight`` 1 (it only scales ``base_color``), ``coat_color`` white,
``coat_darkening`` 1, ``coat_roughness_anisotropy`` 0, no transmission, subsurface or
emission, ``geometry_thin_walled`` false, the coat's normal and tangent the surface's.
MaterialX clamps ``cos_i``, ``cos_o``, ``c_d`` and ``wi.wo`` to ``[eps, 1]`` in every
closure, and so does the model (:func:`clamped`), dividing the response by the clamped
``cos_i``: within 1e-8 of the horizon the values are MaterialX's, not the formulas' limits.

Bounds: ``specular_roughness`` and ``coat_roughness`` from 0.01 (``alpha`` 1e-4, as the
``gltf`` model, so every GGX lobe walter fits is reachable; MaterialX's own floor is
``alpha = eps``); ``specular_ior`` and ``coat_ior`` in [1, 3] (OpenPBR's soft range;
from 1, ``eta_s >= 1``, where MaterialX's ``sign`` is 0 or 1 and the modulated index is
the smooth ``e`` above); ``specular_weight`` in [0, 1] (OpenPBR allows more: above 1
the metal reflects more than its ``F0`` and its throughput turns negative);
``fuzz_roughness`` in [0.01, 1], the clamp; ``thin_film_thickness`` in [0.01, 2] um
(MaterialX switches the Airy sum off at 0, a jump; at 2 um, twice OpenPBR's soft maximum,
the interference terms have died out) and ``thin_film_ior`` in [1, 3].

Guards, each leaving the value unchanged where it is defined: ``sqrt`` of
``specular_weight`` and of the Airy sum's ``R12 R23`` and phase terms is taken of a
sanitised value (0 gives 0 with a zero derivative,
:func:`~brdffit.models._films.sqrt0`); the film's phases use ``atan2(0, 0) = 0`` with a
zero derivative (``_films._atan2``: a film whose index equals its
base's, where ``R23 = 0`` multiplies them); the refracted ``cos_t^2`` is floored at
``cos^2`` (its exact minimum) and ``1 - R12 R23`` at 1e-18 (it is >= ``1 - R12``), which
float32 rounding reaches only at grazing. Not reciprocal (every throughput is a function
of ``c_v``), not energy conserving (the albedo fit exceeds 1 by up to 3.5%).

Free parameters: all inputs above; neutral values (:func:`brdffit.simplify`)
``base_metalness`` 0, ``base_diffuse_roughness`` 0 (Lambert), ``specular_weight`` 1,
``specular_color`` 1, ``specular_ior`` 1.5, ``specular_roughness_anisotropy`` 0 (the
OpenPBR defaults). Coat, fuzz and thin film have none: their options remove them.
For a dielectric (``base_metalness`` 0, no coat) only ``specular_weight F0(specular_ior)``
is seen, so one of the pair must be frozen (``tests/cases_j.py``).
"""

from __future__ import annotations

from typing import ClassVar, final

import equinox as eqx
import jax
import jax.numpy as jnp

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models import _films, _terms

EPS = 1e-8
"""MaterialX's ``M_FLOAT_EPS`` (``stdlib/genglsl/lib/mx_math.glsl``)."""


def _unit(name: str, default: float, doc: str, **kw: object) -> Parameter:
    return Parameter(name, (), (0.0, 1.0), default, "logit", doc, **kw)  # type: ignore[arg-type]


def _color(name: str, default: float, doc: str, **kw: object) -> Parameter:
    return Parameter(name, (3,), (0.0, 1.0), default, "logit", doc, **kw)  # type: ignore[arg-type]


def _rough(name: str, low: float, default: float, doc: str) -> Parameter:
    return Parameter(name, (), (low, 1.0), default, "log", doc)


def _ior(name: str, default: float, doc: str, neutral: float | None = None) -> Parameter:
    return Parameter(name, (), (1.0, 3.0), default, "logit", doc, neutral=neutral)


BASE_COLOR = _color("base_color", 0.5, "diffuse albedo and metal F0, linear RGB")
BASE_METALNESS = _unit("base_metalness", 0.2, "metal blend (0 dielectric, 1 metal)", neutral=0.0)
BASE_DIFFUSE_ROUGHNESS = _unit(
    "base_diffuse_roughness", 0.3, "EON roughness sigma (0 Lambert)", neutral=0.0
)
SPECULAR_WEIGHT = _unit(
    "specular_weight", 0.9, "dielectric F0 scale (via the IOR) and metal weight", neutral=1.0
)
SPECULAR_COLOR = _color(
    "specular_color", 0.9, "dielectric tint and metal F82 tint, RGB", neutral=1.0
)
SPECULAR_ROUGHNESS = _rough("specular_roughness", 0.01, 0.3, "perceptual: alpha = r^2")
SPECULAR_IOR = _ior("specular_ior", 1.5, "dielectric index of refraction", neutral=1.5)
ANISOTROPY = _unit("specular_roughness_anisotropy", 0.3, "stretch along the tangent x", neutral=0.0)
COAT_WEIGHT = _unit("coat_weight", 0.5, "clear-coat presence")
COAT_ROUGHNESS = _rough("coat_roughness", 0.01, 0.1, "coat, perceptual: alpha = r^2")
COAT_IOR = _ior("coat_ior", 1.6, "coat index of refraction")
FUZZ_WEIGHT = _unit("fuzz_weight", 0.5, "fuzz presence")
FUZZ_COLOR = _color("fuzz_color", 0.5, "fuzz colour, RGB", linear=True)
FUZZ_ROUGHNESS = _rough("fuzz_roughness", 0.01, 0.5, "Zeltner sheen roughness")
THIN_FILM_WEIGHT = _unit("thin_film_weight", 0.5, "thin-film coverage")
THIN_FILM_THICKNESS = Parameter(
    "thin_film_thickness", (), (0.01, 2.0), 0.5, "log", "film thickness, micrometres"
)
THIN_FILM_IOR = _ior("thin_film_ior", 1.4, "film index of refraction")


def ggx_albedo(cos_v: jax.Array, alpha: jax.Array) -> tuple[jax.Array, jax.Array]:
    """MaterialX's rational fit of GGX's directional albedo, ``(A, B)`` with ``E = F0 A +
    F90 B`` (``mx_ggx_dir_albedo_analytic``), each clamped to [0, 1], (N,) each. Its
    denominators stay above 0.97 on [0, 1]^2 (no pole); ``A + B`` lies in [0.31, 1.035]."""
    x, y = cos_v, alpha
    xy, x2, y2 = x * y, x * x, y * y
    terms = (1.0, x, y, xy, x2, y2, x2 * y, x * y2, x2 * y2)
    coef = (
        (0.1003, 0.9345, 1.0, 1.0),
        (-0.6303, -2.323, -1.765, 0.2281),
        (9.748, 2.229, 8.263, 15.94),
        (-2.038, -3.748, 11.53, -55.83),
        (29.34, 1.424, 28.96, 13.08),
        (-8.245, -0.7684, -7.507, 41.26),
        (-26.44, 1.436, -36.11, 54.9),
        (19.99, 0.2913, 15.86, 300.2),
        (-5.448, 0.6286, 33.37, -285.1),
    )
    r = [sum(c[k] * t for c, t in zip(coef, terms, strict=True)) for k in range(4)]
    return jnp.clip(r[0] / r[2], 0.0, 1.0), jnp.clip(r[1] / r[3], 0.0, 1.0)


def compensation(f: jax.Array, a: jax.Array, b: jax.Array) -> jax.Array:
    """Turquin's energy compensation ``1 + F (1 - E_ss) / E_ss``, ``E_ss = A + B``, of a
    Fresnel ``F`` (N,) or (N, 3) at ``c_d`` (``mx_ggx_energy_compensation``)."""
    e_ss = a + b
    e_ss = e_ss[:, None] if f.ndim == 2 else e_ss
    return 1.0 + f * (1.0 - e_ss) / e_ss


def alphas(r: jax.Array, anisotropy: jax.Array | float) -> tuple[jax.Array, jax.Array]:
    """OpenPBR's ``(alpha_x, alpha_y)`` of a perceptual roughness and its anisotropy
    (``open_pbr_anisotropy``), clamped to ``[eps, 1]`` as the closures do."""
    ax = r * r * jnp.sqrt(2.0 / (1.0 + (1.0 - anisotropy) ** 2))
    return jnp.clip(ax, EPS, 1.0), jnp.clip((1.0 - anisotropy) * ax, EPS, 1.0)


def _smith_lambda(cos: jax.Array, alpha: jax.Array) -> jax.Array:
    """GGX Smith ``Lambda = (sqrt(1 + alpha^2 tan^2) - 1) / 2`` of a cosine, written
    without cancellation (:func:`~brdffit.models._terms.ggx_lambda` of a cosine: MaterialX's
    ``mx_ggx_smith_G2`` takes clamped cosines, not directions)."""
    x = alpha * alpha * (1.0 - cos * cos) / (cos * cos)
    return 0.5 * x / (jnp.sqrt(1.0 + x) + 1.0)


def microfacet(g: ShadingGeometry, ax: jax.Array, ay: jax.Array) -> jax.Array:
    """``D(ax, ay) G2(sqrt(ax ay)) / (4 cos_i cos_o)`` (1/sr), (N,): anisotropic GGX ``D``,
    isotropic height-correlated Smith ``G2 = 1 / (1 + Lambda_i + Lambda_o)`` of the mean
    alpha (MaterialX's pairing), cosines as ``g`` holds them (clamped: :func:`clamped`)."""
    a = jnp.sqrt(ax * ay)
    g2 = _terms.smith_g(
        _smith_lambda(g.cos_i, a), _smith_lambda(g.cos_o, a), height_correlated=True
    )
    return _terms.ggx_d(g.h, ax, ay) * g2 / (4.0 * g.cos_i * g.cos_o)


def clamped(g: ShadingGeometry) -> ShadingGeometry:
    """``g`` with ``cos_i``, ``cos_o`` and ``cos_d`` clamped to ``[eps, 1]``, as every
    MaterialX closure clamps ``N.L``, ``N.V`` and ``V.H`` (they differ only within 1e-8 of
    the horizon)."""
    cos = (jnp.clip(c, EPS, 1.0) for c in (g.cos_i, g.cos_o, g.cos_d))
    return eqx.tree_at(lambda t: (t.cos_i, t.cos_o, t.cos_d), g, tuple(cos))


@final
class OpenPbr(AbstractModel):
    """OpenPBR Surface (opaque) as MaterialX's GLSL evaluates it; optional anisotropy,
    coat, fuzz and thin film."""

    anisotropic: bool = eqx.field(static=True, default=False)
    coat: bool = eqx.field(static=True, default=False)
    fuzz: bool = eqx.field(static=True, default=False)
    thin_film: bool = eqx.field(static=True, default=False)
    negative_f82: bool = eqx.field(static=True, default=False)

    name: ClassVar[str] = "openpbr"
    reference: ClassVar[str] = "OpenPBR Surface 1.1, as MaterialX 1.39.5 GLSL evaluates it"
    reciprocal: ClassVar[bool] = False
    energy_conserving: ClassVar[bool] = False

    @property
    def channel_separable(self) -> bool:  # type: ignore[override]
        """False while ``thin_film`` is on: the film's Fresnel mixes the channels of
        ``base_color`` and ``specular_color`` (:func:`~brdffit.models._films.airy_fresnel`;
        :attr:`AbstractModel.channel_separable`)."""
        return not self.thin_film

    def __check_init__(self) -> None:
        for k, v in self.options().items():
            if not isinstance(v, bool):
                raise ValueError(f"openpbr: option {k}={v!r} is not a bool")

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        out = (BASE_COLOR, BASE_METALNESS, BASE_DIFFUSE_ROUGHNESS, SPECULAR_WEIGHT)
        out += (SPECULAR_COLOR, SPECULAR_ROUGHNESS, SPECULAR_IOR)
        out += (ANISOTROPY,) if self.anisotropic else ()
        out += (COAT_WEIGHT, COAT_ROUGHNESS, COAT_IOR) if self.coat else ()
        out += (FUZZ_WEIGHT, FUZZ_COLOR, FUZZ_ROUGHNESS) if self.fuzz else ()
        return out + (THIN_FILM_ROWS if self.thin_film else ())

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        cos_i = g.cos_i  # before the clamp: the fuzz's LTC response holds it (below)
        g = clamped(g)
        c, m, sw = params["base_color"], params["base_metalness"], params["specular_weight"]
        tint, r, ior = (
            params["specular_color"],
            params["specular_roughness"],
            params["specular_ior"],
        )
        if self.coat:
            cw, cior = params["coat_weight"], params["coat_ior"]
            r = r + cw * (jnp.minimum(1.0, 2.0 * params["coat_roughness"] ** 4 + r**4) ** 0.25 - r)
            ratio = jnp.where(ior / cior > 1.0, ior / cior, cior / ior)
            ior = ior + cw * (ratio - ior)
        e = _films.sqrt0(sw) * (ior - 1.0) / (ior + 1.0)  # modulated: F0(eta) = e^2
        eta = (1.0 + e) / (1.0 - e)
        ax, ay = alphas(r, params["specular_roughness_anisotropy"] if self.anisotropic else 0.0)
        dg = microfacet(g, ax, ay)[:, None]
        a, b = ggx_albedo(g.cos_o, jnp.sqrt(ax * ay))

        def dielectric(f: jax.Array, weight: jax.Array | float) -> tuple[jax.Array, jax.Array]:
            comp = compensation(f, a, b)  # f (N, 1) or (N, 3)
            off = weight < EPS
            spec = jnp.where(off, 0.0, weight * f * comp * dg)
            return spec, jnp.where(off, 0.0, weight * (e * e * a + b)[:, None] * comp)

        def metal(f: jax.Array, weight: jax.Array) -> jax.Array:
            return jnp.where(weight < EPS, 0.0, weight * dg * f * compensation(f, a, b))

        f_d = _terms.fresnel_dielectric(g.cos_d, eta)[:, None]
        f_m = _terms.f82_schlick(c, tint, g.cos_d)
        f_m = f_m if self.negative_f82 else jnp.maximum(f_m, 0.0)
        if self.thin_film:
            w = params["thin_film_weight"]
            nm, film = 1000.0 * params["thin_film_thickness"], params["thin_film_ior"]
            f_dt = _films.airy_fresnel(g.cos_d, film, nm, jnp.broadcast_to(eta, (3,)), None)
            f_mt = _films.airy_fresnel(g.cos_d, film, nm, _f0_to_ior(c), (c, tint))
            spec, albedo = dielectric(f_d, 1.0 - w)
            spec_t, albedo_t = dielectric(f_dt, w)
            spec, albedo = spec + spec_t, albedo + albedo_t
            shine = metal(f_m, sw * (1.0 - w)) + metal(f_mt, sw * w)
        else:
            spec, albedo = dielectric(f_d, 1.0)
            shine = metal(f_m, sw)
        cos_io = jnp.clip(jnp.sum(g.wi * g.wo, axis=-1), EPS, 1.0)
        sigma = params["base_diffuse_roughness"]
        diffuse = _terms.eon_diffuse(g.cos_i, g.cos_o, cos_io, sigma, c, EPS) * _terms.INV_PI
        base = spec * tint[None, :] + diffuse * jnp.maximum(0.0, 1.0 - albedo)
        out = m * shine + (1.0 - m) * base
        if self.coat:
            out = self.coated(params, g, out)
        if self.fuzz:
            fw, fr = params["fuzz_weight"], jnp.clip(params["fuzz_roughness"], 0.01, 1.0)
            e_z = _terms.zeltner_albedo(g.cos_o, fr)
            # the LTC lobe's response holds the unclamped cos_i, the division the clamped one
            ltc = _terms.zeltner_sheen(g.wi, g.wo, g.cos_o, fr) * (cos_i / g.cos_i)
            lobe = (fw * e_z * ltc)[:, None]
            fuzzed = lobe * params["fuzz_color"][None, :] + out * (1.0 - fw * e_z)[:, None]
            out = jnp.where(fw < EPS, out, fuzzed)
        return out

    def coated(self, params: Params, g: ShadingGeometry, base: jax.Array) -> jax.Array:
        """``coat + T_coat k_dark base`` of the uncoated ``base`` (N, 3) (module docstring)."""
        c, m, sw = params["base_color"], params["base_metalness"], params["specular_weight"]
        cw, cior = params["coat_weight"], params["coat_ior"]
        f0 = ((cior - 1.0) / (cior + 1.0)) ** 2
        k = 1.0 - (1.0 - f0) / cior**2
        e_base = c + m * (sw * c - c)
        dark = 1.0 + cw * ((1.0 - k) / (1.0 - e_base * k) - 1.0)
        base = base * jnp.clip(dark, 0.0, 1.0)[None, :]
        ax, ay = alphas(params["coat_roughness"], 0.0)
        a, b = ggx_albedo(g.cos_o, jnp.sqrt(ax * ay))
        f_c = _terms.fresnel_dielectric(g.cos_d, cior)
        comp = compensation(f_c, a, b)
        coat = cw * f_c * comp * microfacet(g, ax, ay)
        throughput = 1.0 - cw * (f0 * a + b) * comp
        coated = coat[:, None] + base * throughput[:, None]
        return jnp.where(cw < EPS, base, coated)


def _f0_to_ior(f0: jax.Array) -> jax.Array:
    """``mx_f0_to_ior``: ``(1 + sqrt F0) / (1 - sqrt F0)`` of ``F0`` clamped to [.01, .99]."""
    root = jnp.sqrt(jnp.clip(f0, 0.01, 0.99))
    return (1.0 + root) / (1.0 - root)


THIN_FILM_ROWS = (THIN_FILM_WEIGHT, THIN_FILM_THICKNESS, THIN_FILM_IOR)
