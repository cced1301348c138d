"""Kurt, Szirmay-Kalos and Křivánek 2010, "An anisotropic BRDF model for fitting and Monte
Carlo rendering" (ACM SIGGRAPH Computer Graphics 44(1)), with a Lambert diffuse term.

    f(wi, wo) = kd / pi + sum_l ks_l F_l(wi . h) D_l(h) / (4 (wi . h) (cos_i cos_o)^alpha_l)

* ``D_l``: anisotropic Beckmann, ``exp(-((hx/mx)^2 + (hy/my)^2)/hz^2) / (pi mx my hz^4)``,
  normalised (``int D cos theta_h dw = 1``); ``anisotropic=False`` ties ``mx = my = m``.
* ``F_l``: Schlick, ``f0 + (1 - f0)(1 - wi . h)^5`` with a scalar ``f0_l``; the colour is
  in the RGB scale ``ks_l``. ``f`` is affine in ``kd`` and every ``ks_l`` (flagged
  ``linear``), but ``ks_l F_l`` is bilinear, so ``f0_l`` is not.
* ``alpha_l`` in [0, 1] replaces the shadowing/foreshortening term: ``alpha = 1`` is the
  Cook-Torrance ``1/(cos_i cos_o)`` without ``G``, ``alpha = 1/2`` Ward's
  ``1/sqrt(cos_i cos_o)``, ``alpha = 0`` a pure half-vector lobe. ``n_lobes`` (>= 1)
  lobes are summed; the paper fits MERL materials with one or two.

Identifiability: ``alpha_l`` and the roughness both shape the lobe away from the mirror
direction (``alpha`` through ``cos_i cos_o``, roughness through ``theta_h``): they are
strongly correlated, and ``f0_l`` acts only near grazing where ``alpha_l`` also acts. Fits
determine them poorly from data cut at 80 degrees, though each is identifiable in principle.

Singularities: ``(cos_i cos_o)^-alpha`` grows to 1e12 at cos 1e-6 (alpha = 1): evaluated as
``exp(-alpha (log cos_i + log cos_o))`` (cosines are > 0 above the horizon), finite in
float32; compare ``f cos_i`` at grazing angles. Beckmann is evaluated in log space
(``_terms.beckmann_d``). Reciprocal (every factor is symmetric in ``wi``, ``wo``); not energy
conserving (``alpha = 1`` diverges at grazing incidence like Cook-Torrance without ``G``).
"""

from __future__ import annotations

from typing import ClassVar, final

import equinox as eqx
import jax
import jax.numpy as jnp

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models._terms import DIELECTRIC_F0, beckmann_d, lambert

KD = Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo, RGB", linear=True)


def lobe_parameters(l: int, anisotropic: bool) -> tuple[Parameter, ...]:
    """Table rows of lobe ``l`` (1-based): ``ks_l``, ``f0_l``, roughness, ``alpha_l``.

    Default roughness shrinks 4x per lobe (down to 1e-3) so that a fit started from the
    defaults is not stuck at the symmetric point where every lobe is the same.
    """
    m0 = max(0.3 / 4.0 ** (l - 1), 1e-3)
    ks = Parameter(
        f"ks_{l}", (3,), (0.0, 1.0), 0.3, "logit", f"lobe {l} specular scale, RGB", linear=True
    )
    f0 = Parameter(
        f"f0_{l}", (), (0.0, 1.0), 0.1, "logit", f"lobe {l} Schlick F0, unitless",
        neutral=DIELECTRIC_F0,
    )  # fmt: skip
    if anisotropic:
        rough = (
            Parameter(
                f"mx_{l}", (), (1e-4, 2.0), m0, "log", f"lobe {l} Beckmann roughness along x"
            ),
            Parameter(
                f"my_{l}", (), (1e-4, 2.0), m0, "log", f"lobe {l} Beckmann roughness along y"
            ),
        )
    else:
        rough = (Parameter(f"m_{l}", (), (1e-4, 2.0), m0, "log", f"lobe {l} Beckmann roughness"),)
    alpha = Parameter(
        f"alpha_{l}", (), (0.0, 1.0), 0.5, "logit", f"lobe {l} exponent of 1/(cos_i cos_o)"
    )
    return (ks, f0, *rough, alpha)


def schlick_scalar(f0: jax.Array, cos_d: jax.Array) -> jax.Array:
    """Schlick's Fresnel with a scalar ``f0``: ``f0 + (1 - f0)(1 - cos_d)^5``, (N,)."""
    return f0 + (1.0 - f0) * (1.0 - cos_d) ** 5


def foreshortening(cos_i: jax.Array, cos_o: jax.Array, alpha: jax.Array) -> jax.Array:
    """``(cos_i cos_o)^-alpha`` in log space, (N,); cosines are > 0 above the horizon."""
    return jnp.exp(-alpha * (jnp.log(cos_i) + jnp.log(cos_o)))


@final
class Kurt(AbstractModel):
    """Lambert plus ``n_lobes`` Beckmann lobes with Schlick Fresnel and the alpha exponent."""

    n_lobes: int = eqx.field(static=True, default=1)
    anisotropic: bool = eqx.field(static=True, default=False)

    name: ClassVar[str] = "kurt"
    reference: ClassVar[str] = "Kurt, Szirmay-Kalos, Krivanek 2010, SIGGRAPH Comput. Graph. 44(1)"
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    def __check_init__(self) -> None:
        if not isinstance(self.n_lobes, int) or isinstance(self.n_lobes, bool) or self.n_lobes < 1:
            raise ValueError(f"kurt: n_lobes {self.n_lobes!r} is not an integer >= 1")

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        lobes = (lobe_parameters(l, self.anisotropic) for l in range(1, self.n_lobes + 1))
        return (KD,) + sum(lobes, ())

    def roughness(self, params: Params, l: int) -> tuple[jax.Array, jax.Array]:
        """(mx, my) of lobe ``l`` for either parametrisation."""
        if self.anisotropic:
            return params[f"mx_{l}"], params[f"my_{l}"]
        return params[f"m_{l}"], params[f"m_{l}"]

    def ndf(self, params: Params, l: int, h: jax.Array) -> jax.Array:
        """Beckmann distribution ``D_l(h)`` of lobe ``l`` (1/sr), (N,)."""
        return beckmann_d(h, *self.roughness(params, l))

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        f = lambert(params["kd"])
        for l in range(1, self.n_lobes + 1):
            lobe = (
                schlick_scalar(params[f"f0_{l}"], g.cos_d)
                * self.ndf(params, l, g.h)
                * foreshortening(g.cos_i, g.cos_o, params[f"alpha_{l}"])
                / (4.0 * g.cos_d)
            )
            f = f + params[f"ks_{l}"][None, :] * lobe[:, None]
        return f
