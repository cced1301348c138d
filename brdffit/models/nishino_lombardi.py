"""Nishino 2009, "Directional statistics BRDF model" (ICCV), and Nishino and Lombardi 2011,
"Directional statistics-based reflectance model for isotropic BRDFs" (JOSA A 28(1)): the
hemispherical exponential power distribution (hemi-EPD) as a microfacet distribution.

The hemi-EPD of the papers is ``p(theta) = C (exp(kappa cos^gamma theta) - 1)`` with
``kappa < 0`` (so ``C < 0``); with ``k = -kappa > 0`` and ``m = gamma`` it is the form of
the seed table and of the Disney BRDF Explorer (``d_nishino.brdf``):

    D(h) = C(k, m) (1 - exp(-k cos^m theta_h)),   C(k, m) = m / (2 pi K(2/m, k))
    K(a, k) = int_0^inf exp(-a s) (1 - exp(-k exp(-s))) ds

``C`` normalises ``D`` as a microfacet distribution, ``int D cos theta_h dw = 1`` (the
papers normalise ``int p dw = 1`` instead; ``K`` comes from ``u = cos^m theta_h = e^-s``).
Small ``k`` gives the normalised Blinn lobe ``(m + 2)/(2 pi) cos^m``; large ``k`` flattens
its top. ``K`` has a closed form with incomplete gamma functions, ``(1/a - k^-a
gamma(a, k))``, which cancels catastrophically for small ``a`` (sharp lobes) or small ``k``;
it is computed by a fixed 96-node Gauss-Legendre rule on ``s in [0, S]``,
``S = (log max(k, 1) + 34)/(1 + a)`` (tail < e^-34 relative; rule error < 1e-11 over the bounds).

The papers fit the BRDF itself as ``sum_j (exp(kappa_j(theta_d) cos^gamma_j theta_h) - 1)``
with curves ``kappa(theta_d)``, ``gamma(theta_d)``, which absorb Fresnel and shadowing. We
use one lobe with constant ``k``, ``m`` in the microfacet form the comparison table gives:

    f(wi, wo) = kd / pi + ks F(wi . h) D(h) G(wi, wo) / (4 cos_i cos_o)

with Schlick ``F`` (RGB ``f0``) and the Cook-Torrance V-cavity ``G`` (the table's common
``G``); the table's ``pi`` in the denominator is read as the ``4`` of a normalised ``D``.
``ks`` is the table's specular weight rho_s (RGB); ``specular_weight=False`` removes it
(``ks = 1``). How ``ks`` and ``f0`` trade off, and why only the Fresnel rise at grazing
``theta_d`` tells them apart, is said in ``models/walter.py``. Affine in ``kd`` and
``ks`` (in ``kd`` and ``f0`` without ``ks``), solved linearly for each start of a fit.

Singularities: ``1/(cos_i cos_o)`` is cancelled to first order by ``G``;
``cos^m theta_h = exp(m log cos_h)`` with ``log cos_h`` accurate near the normal, and
``1 - exp(-x)`` is ``-expm1(-x)``. Reciprocal; isotropic; not energy conserving
(``kd`` and the specular term are added uncoupled).
"""

from __future__ import annotations

from typing import ClassVar, final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models._terms import (
    INV_PI,
    fresnel_rows,
    lambert,
    log_cos_theta_h,
    v_cavity_g,
    weighted_schlick,
)

KD = Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo, RGB", linear=True)
LOBE = (
    Parameter("k", (), (1e-3, 1e3), 1.0, "log", "hemi-EPD concentration -kappa, unitless"),
    Parameter("m", (), (0.1, 1e5), 100.0, "log", "hemi-EPD exponent gamma, unitless"),
)

_X, _W = np.polynomial.legendre.leggauss(96)
GL_NODES = tuple(float(x) for x in _X)
"""Gauss-Legendre nodes on [-1, 1] for :func:`normalisation_integral` (module constant)."""
GL_WEIGHTS = tuple(float(w) for w in _W)


def normalisation_integral(k: jax.Array, m: jax.Array) -> jax.Array:
    """``K(2/m, k) = int_0^inf exp(-2 s/m) (1 - exp(-k e^-s)) ds`` by Gauss-Legendre, ()."""
    a = 2.0 / m
    span = (jnp.log(jnp.maximum(k, 1.0)) + 34.0) / (1.0 + a)
    x = jnp.asarray(GL_NODES, k.dtype)
    w = jnp.asarray(GL_WEIGHTS, k.dtype)
    s = 0.5 * span * (x + 1.0)
    return 0.5 * span * jnp.sum(w * jnp.exp(-a * s) * -jnp.expm1(-k * jnp.exp(-s)))


def hemi_epd(h: jax.Array, k: jax.Array, m: jax.Array) -> jax.Array:
    """Normalised hemi-EPD ``D(h) = C(k, m)(1 - exp(-k cos^m theta_h))`` (1/sr), (N,)."""
    c = m * (0.5 * INV_PI) / normalisation_integral(k, m)
    return c * -jnp.expm1(-k * jnp.exp(m * log_cos_theta_h(h)))


@final
class NishinoLombardi(AbstractModel):
    """Lambert plus a weighted hemi-EPD microfacet lobe, Schlick Fresnel, V-cavity masking."""

    specular_weight: bool = eqx.field(static=True, default=True)

    name: ClassVar[str] = "nishino_lombardi"
    reference: ClassVar[str] = "Nishino 2009, ICCV; Nishino, Lombardi 2011, JOSA A 28(1)"
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return (KD, *fresnel_rows(self.specular_weight), *LOBE)

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        d = hemi_epd(g.h, params["k"], params["m"])
        gg = v_cavity_g(g.cos_h, g.cos_i, g.cos_o, g.cos_d)
        f = weighted_schlick(params, g.cos_d, self.specular_weight)
        return f * (d * gg / (4.0 * g.cos_i * g.cos_o))[:, None] + lambert(params["kd"])
