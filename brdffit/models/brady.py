"""Brady, Lawrence, Peers and Weimer 2014, "genBRDF: Discovering new analytic BRDFs with
genetic programming" (ACM TOG 33(4), SIGGRAPH 2014), in the form of the model table
(seed 004, row "2014 Brady"):

    f(wi, wo) = kd / pi + ks F(cos_d) / (4 cos_d) exp(-(tan(theta_h) / beta^2)^a)

with ``F = f0 + (1 - f0)(1 - cos_d)^5`` (Schlick, the table's common Fresnel), ``cos_d = wi.h``
(``L.H``) and ``a`` = ``exponent``.

Which form: the paper's own expressions ("BRDF A"/"BRDF B") could not be retrieved (searches
of public pages, documentation and code found the abstract and citations only), so this file
implements the table's form literally, with its two shape parameters (beta, a) and no variant
option. ``beta`` enters only through ``beta^2`` (the table's notation), which fixes its sign.

Normalisation is NOT claimed: ``exp(-(tan/beta^2)^a)`` is a peak-1 lobe, and
``int exp(.) cos(theta_h) d(omega_h) = 2 pi int_0^inf exp(-(t/beta^2)^a) t / (1 + t^2)^2 dt``,
close to ``2 pi beta^4 Gamma(2/a) / a`` for narrow lobes (checked by quadrature in the
test). So ``ks`` is a peak scale (1/sr per unit lobe), not an albedo, and must reach 1e4 for
mirror-like metals: it is bounded below by 0 only. ``1/(4 cos_d)`` is the half-vector
Jacobian, so ``ks F lobe`` integrates like a distribution of normals.

Guards: ``tan^2 = (h_x^2 + h_y^2) / h_z^2`` is raised to ``a/2`` in log space; where
``h_x^2 + h_y^2`` is 0 (h = n, e.g. wi = wo = n) the lobe is exactly 1 (double where); the
exponent is capped at 750 (``exp(-750)`` = 0 in float64 and float32) so that overflow in
float32 cannot meet a zero as NaN in the gradient. ``cos_d`` and ``h_z`` are > 0 for every
pair above the horizon. Reciprocal (h and cos_d are symmetric), isotropic; not energy
conserving (``ks`` unbounded, the lobe unnormalised, ``kd`` added uncoupled).

Identifiability: all five parameters in principle (``f0`` only through the grazing
``(1 - cos_d)^5`` shape, so it is weakly determined away from grazing data).
"""

from __future__ import annotations

import math
from typing import ClassVar, final

import jax
import jax.numpy as jnp

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models._terms import DIELECTRIC_F0, lambert

PARAMETERS = (
    Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo rho_d, RGB", linear=True),
    Parameter(
        "ks",
        (3,),
        (0.0, math.inf),
        1.0,
        "log",
        "specular scale rho_s, RGB, 1/sr at the peak (not an albedo)",
        linear=True,
    ),
    Parameter(
        "f0",
        (),
        (0.0, 1.0),
        0.04,
        "logit",
        "Schlick reflectance at normal incidence",
        neutral=DIELECTRIC_F0,
    ),
    Parameter("beta", (), (1e-2, 2.0), 0.3, "log", "lobe width; tan(theta_h) scale is beta^2"),
    Parameter("exponent", (), (0.2, 8.0), 1.0, "log", "lobe shape exponent a, unitless"),
)


def brady_lobe(sin2_h: jax.Array, cos_h: jax.Array, beta: jax.Array, a: jax.Array) -> jax.Array:
    """``exp(-(tan(theta_h) / beta^2)^a)``, unitless, (N,); 1 at ``theta_h = 0``."""
    pos = sin2_h > jnp.finfo(sin2_h.dtype).tiny
    s = jnp.where(pos, sin2_h, 1.0)
    log_x = a * (0.5 * jnp.log(s) - jnp.log(cos_h) - 2.0 * jnp.log(beta))
    x = jnp.exp(jnp.minimum(log_x, 6.62))  # e^6.62 > 749: exp(-x) is 0 beyond the cap
    return jnp.where(pos, jnp.exp(-x), 1.0)


def schlick_scalar(f0: jax.Array, cos_d: jax.Array) -> jax.Array:
    """Schlick ``f0 + (1 - f0)(1 - cos_d)^5`` for a scalar ``f0``, (N,)."""
    return f0 + (1.0 - f0) * (1.0 - cos_d) ** 5


@final
class Brady(AbstractModel):
    """genBRDF lobe of the model table: Lambert plus ``ks F exp(-(tan/beta^2)^a) / (4 cos_d)``."""

    name: ClassVar[str] = "brady"
    reference: ClassVar[str] = "Brady, Lawrence, Peers, Weimer 2014, genBRDF, ACM TOG 33(4)"
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return PARAMETERS

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        sin2_h = g.h[:, 0] ** 2 + g.h[:, 1] ** 2
        lobe = brady_lobe(sin2_h, g.cos_h, params["beta"], params["exponent"])
        spec = schlick_scalar(params["f0"], g.cos_d) * lobe / (4.0 * g.cos_d)
        return lambert(params["kd"]) + params["ks"][None, :] * spec[:, None]
