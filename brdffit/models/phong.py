"""Modified Phong (Lewis 1994, "Making shaders more physically plausible", Computer
Graphics Forum 13(2)), energy-normalised, with a Lambert diffuse term.

    f(wi, wo) = kd / pi + ks (n + 2) / (2 pi) max(0, cos alpha)^n

``alpha`` is the angle between ``wo`` and the mirror direction of ``wi`` about the
normal, ``r = (-wi.x, -wi.y, wi.z)``, so ``cos alpha = r . wo = wi.z wo.z - wi.x wo.x -
wi.y wo.y``: symmetric in (wi, wo), hence reciprocal (Phong 1975's lobe was a radiance,
i.e. a BRDF ``cos^n alpha / cos_i``; Lewis's BRDF form drops the ``1/cos_i``). The
factor ``(n + 2)/(2 pi)`` makes the lobe's directional albedo exactly ``ks`` at normal
incidence and smaller elsewhere (the lobe is cut by the horizon); Lewis shows that
``kd + ks <= 1`` then conserves energy. Here ``kd`` and ``ks`` have independent bounds
[0, 1] (so both stay linear and separately bounded), which lets ``kd + ks`` reach 2:
the model is flagged not energy conserving; it is not reparametrised.

Singularities and guards: ``cos^n`` is evaluated as ``exp(n log1p(-q))`` with
``q = 1 - cos alpha = |r - wo|^2 / 2`` (precise near the mirror direction, where the
lobe of a 1e5 exponent lives); ``q`` is replaced by 0 where ``q >= 1`` (``cos <= 0``)
before the log (double where), so the derivative in ``n`` stays finite there and the
lobe is exactly 0. Exponents reach 1e5 (optimised in log space). Isotropic.
"""

from __future__ import annotations

from typing import ClassVar, final

import jax
import jax.numpy as jnp

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models._terms import INV_PI, lambert

PARAMETERS = (
    Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo, RGB", linear=True),
    Parameter("ks", (3,), (0.0, 1.0), 0.2, "logit", "specular albedo, RGB", linear=True),
    Parameter("n", (), (1.0, 1e5), 50.0, "log", "Phong exponent, unitless"),
)


def one_minus_cos_mirror(wi: jax.Array, wo: jax.Array) -> jax.Array:
    """``1 - cos alpha = |r - wo|^2 / 2`` with ``r`` the mirror direction of ``wi``, (N,).

    Written from the difference vector so that it keeps its relative precision near the
    mirror direction, where ``cos alpha`` itself rounds to 1 (float32, n up to 1e5).
    """
    d = jnp.stack([wi[:, 0] + wo[:, 0], wi[:, 1] + wo[:, 1], wi[:, 2] - wo[:, 2]], axis=-1)
    return 0.5 * jnp.sum(d**2, axis=-1)


def phong_lobe(one_minus_cos: jax.Array, n: jax.Array) -> jax.Array:
    """Normalised Phong lobe ``(n + 2)/(2 pi) max(0, cos alpha)^n`` (1/sr), (N,)."""
    positive = one_minus_cos < 1.0
    q = jnp.where(positive, one_minus_cos, 0.0)
    power = jnp.where(positive, jnp.exp(n * jnp.log1p(-q)), 0.0)
    return (n + 2.0) * (0.5 * INV_PI) * power


@final
class Phong(AbstractModel):
    """Lambert plus Lewis's normalised Phong lobe around the mirror direction."""

    name: ClassVar[str] = "phong"
    reference: ClassVar[str] = (
        "Lewis 1994, Making shaders more physically plausible (after Phong 1975)"
    )
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return PARAMETERS

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        spec = phong_lobe(one_minus_cos_mirror(g.wi, g.wo), params["n"])
        return lambert(params["kd"]) + params["ks"][None, :] * spec[:, None]
