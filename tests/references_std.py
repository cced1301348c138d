"""High-precision reference for ``brdffit/models/std.py``: the paper's formulas in mpmath.

An independent transcription of Ribardière et al. 2017 (STD), evaluated elementwise at
``mp.dps = 40`` (``REFERENCES["std"]``): the NDF as the slope density over ``cos^4``,
``D = P22(-hx/hz, -hy/hz) / hz^4`` with the bivariate Student t
``P22(p, q) = (1 + ((p/ax)^2 + (q/ay)^2) / (gamma - 1))^-gamma / (pi ax ay)``,
the Smith ``Lambda`` of eq. 13 with
the exact hypergeometric ``S2`` of eq. 15 (not the rational fit of eqs. 22-23), and the
exact dielectric Fresnel of Cook and Torrance (or Schlick, as the model's option says). The
directions are taken as the float64 values given (not renormalised; ``wi . h`` is capped at
1). Values are mpf (unbounded exponent); rounded to float64 one beyond range becomes ``+inf``.

Conditioning: with ``f0 = 0`` (Schlick) and ``wi = wo``, ``F = (1 - wi . h)^5`` depends on the
last bit of the inputs (values ~1e-75 against ~1e12 elsewhere); compare such values with an
absolute tolerance scaled by the largest value, not relatively.
"""

from __future__ import annotations

from collections.abc import Callable

import mpmath as mp
import numpy as np

DPS = 40


def _lambda(v, ax, ay, gamma):
    """Paper eq. 13: ``K [(g-1)^g/(2g-3) (g-1+z^2)^(3/2-g)/z + sqrt(g-1) S2(z)] - 1/2``."""
    proj = mp.sqrt((ax * v[0]) ** 2 + (ay * v[1]) ** 2)
    if proj == 0:
        return mp.mpf(0)  # normal incidence: no masking
    z = v[2] / proj  # cot(theta) / alpha(phi)
    g = gamma
    k = mp.gamma(g - mp.mpf(1) / 2) / (mp.gamma(g) * mp.sqrt(mp.pi))
    s1 = (g - 1) ** g / (2 * g - 3) * (g - 1 + z**2) ** (mp.mpf(3) / 2 - g) / z
    s2 = z * mp.hyp2f1(mp.mpf(1) / 2, g - mp.mpf(1) / 2, mp.mpf(3) / 2, -(z**2) / (g - 1))
    return k * (s1 + mp.sqrt(g - 1) * s2) - mp.mpf(1) / 2


def _ndf(h, ax, ay, gamma):
    """``D(h) = P22(p, q) / cos^4`` with the slopes ``p = -hx/hz``, ``q = -hy/hz``."""
    p, q = -h[0] / h[2], -h[1] / h[2]
    p22 = (1 + ((p / ax) ** 2 + (q / ay) ** 2) / (gamma - 1)) ** -gamma / (mp.pi * ax * ay)
    return p22 / h[2] ** 4


def _fresnel_dielectric(c, eta):
    g = mp.sqrt(eta**2 - 1 + c**2)
    return (g - c) ** 2 / (2 * (g + c) ** 2) * (1 + (c * (g + c) - 1) ** 2 / (c * (g - c) + 1) ** 2)


def reference(model, params: dict, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """STD BRDF in 1/sr (no cosine, 0 below the horizon), ``mp.dps = 40``.

    ``params``: name -> numpy array of natural values; ``wi``, ``wo``: (N, 3) float64.
    Returns an (N, 3) object array of mpmath ``mpf`` (as ``tests/references.py`` asks;
    ``np.asarray(out, float)`` rounds it, overflowing to ``+inf``).
    """
    with mp.workdps(DPS):
        p = {
            k: [mp.mpf(float(x)) for x in np.atleast_1d(np.asarray(v, float))]
            for k, v in params.items()
        }
        rgb = lambda name: p[name] * 3 if len(p[name]) == 1 else p[name]  # noqa: E731
        if model.anisotropic:
            ax, ay = p["alpha_x"][0], p["alpha_y"][0]
        else:
            ax = ay = p["alpha"][0]
        gamma = p["gamma"][0]
        out = np.full((len(wi), 3), mp.mpf(0), dtype=object)
        for n, (a, b) in enumerate(zip(wi, wo, strict=True)):
            i = [mp.mpf(float(x)) for x in a]
            o = [mp.mpf(float(x)) for x in b]
            if i[2] <= 0 or o[2] <= 0:
                continue
            s = [x + y for x, y in zip(i, o, strict=True)]
            norm = mp.sqrt(sum(x**2 for x in s))
            h = [x / norm for x in s]
            # |wi| may exceed 1 by an ulp; the facet cosine is at most 1 (as in the model)
            cos_d = min(sum(x * y for x, y in zip(i, h, strict=True)), mp.mpf(1))
            lam_i, lam_o = _lambda(i, ax, ay, gamma), _lambda(o, ax, ay, gamma)
            if model.masking == "height_correlated":
                g2 = 1 / (1 + lam_i + lam_o)
            else:
                g2 = 1 / ((1 + lam_i) * (1 + lam_o))
            lobe = _ndf(h, ax, ay, gamma) * g2 / (4 * i[2] * o[2])
            if model.fresnel == "dielectric":
                f = _fresnel_dielectric(cos_d, p["eta"][0])
                spec = [ks * f * lobe for ks in rgb("ks")]
            else:
                s5 = (1 - cos_d) ** 5
                spec = [(f0 + (1 - f0) * s5) * lobe for f0 in rgb("f0")]
            diff = [kd / mp.pi for kd in rgb("kd")] if model.diffuse else [0, 0, 0]
            out[n] = [x + y for x, y in zip(spec, diff, strict=True)]
        return out


REFERENCES: dict[str, Callable] = {"std": reference}
