"""Lambert (1760): the ideal diffuse reflector.

    f(wi, wo) = kd / pi

``kd`` is the RGB albedo in [0, 1]; the directional albedo equals ``kd`` at every
incidence, so the model conserves energy. Reciprocal and isotropic.
"""

from __future__ import annotations

from typing import ClassVar, final

import jax
import jax.numpy as jnp

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models._terms import lambert

PARAMETERS = (
    Parameter("kd", (3,), (0.0, 1.0), 0.5, "logit", "diffuse albedo, RGB, unitless", linear=True),
)


@final
class Lambert(AbstractModel):
    """Constant BRDF ``kd / pi``."""

    name: ClassVar[str] = "lambert"
    reference: ClassVar[str] = "Lambert 1760, Photometria"
    channel_separable: ClassVar[bool] = True

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return PARAMETERS

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        return jnp.broadcast_to(lambert(params["kd"]), g.cos_i.shape + (3,))
