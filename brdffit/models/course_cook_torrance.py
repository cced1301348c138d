"""The Cook-Torrance/GGX BRDF of the course notes "Work Session 0: Physically Based
Rendering" (seed 002), which follow LearnOpenGL's "PBR - Theory" (de Vries 2014) and
Karis 2013, "Real Shading in Unreal Engine 4".

    f = k_d albedo / pi + D G F / (4 cos_o cos_i),   k_s = F,  k_d = 1 - k_s
    D = alpha^2 / (pi (cos_h^2 (alpha^2 - 1) + 1)^2),  alpha = roughness^2     (GGX)
    G = G1(cos_i) G1(cos_o),  G1(c) = c / (c (1 - k) + k),  k = (roughness + 1)^2 / 8
    F = F0 + (1 - F0)(1 - v.h)^5                                             (Schlick)

The seed writes ``alpha`` in ``D`` and ``roughness`` in the direct-lighting ``k``; as in
LearnOpenGL and Karis, ``alpha = roughness^2`` (the seed's alternative ``k = alpha/2`` is
the image-based-lighting one and is not used). ``F`` enters the specular term once: the
seed's ``k_s f_cook-torrance`` is read, as LearnOpenGL says, with ``k_s`` being the ``F``
already inside ``f_cook-torrance``. ``D`` is evaluated in the equivalent form
``1 / (pi alpha^2 ((hx^2 + hy^2)/alpha^2 + hz^2)^2)`` (``_terms.ggx_d``), free of the
``1 - cos_h^2`` cancellation.

``F0``: the seed leaves it a free symbol, so by default it is an RGB parameter ``f0``.
With ``metallic=True`` the LearnOpenGL metallic workflow replaces it:
``F0 = 0.04 (1 - metallic) + albedo metallic`` and ``k_d = (1 - F)(1 - metallic)``.

Linear parameters: ``albedo`` with a fixed ``f0`` (``f0`` alone is also affine, but not
jointly with ``albedo``: ``(1 - F) albedo``); none with ``metallic`` (``F0`` and ``k_d``
both hold ``albedo``).
Reciprocal: ``F`` depends on ``v.h = l.h`` only, and ``G`` is a symmetric product.
Singularities: ``1 / (4 cos_o cos_i)`` is cancelled to first order by ``G1(c) ~ c / k``
(``k >= 1/8``), so grazing values stay finite without LearnOpenGL's ``+ 1e-4``.
Not energy conserving under every parameter value (the Schlick-GGX ``G`` is not the
exact Smith one and ``k_d`` only follows ``F`` at the half vector), so it is not claimed.
"""

from __future__ import annotations

from typing import ClassVar, final

import equinox as eqx
import jax

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models import _terms

F0 = Parameter(
    "f0", (3,), (0.0, 1.0), 0.04, "logit", "Fresnel reflectance F0, RGB",
    neutral=_terms.DIELECTRIC_F0,
)  # fmt: skip
METALLIC = Parameter("metallic", (), (0.0, 1.0), 0.5, "logit", "metalness, unitless")
ROUGHNESS = Parameter("roughness", (), (0.01, 1.0), 0.5, "log", "roughness, alpha = roughness^2")


def schlick_ggx_g1(cos: jax.Array, k: jax.Array) -> jax.Array:
    """Schlick-GGX masking ``c / (c (1 - k) + k)``, (N,)."""
    return cos / (cos * (1.0 - k) + k)


@final
class CourseCookTorrance(AbstractModel):
    """Course-notes Cook-Torrance: GGX, Schlick-GGX Smith, Schlick F, ``(1 - F)`` Lambert."""

    metallic: bool = eqx.field(static=True, default=False)

    name: ClassVar[str] = "course_cook_torrance"
    reference: ClassVar[str] = "Course notes after LearnOpenGL PBR Theory (de Vries), Karis 2013"
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        albedo = Parameter(
            "albedo", (3,), (0.0, 1.0), 0.5, "logit", "albedo, RGB", linear=not self.metallic
        )
        return (albedo, METALLIC if self.metallic else F0, ROUGHNESS)

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        r, albedo = params["roughness"], params["albedo"]
        alpha = r**2
        k = (r + 1.0) ** 2 / 8.0
        d = _terms.ggx_d(g.h, alpha, alpha)
        gg = schlick_ggx_g1(g.cos_i, k) * schlick_ggx_g1(g.cos_o, k)
        if self.metallic:
            m = params["metallic"]
            f = _terms.schlick_fresnel(0.04 * (1.0 - m) + albedo * m, g.cos_d)
            kd = (1.0 - f) * (1.0 - m)
        else:
            f = _terms.schlick_fresnel(params["f0"], g.cos_d)
            kd = 1.0 - f
        spec = f * (d * gg / (4.0 * g.cos_o * g.cos_i))[:, None]
        return kd * _terms.lambert(albedo) + spec
