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
* Affine parameters (solved by linear least squares for each start of a fit): ``kd``
  and ``ks``; with ``specular_weight=False``, ``kd`` and ``f0``.
* ``diffuse=False`` removes ``kd`` and the Lambert term.

The ``chi+`` factors of the paper are 1 for every reflection pair above the horizon.
Singularities: ``1/(cos_i cos_o)`` grows at grazing angles but ``G`` cancels it to
first order; cosines are > 0 for every sample the geometry marks above the horizon.
Not energy conserving in the strict sense (``kd`` and the specular lobe are added
uncoupled; single scattering loses energy at high roughness). Reciprocal.
"""

from __future__ import annotations

from typing import ClassVar, Literal, final

import equinox as eqx
import jax

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models import _terms

KD = Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo, RGB", linear=True)
ALPHA = Parameter("alpha", (), (1e-4, 2.0), 0.2, "log", "roughness alpha, unitless")
ALPHA_X = Parameter("alpha_x", (), (1e-4, 2.0), 0.2, "log", "roughness along the tangent x")
ALPHA_Y = Parameter("alpha_y", (), (1e-4, 2.0), 0.2, "log", "roughness along the bitangent y")


@final
class Walter(AbstractModel):
    """Microfacet BRDF (GGX by default) with Smith masking, Schlick Fresnel, a specular
    weight and Lambert."""

    distribution: Literal["ggx", "beckmann"] = eqx.field(static=True, default="ggx")
    masking: Literal["uncorrelated", "height_correlated"] = eqx.field(
        static=True, default="uncorrelated"
    )
    smith: Literal["exact", "rational"] = eqx.field(static=True, default="exact")
    anisotropic: bool = eqx.field(static=True, default=False)
    diffuse: bool = eqx.field(static=True, default=True)
    specular_weight: bool = eqx.field(static=True, default=True)

    name: ClassVar[str] = "walter"
    reference: ClassVar[str] = "Walter, Marschner, Li, Torrance 2007, EGSR"
    energy_conserving: ClassVar[bool] = False

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

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        rough = (ALPHA_X, ALPHA_Y) if self.anisotropic else (ALPHA,)
        spec = _terms.fresnel_rows(self.specular_weight)
        return ((KD,) if self.diffuse else ()) + spec + rough

    def roughness(self, params: Params) -> tuple[jax.Array, jax.Array]:
        """(alpha_x, alpha_y) for either roughness parametrisation."""
        if self.anisotropic:
            return params["alpha_x"], params["alpha_y"]
        return params["alpha"], params["alpha"]

    def ndf(self, params: Params, h: jax.Array) -> jax.Array:
        """The microfacet distribution D(h) in 1/sr, (N,)."""
        ax, ay = self.roughness(params)
        return (
            _terms.ggx_d(h, ax, ay) if self.distribution == "ggx" else _terms.beckmann_d(h, ax, ay)
        )

    def lambda_(self, params: Params, v: jax.Array) -> jax.Array:
        """Smith Lambda of direction ``v`` for the chosen distribution, (N,)."""
        ax, ay = self.roughness(params)
        if self.distribution == "ggx":
            return _terms.ggx_lambda(v, ax, ay)
        if self.smith == "rational":
            return _terms.beckmann_lambda_rational(v, ax, ay)
        return _terms.beckmann_lambda(v, ax, ay)

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        d = self.ndf(params, g.h)
        gg = _terms.smith_g(
            self.lambda_(params, g.wi),
            self.lambda_(params, g.wo),
            height_correlated=self.masking == "height_correlated",
        )
        f = _terms.weighted_schlick(params, g.cos_d, self.specular_weight)
        spec = f * (d * gg / (4.0 * g.cos_i * g.cos_o))[:, None]
        if self.diffuse:
            spec = spec + _terms.lambert(params["kd"])
        return spec
