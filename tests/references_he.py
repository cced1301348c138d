"""High-precision reference for ``brdffit/models/he.py``: He, Torrance, Sillion and Greenberg
1991 as bsdfbenchmark's ``NganHe`` evaluates it (``bsdfmodel/he.h`` with ``fresnel::cook``,
``he_eq25::Errata``, ``he_eq78::Westin``, 4 Newton steps, at most 64 series terms with the
adaptive stop, rough limit blended over ``g`` in [18, 19]), plus Lambert; written out again
in mpmath, one direction pair at a time, from the paper's equations and bbm's source, not
from the model's code.

Per pair, with ``k_i = -wi``, ``k_r = wo``, ``n = z`` (the float64 inputs taken exactly):

* Eq. 76 as printed: ``s = k x n / |k x n|``, ``p = s x k`` for each direction, ``v = k_r -
  k_i`` and ``G = (v.v / v_z)^2 [(s_r.k_i)^2 + (p_r.k_i)^2][(s_i.k_r)^2 + (p_i.k_r)^2] /
  |k_i x k_r|^4``; where ``k x n = 0`` (normal incidence) ``s`` is any unit vector normal to
  ``n`` (Westin's ``PerpUnitVector``), where ``|k_i x k_r|^4 <= eps`` the bracket ratio is 1
  (bbm). ``sin(theta) = |k x n|``.
* Eqs. 24-25 (errata): ``S = (1 - erfc(c)/2) / (1 + (exp(-c^2)/(sqrt(pi) c) - erfc(c))/2)``,
  ``c = tau cos / (2 sigma_0 sin)``, 1 at ``sin = 0``.
* Eqs. 80, 82-83: ``K = tan erfc(tau / (2 sigma_0 tan))`` (0 for ``tan <= eps``), ``f0 = (K_i +
  K_o) / sqrt(8 pi)``, ``x`` from ``f0`` (``f0 <= 1``) or ``sqrt(2 ln f0)`` by four Newton
  steps on ``x e^(x^2/2) - f0`` in bbm's form ``x -= (x e - f0) / ((1 + x^2) e)``, ``sigma =
  sigma_0 / sqrt(1 + x^2)``.
* Eqs. 78-79, 84 per channel, ``lambda`` = 0.645, 0.526, 0.444 um: ``g = (2 pi sigma (cos_i +
  cos_o) / lambda)^2``, the running product ``g^m / m!`` as Westin and bbm form it, terms
  ``exp(-g - pi^2 tau^2 v_xy^2 / (m lambda^2)) (g^m / m!) / m`` summed until (and including)
  the first one whose smallest channel is below eps and below the previous term's smallest
  channel, at most 64; none when ``min g > 19``; the rough limit ``exp(-pi^2 tau^2 v_xy^2 /
  (lambda^2 g)) / g`` blended with weight ``clip(min g - 18, 0, 1)``; times ``pi^2 tau^2 /
  (4 lambda^2)``.
* Cook and Torrance's Fresnel, real ``eta``, at ``cos = sqrt(max((1 + wi.wo) / 2, 0))`` (bbm).
* ``f = kd / pi + ks F S_i S_o G D / (pi cos_i cos_o)``.

``REFERENCES["he"](model, params, wi, wo)`` returns an (N, 3) object array of ``mp.mpf`` at
40 digits (or the caller's ``mp.mp.dps`` if higher). ``eps`` is float64's 2^-52 (bbm's
``Constants::Epsilon()`` of its double configuration): the series' stop is a decision on
values, made here in 40 digits, so the reference agrees with a float64 evaluation except
where a term lies within rounding of that threshold.
"""

from __future__ import annotations

from collections.abc import Callable

import mpmath as mp
import numpy as np

DPS = 40
WAVELENGTHS_UM = ("0.645", "0.526", "0.444")
"""bbm's ``Config::wavelength()`` (backbone.h), micrometres, R G B."""
NEWTON = 4
TERMS = 64
ROUGH = 18
EPS = mp.mpf(2) ** -52


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _norm(a):
    return mp.sqrt(_dot(a, a))


def _s_vector(k):
    """``s = k x n / |k x n|``; a unit vector normal to ``n`` where ``k`` is along ``n``."""
    c = _cross(k, (0, 0, 1))
    length = _norm(c)
    if length == 0:
        return (mp.mpf(1), mp.mpf(0), mp.mpf(0))
    return tuple(x / length for x in c)


def geometry_g(k_i, k_r):
    """Eq. 76 with the vectors of the paper."""
    v = tuple(a - b for a, b in zip(k_r, k_i, strict=True))
    scale = (_dot(v, v) / v[2]) ** 2
    s_i, s_r = _s_vector(k_i), _s_vector(k_r)
    p_i, p_r = _cross(s_i, k_i), _cross(s_r, k_r)
    cross4 = _dot(_cross(k_i, k_r), _cross(k_i, k_r)) ** 2
    if cross4 <= EPS:
        return scale
    bracket = (_dot(s_r, k_i) ** 2 + _dot(p_r, k_i) ** 2) * (
        _dot(s_i, k_r) ** 2 + _dot(p_i, k_r) ** 2
    )
    return scale * bracket / cross4


def shadowing(cos, sin, tau, sigma0):
    """Eq. 24 with Eq. 25's errata form of Lambda."""
    if sin == 0:
        return mp.mpf(1)
    c = tau * (cos / sin) / (2 * sigma0)
    lam = (mp.exp(-(c**2)) / (mp.sqrt(mp.pi) * c) - mp.erfc(c)) / 2
    return (1 - mp.erfc(c) / 2) / (lam + 1)


def apparent_sigma(ci, si, co, so, tau, sigma0):
    """Eq. 80 by four Newton steps from bbm's (Westin's) start."""

    def k_term(cos, sin):
        tan = sin / cos
        return tan * mp.erfc(tau / (2 * sigma0 * tan)) if tan > EPS else mp.mpf(0)

    f0 = (k_term(ci, si) + k_term(co, so)) / mp.sqrt(8 * mp.pi)
    x = f0 if f0 <= 1 else mp.sqrt(2 * mp.log(f0))
    for _ in range(NEWTON):
        e = mp.exp(x * x / 2)
        x = x - (x * e - f0) / ((1 + x * x) * e)
    return sigma0 / mp.sqrt(1 + x * x)


def distribution(sigma, cos_sum, vxy2, tau):
    """Eq. 78 (Westin's exponent) and the rough limit, blended as bbm; three channels."""
    lams = [mp.mpf(w) for w in WAVELENGTHS_UM]
    g = [(2 * mp.pi * sigma * cos_sum / lam) ** 2 for lam in lams]
    a = [mp.pi**2 * tau**2 * vxy2 / lam**2 for lam in lams]
    norm = [mp.pi**2 * tau**2 / (4 * lam**2) for lam in lams]
    g_min = min(g)
    rough, weight = [mp.mpf(0)] * 3, mp.mpf(0)
    if g_min > ROUGH:
        rough = [mp.exp(-a[c] / g[c]) / g[c] for c in range(3)]
        weight = min(max(g_min - ROUGH, mp.mpf(0)), mp.mpf(1))
    total = [mp.mpf(0)] * 3
    g_m = [mp.mpf(1)] * 3
    term = [mp.mpf(0)] * 3
    done = g_min - 1 > ROUGH
    for m in range(1, TERMS + 1):
        if done:
            break
        last = min(term)
        g_m = [g_m[c] * g[c] / m for c in range(3)]
        term = [mp.exp(-g[c] - a[c] / m) * g_m[c] / m for c in range(3)]
        total = [total[c] + term[c] for c in range(3)]
        done = min(term) < EPS and min(term) < last
    return [norm[c] * ((1 - weight) * total[c] + weight * rough[c]) for c in range(3)]


def fresnel_cook(cos, eta):
    """Cook and Torrance 1982, real ``eta``; ``g = 0`` where ``g^2 < 0`` (bbm's ``safe_sqrt``:
    ``F = 1``, total internal reflection, only for ``eta < 1``)."""
    g = mp.sqrt(max(eta**2 + cos**2 - 1, 0))
    if g + cos == 0:  # eta <= 1 at cos = 0: the limit cos -> 0+ (F = 0 for eta = 1, else 1)
        return mp.mpf(0) if eta == 1 else mp.mpf(1)
    b = (cos * (g + cos) - 1) / (cos * (g - cos) + 1)
    return ((g - cos) / (g + cos)) ** 2 * (1 + b**2) / 2


def he_value(p: dict, wi: tuple, wo: tuple) -> list:
    """f of one pair (three mpf); ``p``: name -> mpf or list of three mpf."""
    if wi[2] <= 0 or wo[2] <= 0:
        return [mp.mpf(0)] * 3
    k_i, k_r = tuple(-x for x in wi), wo
    sigma0, tau, eta = p["sigma"], p["tau"], p["eta"]
    si, so = _norm(_cross(k_i, (0, 0, 1))), _norm(_cross(k_r, (0, 0, 1)))
    ci, co = wi[2], wo[2]
    s = shadowing(ci, si, tau, sigma0) * shadowing(co, so, tau, sigma0)
    g = geometry_g(k_i, k_r)
    sigma = apparent_sigma(ci, si, co, so, tau, sigma0)
    vxy2 = (wi[0] + wo[0]) ** 2 + (wi[1] + wo[1]) ** 2
    d = distribution(sigma, ci + co, vxy2, tau)
    f = fresnel_cook(mp.sqrt(max((1 + _dot(wi, wo)) / 2, 0)), eta)
    lobe = f * s * g / (mp.pi * ci * co)
    return [p["kd"][c] / mp.pi + p["ks"][c] * lobe * d[c] for c in range(3)]


def reference(model, params: dict, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """f(wi, wo) in 1/sr, (N, 3) object array of mpf; ``params`` natural values (numpy)."""
    wi, wo = np.asarray(wi, float), np.asarray(wo, float)
    out = np.empty((len(wi), 3), dtype=object)
    with mp.workdps(max(DPS, mp.mp.dps)):
        p = {}
        for k, v in params.items():
            a = np.asarray(v, float)
            p[k] = mp.mpf(float(a)) if a.ndim == 0 else [mp.mpf(float(x)) for x in a]
        for i in range(len(wi)):
            a = tuple(mp.mpf(float(x)) for x in wi[i])
            b = tuple(mp.mpf(float(x)) for x in wo[i])
            out[i] = he_value(p, a, b)
    return out


REFERENCES: dict[str, Callable] = {"he": reference}
