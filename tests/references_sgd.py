"""High-precision reference for ``brdffit/models/sgd.py``: Bagher, Soler, Holzschuch 2012 written
out again in mpmath (30 digits), independently of the model's numerics.

* ``D`` in the paper's slope form ``P22(x) = alpha^(p-1) exp(-(alpha^2 + x)/alpha) /
  (pi Gamma(1-p, alpha) (alpha^2 + x)^p)``, ``D = P22(tan^2) / cos^4`` (mpmath's
  ``gammainc`` for the upper incomplete gamma, any real first argument);
* Smith's ``Lambda = (1/nu) int_{slope_x > nu} (slope_x - nu) P22 d^2slope`` with
  ``nu = cot theta``, integrated in polar slope coordinates (the azimuth in closed form:
  ``2 (sqrt(r^2 - nu^2) - nu arccos(nu/r))``) by ``mp.quad`` on breakpoints scaled to the
  distribution's decay, not by the model's substitution and trapezoid rule;
* ``F = max(F0 - F1 c + (1 - F0)(1 - c)^5, 0)``, ``c = wi.h``, and
  ``f = kd/pi + ks F D G1(wi) G1(wo) / (pi cos_i cos_o)``, 0 below the horizon.

``REFERENCES["sgd"](model, params, wi, wo)`` returns an (N, 3) object array of ``mp.mpf``
(values far below float64's range, e.g. ``exp(-1e20)`` at cos 1e-10, do not fit a
``np.longdouble`` either). Precision: 30 digits, or the caller's ``mp.mp.dps`` if higher.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import mpmath as mp
import numpy as np

DPS = 30


def _mpf(x: float) -> mp.mpf:
    return mp.mpf(float(x))


def slope_density(r2: mp.mpf, alpha: mp.mpf, p: mp.mpf) -> mp.mpf:
    """The normalised SGD slope density ``P22`` at squared slope ``r2`` (per unit slope area)."""
    norm = alpha ** (p - 1) / (mp.pi * mp.gammainc(1 - p, alpha))
    return norm * mp.exp(-(alpha**2 + r2) / alpha) / (alpha**2 + r2) ** p


@functools.lru_cache(maxsize=4096)
def smith_lambda(cos_t: float, sin_t: float, alpha: float, p: float, dps: int = DPS) -> mp.mpf:
    """Smith Lambda of a direction with the given cos/sin of its polar angle (floats)."""
    with mp.workdps(dps):
        if sin_t == 0.0:
            return mp.mpf(0)
        a, pp = _mpf(alpha), _mpf(p)
        nu = _mpf(cos_t) / _mpf(sin_t)
        if nu**2 / a > 3000:  # Lambda < exp(-3000): nothing float64 can see next to 1
            return mp.mpf(0)

        def integrand(r):
            wedge = 2 * (mp.sqrt(r * r - nu * nu) - nu * mp.acos(nu / r))
            return wedge * slope_density(r * r, a, pp) * r

        scale = min(mp.sqrt(a), a / nu)  # decay length of P22 beyond r = nu
        steps = (1e-8, 1e-5, 1e-2, 0.3, 2, 8, 64)
        points = [nu] + [nu + scale * _mpf(k) for k in steps] + [mp.inf]
        return mp.quad(integrand, points) / nu


def _sample(params: dict, c: int, wi: np.ndarray, wo: np.ndarray) -> mp.mpf:
    """Channel ``c`` of f at one pair; ``params`` maps every name to a (3,) array."""
    if wi[2] <= 0 or wo[2] <= 0:
        return mp.mpf(0)
    alpha, p = float(params["alpha"][c]), float(params["p"][c])
    vi = [_mpf(x) for x in wi]
    vo = [_mpf(x) for x in wo]
    s = [a + b for a, b in zip(vi, vo, strict=True)]
    n = mp.sqrt(sum(x * x for x in s))
    h = [x / n for x in s]
    cos_d = sum(a * b for a, b in zip(vi, h, strict=True))
    tan2 = (h[0] ** 2 + h[1] ** 2) / h[2] ** 2
    a, pp = _mpf(alpha), _mpf(p)
    d = slope_density(tan2, a, pp) / h[2] ** 4
    lam_i = smith_lambda(float(wi[2]), float(np.hypot(wi[0], wi[1])), alpha, p, mp.mp.dps)
    lam_o = smith_lambda(float(wo[2]), float(np.hypot(wo[0], wo[1])), alpha, p, mp.mp.dps)
    f0, f1 = _mpf(params["f0"][c]), _mpf(params["f1"][c])
    fres = max(f0 - f1 * cos_d + (1 - f0) * (1 - cos_d) ** 5, mp.mpf(0))
    spec = fres * d / ((1 + lam_i) * (1 + lam_o) * vi[2] * vo[2] * mp.pi)
    return _mpf(params["kd"][c]) / mp.pi + _mpf(params["ks"][c]) * spec


def reference(model, params: dict, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """f(wi, wo) in 1/sr, (N, 3) object array of mpf; ``params`` natural values (numpy)."""
    # every parameter as (3,): scalars (alpha, p unless rgb_lobe) are the same in each channel
    params = {k: np.broadcast_to(np.asarray(v, float), (3,)) for k, v in params.items()}
    wi, wo = np.asarray(wi, float), np.asarray(wo, float)
    out = np.empty((len(wi), 3), dtype=object)
    with mp.workdps(max(DPS, mp.mp.dps)):
        for i in range(len(wi)):
            for c in range(3):
                out[i, c] = +_sample(params, c, wi[i], wo[i])
    return out


REFERENCES: dict[str, Callable] = {"sgd": reference}
