"""Bagher, Soler and Holzschuch 2012, "Accurate fitting of measured reflectances using a
Shifted Gamma micro-facet distribution", Computer Graphics Forum 31(4) (EGSR 2012).

    f(wi, wo) = kd / pi + ks F(cos_d) D(h) G1(wi) G1(wo) / (pi cos_i cos_o)

* ``D``, the Shifted Gamma Distribution (SGD) of slopes, with ``x = tan^2 theta_h`` and
  ``g = alpha + x / alpha`` (the shifted gamma variable, ``g >= alpha``):

      D(h) = K exp(-g) g^-p / (pi cos^4 theta_h),   K = 1 / (alpha Gamma(1 - p, alpha))

  (the paper's ``K_ap exp(-(alpha^2 + x)/alpha) / (alpha^2 + x)^p`` slope law with its
  ``alpha^p`` folded into ``K``). ``int D cos theta_h dw = 1``: the slope integral is
  ``alpha int_alpha^inf e^-g g^-p dg = alpha Gamma(1 - p, alpha)``. The ``K`` the authors
  published with their MERL fits is this constant to all printed digits (checked in the
  tests). ``p = 0`` is Beckmann with ``alpha_b^2 = alpha``; larger ``p`` lifts the tail.
* ``Gamma(a, x)`` (upper incomplete, ``a = 1 - p`` in [-1, 1], where
  ``jax.scipy.special.gammaincc`` (a > 0 only) and the recurrence (cancels near a = 0)
  fail): ``int_{ln x}^{ln 50} exp(a s - e^s) ds`` by 64-node Gauss-Legendre (tail
  ``< e^-50``; relative error < 1e-13 against mpmath over the bounds).
* ``G1 = 1 / (1 + Lambda)``: Smith's masking for this distribution, computed exactly (no
  closed form exists). For a direction with ``q = alpha tan^2 theta`` (``u = alpha + 1/q``):

      Lambda = 1 / (pi Gamma(1 - p, alpha)) int_0^inf H(sqrt(q s)) exp(-(u + s)) (u + s)^-p ds

  with ``H(y) = y - arctan y``. This is Smith's ``(1/cot) int_{slope_x > cot} (slope_x -
  cot) P22 d^2slope`` in polar slope coordinates, ``r^2 = alpha (u + s) - alpha^2``. The
  quadrature (:func:`smith_lambda`) is the trapezoid rule in ``t = ln s`` with 128 nodes
  from ``t_lo`` (where the neglected left tail is < 1e-16 relative, from its ``s^1.5`` /
  ``s^2.5`` decay) to ``ln 40``; the integrand is analytic in the strip ``|Im t| < pi/2``
  and negligible at both ends, so the rule converges geometrically: G1 within 2e-14 of
  mpmath and of the Beckmann closed form (p = 0) over the bounds, grazing included (tests).
* The model does not run that quadrature per sample (128 nodes x 2 directions x 10^6
  samples, times the Jacobian's tangents, is 100 GB). For given ``alpha, p``, ``Lambda``
  is a function of one variable, ``x = 1/sqrt(q) = cot theta / sqrt(alpha)``. Once per
  evaluation the quadrature tabulates ``y = ln(Lambda e^u u^p)`` (the exponential decay
  at normal incidence divided out, so that ``y`` is smooth: ``~ -3 ln x`` at normal
  incidence, ``~ -ln x`` at grazing) and its derivative at :data:`TABLE_NODES`
  equispaced ``tau = ln x`` on :data:`TABLE_TAU`; each sample reads it by cubic Hermite
  interpolation (:func:`smith_lambda_table`): C1, differentiable in ``alpha, p`` through
  the table and through ``x``, error ``h^4 max|y''''| / 384``, measured < 2e-8 in ``ln
  Lambda`` over the bounds (tests). The quadrature itself runs only at the Chebyshev
  nodes of :data:`TABLE_PANELS` panels (:data:`PANEL_NODES` each); the table's values
  and slopes are the panels' Chebyshev interpolants there (one constant linear map,
  :func:`panel_maps`), exact to about 1e-11, far below the Hermite error. Below ``x0 =
  e^-15`` (within ``3e-7 sqrt(alpha)`` rad of grazing) it uses the grazing expansion
  ``Lambda = A/x - 1/2 + O(x)`` through the table's first node, ``Lambda = (Lambda(x0) +
  1/2) x0 / x - 1/2`` (from ``H(y) = y - pi/2 + arctan(1/y)``; the constant is ``-(pi/2)
  Gamma(1-p, u) / (pi Gamma(1-p, alpha))`` at ``u = alpha``), error ``O(x0^2)``,
  measured < 1e-8.
* ``F = F0 - F1 cos_d + (1 - F0)(1 - cos_d)^5``: Schlick with the paper's extra linear
  term (as in the authors' released code), floored at 0 (``F >= 0`` holds whenever
  ``F1 <= F0``, which a box cannot express).

Which form: the paper's shadowing is a per-material empirical curve ``G1(theta) = 1 +
Lambda'(1 - exp(c (theta - theta0)^k))`` with four more fitted parameters per channel
(their released fits; e.g. ``c = 1e84``), not an approximation of stated accuracy to the
Smith term of ``D``. We use the exact Smith term instead: it follows from ``alpha, p``,
adds no parameter and keeps the model reciprocal and identifiable. The ``pi`` (not
``4``) in the denominator is the one of the authors' released evaluation code and of
independent reimplementations (dj_brdf, bsdfbenchmark ``bagher.h``), so ``kd``, ``ks``,
``alpha``, ``p``, ``F0``, ``F1`` are the paper's parameters (ks of the ``4 cos_i cos_o``
form is ``4/pi`` of ours); fits made with the paper's G1 differ in ks, F0, F1.

Parameters: ``kd``, ``ks`` RGB and affine (solved linearly); ``F0``, ``F1`` RGB as in the
paper (metal Fresnel is coloured). ``alpha``, ``p`` are scalars by default: one
microsurface for all channels, and one Lambda table per evaluation; the paper fits
them per channel, available as ``rgb_lobe=True`` (three tables).

Guards: ``D`` and the quadrature terms are exponentials of sums evaluated in log space;
``ln D`` is floored at -750 (D = 0 in float64 and float32 there, zero gradient instead of
0 * inf). ``q`` is floored at 1/800 (Lambda < e^-800, i.e. 0; normal incidence has q = 0).
``H`` uses its series ``y^3 (1/3 - y^2/5 + ...)`` below 0.2 (double where).
``1/(cos_i cos_o)`` is cancelled by ``G1 ~ cos`` at grazing. Reciprocal, isotropic; not
energy conserving (kd and ks uncoupled, ks unbounded).
"""

from __future__ import annotations

import math
from typing import ClassVar, final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.models._terms import DIELECTRIC_F0, INV_PI, lambert

KD = Parameter("kd", (3,), (0.0, 1.0), 0.3, "logit", "diffuse albedo rho_d, RGB", linear=True)
KS = Parameter(
    "ks",
    (3,),
    (0.0, math.inf),
    0.3,
    "log",
    "specular scale rho_s, RGB (4 ks / pi is the lobe's albedo at normal incidence, F = G = 1)",
    linear=True,
)
F0 = Parameter(
    "f0", (3,), (0.0, 1.0), 0.1, "logit", "Fresnel F0 (Schlick base), RGB", neutral=DIELECTRIC_F0
)
F1 = Parameter(
    "f1", (3,), (-1.0, 1.0), 0.0, "logit", "Fresnel F1 (linear term), RGB",
    neutral=0.0,  # F1 = 0 is Schlick's Fresnel
)  # fmt: skip
SHAPE = {
    "alpha": ((1e-5, 2.0), 0.05, "log", "SGD roughness alpha (slope scale sqrt(alpha))"),
    "p": ((0.0, 2.0), 0.5, "logit", "SGD shift exponent p (0: Beckmann; tail weight)"),
}

_XG, _WG = np.polynomial.legendre.leggauss(64)
GAMMA_NODES = tuple(float(x) for x in _XG)
"""Gauss-Legendre nodes on [-1, 1] for :func:`upper_gamma` (module constant)."""
GAMMA_WEIGHTS = tuple(float(w) for w in _WG)
LAMBDA_NODES = 128
"""Trapezoid nodes of the Smith Lambda quadrature (:func:`smith_lambda`)."""
TABLE_NODES = 512
"""Nodes of the Lambda table in ``tau`` (:func:`lambda_table`): spacing 0.036; the cubic
Hermite error, ``~ h^4``, measured 2e-8 in ``ln Lambda`` (1.4e-7 with 384 nodes)."""
TABLE_TAU = (-15.0, 0.5 * math.log(800.0))
"""Range of ``tau = ln(cot theta / sqrt(alpha))`` tabulated: below it the grazing expansion
(error ``~ e^(2 tau) / alpha``: 1e-4 from -10, < 1e-8 from -15, ``alpha >= 1e-5``); above
it ``q < 1/800`` is floored (``Lambda < e^-800``, i.e. 0)."""
TABLE_PANELS = 4
"""Panels of equal width (4.59 in ``tau``) on which :func:`panel_maps` interpolates ``y``."""
PANEL_NODES = 40
"""Chebyshev nodes (first kind) per panel. Why 40: ``y(tau)`` is analytic in the strip
``|Im tau| < pi/2`` (``sqrt(q s)`` meets arctan's poles ``+-i`` where ``q s = -1``, ``q =
e^(-2 tau)``), so on a panel of half-width ``w = 2.29`` the interpolant's error falls like
``rho^-n`` with ``rho = (pi/2)/w + sqrt(1 + ((pi/2)/w)^2) = 1.90`` (the Bernstein ellipse
inside that strip; Trefethen, *Approximation Theory and Approximation Practice*, ch. 8):
``1.90^-40 = 7e-12``. Measured over the bounds: slopes within 4e-11 of forward mode
through the quadrature (32 nodes: 8e-9; 24: 2e-6), ``Lambda`` as accurate as the old
512-node quadrature table (1.6e-8, the Hermite error)."""
_H_SERIES = tuple((-1.0) ** (k + 1) / (2 * k + 1) for k in range(1, 12))


def _last(x: jax.Array) -> jax.Array:
    """``x`` with a trailing axis for quadrature nodes (a 0-d ``x`` stays 0-d)."""
    return x[..., None] if x.ndim else x


def _nodes(values: tuple[float, ...], like: jax.Array) -> jax.Array:
    """Quadrature constants on the last axis, ranked to broadcast against ``_last(like)``."""
    return jnp.asarray(values, like.dtype).reshape((1,) * like.ndim + (-1,))


def upper_gamma(a: jax.Array, x: jax.Array) -> jax.Array:
    """Upper incomplete gamma ``Gamma(a, x) = int_x^inf t^(a-1) e^-t dt`` for any real ``a``.

    For ``x`` in [1e-5, 2] and ``a`` in [-1, 1] (the model's range): ``t = e^s`` and
    64-node Gauss-Legendre on ``s`` in ``[ln x, ln 50]``. Broadcasts; node axis last.
    """
    lo, hi = _last(jnp.log(x)), math.log(50.0)
    s = 0.5 * (hi - lo) * _nodes(GAMMA_NODES, x) + 0.5 * (hi + lo)
    terms = _nodes(GAMMA_WEIGHTS, x) * jnp.exp(_last(a) * s - jnp.exp(s))
    return 0.5 * (hi - jnp.log(x)) * jnp.sum(terms, -1)


def log_norm(alpha: jax.Array, p: jax.Array) -> jax.Array:
    """``ln(pi alpha Gamma(1 - p, alpha))``, the log of ``pi / K``."""
    return jnp.log(jnp.pi * alpha * upper_gamma(1.0 - p, alpha))


def sgd_ndf(tan2: jax.Array, cos_h: jax.Array, alpha: jax.Array, p: jax.Array) -> jax.Array:
    """Normalised SGD ``D = exp(-g) g^-p / (pi alpha Gamma(1-p, alpha) cos^4)`` (1/sr).

    ``g = alpha + tan2 / alpha``; arguments broadcast (``tan2``, ``cos_h`` per sample).
    """
    g = alpha + tan2 / alpha
    log_d = -g - p * jnp.log(g) - log_norm(alpha, p) - 4.0 * jnp.log(cos_h)
    return jnp.exp(jnp.maximum(log_d, -750.0))


def arctan_defect(y: jax.Array) -> jax.Array:
    """``H(y) = y - arctan(y)`` for ``y >= 0``, with its series below 0.2 (no cancellation)."""
    small = y < 0.2
    ys = jnp.where(small, y, 0.0)
    acc = jnp.zeros_like(ys)
    for c in reversed(_H_SERIES):
        acc = acc * ys**2 + c
    yl = jnp.where(small, 1.0, y)
    return jnp.where(small, ys**3 * acc, yl - jnp.arctan(yl))


def scaled_log_lambda(q: jax.Array, alpha: jax.Array, p: jax.Array) -> jax.Array:
    """``ln(Lambda e^u u^p)`` with ``u = alpha + 1/q``: Smith's ``Lambda`` (module docstring)
    with its decay at normal incidence divided out, by the trapezoid rule in ``t = ln s``
    (:data:`LAMBDA_NODES` nodes). Arguments broadcast, node axis last."""
    q = jnp.maximum(q, 1.0 / 800.0)
    u = alpha + 1.0 / q
    big = jnp.log(jnp.minimum(u, 1.0))  # ln of the smallest scale of the bulk
    t_lo = big - 14.8 - 0.4 * jnp.clip(big + jnp.log(q), 0.0, 24.7)
    dt = (math.log(40.0) - t_lo) / LAMBDA_NODES
    k = _nodes(tuple(j + 0.5 for j in range(LAMBDA_NODES)), q)
    t = t_lo[..., None] + dt[..., None] * k
    s = jnp.exp(t)  # exp(-(u + s)) (u + s)^-p = e^-u u^-p exp(-s) (1 + s/u)^-p
    terms = arctan_defect(jnp.sqrt(q[..., None] * s)) * jnp.exp(
        t - s - _last(p) * jnp.log1p(s / u[..., None])
    )
    return jnp.log(dt * jnp.sum(terms, -1) / (jnp.pi * upper_gamma(1.0 - p, alpha)))


def smith_lambda(q: jax.Array, alpha: jax.Array, p: jax.Array) -> jax.Array:
    """Smith ``Lambda`` of the SGD at ``q = alpha tan^2 theta`` by quadrature, unitless.

    :func:`scaled_log_lambda` times ``e^-u u^-p``; the reference the table is built from.
    Arguments broadcast.
    """
    u = alpha + 1.0 / jnp.maximum(q, 1.0 / 800.0)
    return jnp.exp(scaled_log_lambda(q, alpha, p) - u - p * jnp.log(u))


def panel_maps() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The quadrature's nodes and the linear maps from ``y`` there to the table.

    Returns ``tau`` at the Chebyshev nodes of :data:`TABLE_PANELS` equal panels of
    :data:`TABLE_TAU` (``TABLE_PANELS * PANEL_NODES``,), and ``values``, ``slopes``
    (``TABLE_NODES``, ``TABLE_PANELS * PANEL_NODES``): each panel's Chebyshev
    interpolant, and its derivative in ``tau``, at the table nodes in that panel.
    """
    cheb = np.polynomial.chebyshev
    k = PANEL_NODES
    x = cheb.chebpts1(k)
    to_coef = np.linalg.inv(cheb.chebvander(x, k - 1))
    derive = cheb.chebder(np.eye(k), axis=0)  # coefficients -> derivative's (k - 1, k)
    grid = np.linspace(*TABLE_TAU, TABLE_NODES)
    edges = np.linspace(*TABLE_TAU, TABLE_PANELS + 1)
    panel = np.minimum(np.searchsorted(edges, grid, side="right") - 1, TABLE_PANELS - 1)
    nodes = np.empty(TABLE_PANELS * k)
    values = np.zeros((TABLE_NODES, TABLE_PANELS * k))
    slopes = np.zeros_like(values)
    for j in range(TABLE_PANELS):
        mid, half = 0.5 * (edges[j] + edges[j + 1]), 0.5 * (edges[j + 1] - edges[j])
        cols, rows = slice(j * k, (j + 1) * k), panel == j
        nodes[cols] = mid + half * x
        t = (grid[rows] - mid) / half
        values[rows, cols] = cheb.chebvander(t, k - 1) @ to_coef
        slopes[rows, cols] = cheb.chebvander(t, k - 2) @ derive @ to_coef / half
    return nodes, values, slopes


_PANEL_TAU, _VALUES, _SLOPES = panel_maps()


def _table(alpha: jax.Array, p: jax.Array) -> tuple[jax.Array, jax.Array]:
    """``y = ln(Lambda e^u u^p)`` and ``dy/dtau`` at the table nodes (module docstring).

    ``tau = ln x``, ``x = cot theta / sqrt(alpha) = 1/sqrt(q)``: :data:`TABLE_NODES`
    equispaced nodes on :data:`TABLE_TAU`, interpolated from the quadrature at the
    panels' Chebyshev nodes (:func:`panel_maps`). Each of shape ``alpha.shape +
    (TABLE_NODES,)``. Its own JVP rule differentiates the quadrature in ``alpha`` and
    ``p`` once, in one direction each, whatever the number of tangents the caller pushes
    (a fit's Jacobian pushes one per colour of its compressed form,
    :mod:`brdffit.engine.jacobian`: 6 for SGD's 14 scalars). The dense maps hold the panels'
    block-diagonal ones: four 128 x 40 blocks kept per panel instead evaluated no faster
    (30-34 ms for 64 walkers on 2,266 samples either way), and a fresh process's first
    call took as long (0.69-0.80 s either way).
    """
    dtype = jnp.result_type(alpha)
    tau = jnp.broadcast_to(jnp.asarray(_PANEL_TAU, dtype), jnp.shape(alpha) + _PANEL_TAU.shape)
    y = scaled_log_lambda(jnp.exp(-2.0 * tau), _last(alpha), _last(p))
    return y @ jnp.asarray(_VALUES.T, dtype), y @ jnp.asarray(_SLOPES.T, dtype)


lambda_table = jax.custom_jvp(_table)


@lambda_table.defjvp
def _lambda_table_jvp(primals: tuple, tangents: tuple) -> tuple:
    alpha, p = primals
    da, dp = tangents
    # each channel's table depends on its own alpha, p only: one direction each suffices
    out, by_alpha = jax.jvp(lambda a: _table(a, p), (alpha,), (jnp.ones_like(alpha),))
    by_p = jax.jvp(lambda pp: _table(alpha, pp), (p,), (jnp.ones_like(p),))[1]
    tan = tuple(ya * _last(da) + yp * _last(dp) for ya, yp in zip(by_alpha, by_p, strict=True))
    return out, tan


def smith_lambda_table(
    q: jax.Array, alpha: jax.Array, p: jax.Array, table: tuple[jax.Array, jax.Array]
) -> jax.Array:
    """Smith ``Lambda`` at ``q = alpha tan^2 theta`` read from :func:`lambda_table`, unitless.

    ``q`` (N,) with scalar ``alpha, p`` and (M,) tables, or (N, 3) with (3,)/(1, 3)
    ``alpha, p`` and (3, M) tables (``rgb_lobe``). Cubic Hermite in ``tau = -ln(q) / 2``;
    below the table the grazing expansion, above it ``q`` floored (module docstring).
    """
    y, dy = table
    lo, hi = TABLE_TAU
    h = (hi - lo) / (TABLE_NODES - 1)
    tau = -0.5 * jnp.log(jnp.maximum(q, 1.0 / 800.0))  # q floored: a finite log
    z = (jnp.clip(tau, lo, hi) - lo) / h
    i = jnp.clip(jnp.floor(z), 0, TABLE_NODES - 2).astype(jnp.int32)
    s = z - i
    if y.ndim == 1:
        y0, y1, d0, d1 = y[i], y[i + 1], dy[i], dy[i + 1]
    else:  # per channel: tables (3, M), samples (N, 3)
        ch = jnp.arange(y.shape[0])
        y0, y1, d0, d1 = y[ch, i], y[ch, i + 1], dy[ch, i], dy[ch, i + 1]
    hermite = (
        (1.0 + 2.0 * s) * (1.0 - s) ** 2 * y0
        + s**2 * (3.0 - 2.0 * s) * y1
        + h * s * (1.0 - s) * ((1.0 - s) * d0 - s * d1)
    )
    x = jnp.exp(tau)
    u = alpha + x**2
    lam = jnp.exp(hermite - u - p * jnp.log(u))
    # grazing, x < x0: Lambda = (Lambda(x0) + 1/2) x0 / x - 1/2; y[..., 0] is at x0
    x0 = math.exp(lo)
    u0 = alpha + x0**2
    lam0 = jnp.exp(jnp.reshape(y[..., 0], jnp.shape(u0)) - u0 - p * jnp.log(u0))
    graze = (lam0 + 0.5) * (x0 / jnp.minimum(x, x0)) - 0.5
    return jnp.where(tau < lo, graze, lam)


def sgd_fresnel(f0: jax.Array, f1: jax.Array, cos_d: jax.Array) -> jax.Array:
    """``max(F0 - F1 cos_d + (1 - F0)(1 - cos_d)^5, 0)``; RGB ``f0``, ``f1`` -> (N, 3)."""
    c = cos_d[:, None]
    return jnp.maximum(f0[None, :] - f1[None, :] * c + (1.0 - f0[None, :]) * (1.0 - c) ** 5, 0.0)


def tan2(v: jax.Array) -> jax.Array:
    """``tan^2 theta = (vx^2 + vy^2) / vz^2`` of unit vectors (N, 3) above the horizon, (N,)."""
    return (v[:, 0] ** 2 + v[:, 1] ** 2) / v[:, 2] ** 2


@final
class SGD(AbstractModel):
    """Bagher et al. 2012: Shifted Gamma microfacet lobe, exact Smith masking, Lambert."""

    rgb_lobe: bool = eqx.field(static=True, default=False)

    name: ClassVar[str] = "sgd"
    reference: ClassVar[str] = "Bagher, Soler, Holzschuch 2012, CGF 31(4) (EGSR)"
    energy_conserving: ClassVar[bool] = False
    channel_separable: ClassVar[bool] = True

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        shape = (3,) if self.rgb_lobe else ()
        lobe = tuple(Parameter(n, shape, *row) for n, row in SHAPE.items())
        return (KD, KS, F0, F1) + lobe

    def core(self, params: Params, g: ShadingGeometry) -> jax.Array:
        alpha, p = params["alpha"], params["p"]
        th, ti, to = tan2(g.h), tan2(g.wi), tan2(g.wo)
        cos_h, cos_io = g.cos_h, g.cos_i * g.cos_o
        if self.rgb_lobe:  # per-channel lobe: samples (N, 1) against channels (1, 3)
            alpha, p = alpha[None, :], p[None, :]
            th, ti, to, cos_h, cos_io = (x[:, None] for x in (th, ti, to, cos_h, cos_io))
        d = sgd_ndf(th, cos_h, alpha, p)
        table = lambda_table(params["alpha"], params["p"])  # once per evaluation
        lam_i = smith_lambda_table(alpha * ti, alpha, p, table)
        lam_o = smith_lambda_table(alpha * to, alpha, p, table)
        lobe = d / ((1.0 + lam_i) * (1.0 + lam_o) * cos_io) * INV_PI
        if not self.rgb_lobe:
            lobe = lobe[:, None]
        f = sgd_fresnel(params["f0"], params["f1"], g.cos_d)
        return lambert(params["kd"]) + params["ks"][None, :] * f * lobe
