"""Cook and Torrance 1982, "A reflectance model for computer graphics" (ACM TOG 1(1)),
with a Lambert diffuse term.

    f(wi, wo) = kd / pi + ks F(wo . h) D(h) G(wi, wo) / (4 cos_i cos_o)
    D(h) = exp(-tan^2 theta_h / m^2) / (pi m^2 cos^4 theta_h)                (Beckmann)
    G    = min(1, 2 cos_h cos_o / (wo . h), 2 cos_h cos_i / (wo . h))       (V-cavities)

Normalisation (the source of the pi-versus-4 confusion): the paper writes
``R_s = F D G / (pi cos_i cos_o)`` with, in the 1982 TOG version,
``D_82 = exp(-tan^2/m^2) / (m^2 cos^4)``, for which ``int D_82 cos theta_h dw = pi``;
the 1981 SIGGRAPH version has ``D_81 = D_82 / 4``, ``int D_81 cos theta_h dw = pi/4``.
The D above is ``D_82 / pi``, the one with ``int D cos theta_h dw = 1``, and
``D_81 / pi = D / 4``: the implemented term equals the paper's ``F D_81 G / (pi cos_i
cos_o)``, which is the microfacet derivation's ``F D G / (4 cos_i cos_o)`` (Walter et al.
2007, eq. 20). The TOG 1982 formula as printed is 4 times larger; a fitted ``ks`` here
corresponds to the paper's ``s = ks / 4`` under that formula. ``m`` is the rms slope.

Option ``fresnel`` (static): ``"schlick"`` (RGB ``f0``, Schlick 1994), ``"dielectric"``
(the paper's exact unpolarised Fresnel, scalar relative index ``eta``) or
``"conductor"`` (exact Fresnel with complex index ``eta + i k``, RGB ``eta`` and ``k``).
``diffuse=False`` removes ``kd`` and the Lambert term.

Singularities and guards: ``1/(cos_i cos_o)`` grows at grazing angles (cosines >= 1e-6
stay finite; ``G`` cancels it only to first order, and not for grazing mirror pairs,
where ``f`` is large but finite); ``wo . h`` in ``G`` is floored at 1e-30
(:func:`_terms.v_cavity_g`; ``G`` depends on no parameter, so only its value matters);
D is evaluated in log space (:func:`_terms.beckmann_d`). Not energy conserving under
the independent bounds (``kd + ks F`` can exceed 1; the specular term alone, with
``ks <= 1`` and ``F <= 1``, keeps its albedo <= 1, except with ``fresnel="dielectric"``,
whose ``ks`` runs to 10 so that Löw et al.'s published fits lie inside the bounds: there
only ``ks F(1)`` is small). Reciprocal (``wo . h = wi . h``),
isotropic.
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
KS = Parameter("ks", (3,), (0.0, 1.0), 0.5, "logit", "specular weight s, RGB", linear=True)
M = Parameter("m", (), (1e-4, 2.0), 0.2, "log", "Beckmann rms slope m, unitless")
# f0 enters affinely alone but multiplies ks, so it is not marked linear (a joint linear
# solve over ks and f0 would be wrong).
F0 = Parameter(
    "f0", (3,), (0.0, 1.0), 0.04, "logit", "Schlick reflectance at normal incidence",
    neutral=_terms.DIELECTRIC_F0,
)  # fmt: skip
# The exact dielectric Fresnel: F(1) = ((eta - 1)/(eta + 1))^2 is 0.04 at eta = 1.5, so the
# lobe's weight goes past 1 while ks F(1), its normal-incidence share, stays small (Löw et
# al. 2012 publish ks = 4 x 0.34 = 1.36 for MERL materials; 10 is room, not physics: ks F(1)
# reaches 1 at eta = 1.92). eta reaches 10: Löw's fits of
# metallic paints put it at 9.1-9.8, a dielectric stand-in for a conductor's high F(1).
KS_D = Parameter("ks", (3,), (0.0, 10.0), 1.0, "logit", "specular weight s, RGB", linear=True)
ETA_D = Parameter(
    "eta", (), (1.01, 10.0), 1.5, "log", "relative index of refraction, unitless",
    neutral=_terms.DIELECTRIC_ETA,
)  # fmt: skip
ETA_C = Parameter("eta", (3,), (0.01, 6.0), 0.2, "log", "real part of the complex index, RGB")
K_C = Parameter("k", (3,), (1e-3, 15.0), 3.0, "log", "extinction coefficient k, RGB")
FRESNEL = ("schlick", "dielectric", "conductor")


@final
class CookTorrance(AbstractModel):
    """Beckmann microfacet lobe with V-cavity masking, exact or Schlick Fresnel, and Lambert."""

    fresnel: Literal["schlick", "dielectric", "conductor"] = eqx.field(
        static=True, default="schlick"
    )
    diffuse: bool = eqx.field(static=True, default=True)

    name: ClassVar[str] = "cook_torrance"
    reference: ClassVar[str] = "Cook, Torrance 1982, A reflectance model for computer graphics"
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    def __check_init__(self) -> None:
        if self.fresnel not in FRESNEL:
            raise ValueError(f"cook_torrance: fresnel {self.fresnel!r} not one of {FRESNEL}")

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        fresnel = {"schlick": (F0,), "dielectric": (ETA_D,), "conductor": (ETA_C, K_C)}
        ks = KS_D if self.fresnel == "dielectric" else KS
        return ((KD,) if self.diffuse else ()) + (ks, M) + fresnel[self.fresnel]

    def fresnel_term(self, params: Params, cos_d: jax.Array) -> jax.Array:
        """F at the facet incidence cosine ``wo . h``, (N, 3) or (N, 1) for a scalar index."""
        if self.fresnel == "schlick":
            return _terms.schlick_fresnel(params["f0"], cos_d)
        if self.fresnel == "dielectric":
            return _terms.fresnel_dielectric(cos_d, params["eta"])[:, None]
        return _terms.fresnel_conductor(
            cos_d[:, None], params["eta"][None, :], params["k"][None, :]
        )

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        d = _terms.beckmann_d(g.h, params["m"], params["m"])
        masking = _terms.v_cavity_g(g.cos_h, g.cos_i, g.cos_o, g.cos_d)
        lobe = d * masking / (4.0 * g.cos_i * g.cos_o)
        f = params["ks"][None, :] * self.fresnel_term(params, g.cos_d) * lobe[:, None]
        if self.diffuse:
            f = f + _terms.lambert(params["kd"])
        return f
