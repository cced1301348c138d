"""Lafortune, Foo, Torrance and Greenberg 1997, "Non-linear approximation of reflectance
functions" (SIGGRAPH): generalised cosine lobes, plus a Lambert diffuse term.

The paper's lobe is ``[Cx ux vx + Cy uy vy + Cz uz vz]^n`` (``u = wi``, ``v = wo`` in the
local frame), with the albedo folded into the size of the C's. We implement the common
fitting form with an RGB scale per lobe:

    f(wi, wo) = kd / pi
              + sum_l rho_l (n_l + 2) / (2 pi) max(0, cx_l ux vx + cy_l uy vy + uz vz)^n_l

* ``cx_l`` and ``cy_l`` are the paper's ratios ``Cx/Cz`` and ``Cy/Cz``. Three free C's and
  a free scale would be redundant (``C -> t C``, ``rho -> rho / t^n`` leaves ``f``
  unchanged), so ``Cz`` is absorbed into ``rho_l``: the paper's coefficients of a channel
  are ``(cx_l c, cy_l c, c)`` with ``c = (rho_l (n_l + 2) / (2 pi))^(1/n_l)``. Lobes with
  ``Cz <= 0`` (zero at normal incidence) are outside this form.
* ``cx = cy = -1`` is the normalised Phong lobe ``(wi . reflect(wo))^n`` (Lafortune and
  Willems 1994): ``(n + 2)/(2 pi)`` makes ``rho_l`` its directional albedo at normal
  incidence. ``cx = cy < -1`` grows toward grazing (off-specular peak), ``cx = cy > 0``
  is retro-reflective, ``cx != cy`` is anisotropic.
* Ratios are bounded to [-10, 10]: along mirror pairs the lobe grows as ``|cx|^n`` from
  normal incidence to grazing, so beyond 10 it is a pure grazing spike. Exponents span
  [0.1, 1e5] (broad lobes to near-mirror, optimised in log space).
* ``anisotropic=False`` (the paper's choice for isotropic materials) ties ``Cx = Cy``:
  one ratio ``cxy_l`` per lobe. ``n_lobes`` (>= 1) lobes are summed.

Singularities: the base is <= 0 away from the lobe; it is replaced by 1 before the log
and the lobe set to 0 there (double where). ``base^n`` is ``exp(n log base)``, exact in
float64 wherever the value is representable. Along mirror pairs ``base`` reaches
``max(|cx|, |cy|)`` at grazing angles, so with ``|c| > 1`` the lobe exceeds float64's
largest number (1.8e308 1/sr) once ``n ln|c| > 709``, inside the bounds (``n = 1e5`` with
``|c| = 1.01`` already does): there the value is ``+inf``, visibly, and a fit rejects
the point. No real material comes near it (measured BRDFs stay below ~1e5 1/sr). A lobe
whose scale ``rho`` is 0 contributes 0 even where the lobe overflows (not ``0 inf``).
Reciprocal (the base is symmetric in ``u`` and ``v``); not energy conserving (``|cx| > 1``
lobes and ``kd + rho`` up to 2 exceed albedo 1).
"""

from __future__ import annotations

from typing import ClassVar, final

import equinox as eqx
import jax
import jax.numpy as jnp

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models._terms import INV_PI, lambert

KD = Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo, RGB", linear=True)


def lobe_parameters(l: int, anisotropic: bool) -> tuple[Parameter, ...]:
    """Table rows of lobe ``l`` (1-based): ``rho_l``, the C ratios, ``n_l``.

    Default exponents differ per lobe (10, 40, 160, ... up to 5e4) so that a fit started
    from the defaults is not stuck at the symmetric point where every lobe is the same.
    """
    rho = Parameter(
        f"rho_{l}",
        (3,),
        (0.0, 1.0),
        0.2,
        "logit",
        f"lobe {l} scale, RGB: the albedo at normal incidence when cx = cy = -1",
        linear=True,
    )
    ratio = "ratio C{}/Cz of lobe " + str(l) + ", unitless (-1: Phong)"
    if anisotropic:
        cs = (
            Parameter(f"cx_{l}", (), (-10.0, 10.0), -1.0, "identity", ratio.format("x")),
            Parameter(f"cy_{l}", (), (-10.0, 10.0), -1.0, "identity", ratio.format("y")),
        )
    else:
        cs = (Parameter(f"cxy_{l}", (), (-10.0, 10.0), -1.0, "identity", ratio.format("x=Cy")),)
    n0 = min(10.0 * 4.0 ** (l - 1), 5e4)
    n = Parameter(f"n_{l}", (), (0.1, 1e5), n0, "log", f"lobe {l} exponent, unitless")
    return (rho, *cs, n)


def cosine_lobe(
    wi: jax.Array, wo: jax.Array, cx: jax.Array, cy: jax.Array, n: jax.Array
) -> jax.Array:
    """Normalised generalised cosine lobe ``(n+2)/(2 pi) max(0, base)^n`` (1/sr), (N,).

    ``base = cx ux vx + cy uy vy + uz vz``; ``+inf`` where the value exceeds float64.
    """
    base = cx * wi[:, 0] * wo[:, 0] + cy * wi[:, 1] * wo[:, 1] + wi[:, 2] * wo[:, 2]
    pos = base > 0.0
    log_base = jnp.log(jnp.where(pos, base, 1.0))
    lobe = (n + 2.0) * (0.5 * INV_PI) * jnp.exp(n * log_base)
    return jnp.where(pos, lobe, 0.0)


def scaled_lobe(rho: jax.Array, lobe: jax.Array) -> jax.Array:
    """``rho`` (3,) times ``lobe`` (N,), (N, 3), with ``0 inf`` read as 0 (no lobe, no value)."""
    finite = jnp.isfinite(lobe)
    product = rho[None, :] * jnp.where(finite, lobe, 0.0)[:, None]
    return jnp.where(finite[:, None], product, jnp.where(rho[None, :] > 0.0, jnp.inf, 0.0))


@final
class Lafortune(AbstractModel):
    """Lambert plus ``n_lobes`` generalised cosine lobes with RGB albedo each."""

    n_lobes: int = eqx.field(static=True, default=1)
    anisotropic: bool = eqx.field(static=True, default=False)

    name: ClassVar[str] = "lafortune"
    reference: ClassVar[str] = "Lafortune, Foo, Torrance, Greenberg 1997, SIGGRAPH"
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    def __check_init__(self) -> None:
        if not isinstance(self.n_lobes, int) or isinstance(self.n_lobes, bool) or self.n_lobes < 1:
            raise ValueError(f"lafortune: n_lobes {self.n_lobes!r} is not an integer >= 1")

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        lobes = (lobe_parameters(l, self.anisotropic) for l in range(1, self.n_lobes + 1))
        return (KD,) + sum(lobes, ())

    def ratios(self, params: Params, l: int) -> tuple[jax.Array, jax.Array]:
        """(cx, cy) of lobe ``l`` for either parametrisation."""
        if self.anisotropic:
            return params[f"cx_{l}"], params[f"cy_{l}"]
        return params[f"cxy_{l}"], params[f"cxy_{l}"]

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        f = lambert(params["kd"])
        for l in range(1, self.n_lobes + 1):
            cx, cy = self.ratios(params, l)
            lobe = cosine_lobe(g.wi, g.wo, cx, cy, params[f"n_{l}"])
            f = f + scaled_lobe(params[f"rho_{l}"], lobe)
        return f
