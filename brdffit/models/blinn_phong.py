"""Blinn-Phong (Blinn 1977), energy-normalised, with a Lambert diffuse term.

    f(wi, wo) = kd / pi + ks (n + 8) / (8 pi) (n . h)^n

The factor ``(n + 8) / (8 pi)`` is the usual normalisation (Akenine-Möller, Haines
and Hoffman, *Real-Time Rendering* 3rd ed., 2008, eq. 7.49) that keeps the
specular lobe's directional albedo near ``ks`` for any exponent. It is an
approximation: with ``kd + ks`` up to 2 under the independent bounds the sum can
exceed 1, so the model is flagged as not energy conserving. Exponents reach 1e6 for
near-mirror materials (Ngan et al. 2005 publish up to 1.21e5 for MERL's phenolics; the
exponent is optimised in log space). Reciprocal, isotropic.
"""

from __future__ import annotations

from typing import ClassVar, final

import jax

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models._terms import INV_PI, lambert

PARAMETERS = (
    Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo, RGB", linear=True),
    Parameter("ks", (3,), (0.0, 1.0), 0.2, "logit", "specular albedo, RGB", linear=True),
    Parameter("n", (), (1.0, 1e6), 50.0, "log", "Blinn exponent, unitless"),
)


def blinn_lobe(cos_h: jax.Array, n: jax.Array) -> jax.Array:
    """Normalised Blinn lobe ``(n + 8)/(8 pi) cos_h^n`` (1/sr), (N,)."""
    return (n + 8.0) * (0.125 * INV_PI) * cos_h**n


@final
class BlinnPhong(AbstractModel):
    """Lambert plus a normalised Blinn lobe around the half vector."""

    name: ClassVar[str] = "blinn_phong"
    reference: ClassVar[str] = (
        "Blinn 1977, Models of light reflection for computer synthesized pictures"
    )
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return PARAMETERS

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        spec = blinn_lobe(g.cos_h, params["n"])
        return lambert(params["kd"]) + params["ks"][None, :] * spec[:, None]
