"""Spectra to colour: the CIE 1931 observer, XYZ and linear sRGB of sampled spectra.

Spectral BRDF samples (a table's ``nm<wavelength>`` columns, an RGL ``.bsdf`` file) become
the linear sRGB values every model is fitted to: the spectrum is the piecewise-linear
interpolant of its samples, integrated against the CIE 1931 2-degree colour matching
functions (:func:`cie1931_xyz`) under the equal-energy illuminant E, then adapted to the
D65 white of sRGB (Bradford), so a flat spectrum ``c`` gives ``(c, c, c)``.
"""

from __future__ import annotations

import numpy as np
from jaxtyping import ArrayLike, Float

from brdffit.errors import ParameterError


def cie1931_xyz(wavelength_nm: Float[ArrayLike, " n"]) -> Float[np.ndarray, "n 3"]:
    """CIE 1931 2-degree colour matching functions (x, y, z) at ``wavelength_nm``.

    The multi-lobe piecewise-Gaussian fit of Wyman, Sloan & Shirley, "Simple analytic
    approximations to the CIE XYZ color matching functions", JCGT 2(2), 2013 (their
    listing 1): ``g(l; mu, s1, s2) = exp(-((l - mu) / s)^2 / 2)`` with ``s = s1`` below
    ``mu`` and ``s2`` above;
    ``x = 1.056 g(599.8; 37.9, 31.0) + 0.362 g(442.0; 16.0, 26.7) - 0.065 g(501.1; 20.4, 26.2)``,
    ``y = 0.821 g(568.8; 46.9, 40.5) + 0.286 g(530.9; 16.3, 31.1)``,
    ``z = 1.217 g(437.0; 11.8, 36.0) + 0.681 g(459.0; 26.0, 13.8)``.
    Within 0.035 (absolute; peaks 1.06, 1.0, 1.78) of the CIE tables at 1 nm (measured
    against Mitsuba 3's ``cie1931_xyz``).
    """
    w = np.asarray(wavelength_nm, float)

    def g(mu: float, inv_lo: float, inv_hi: float) -> np.ndarray:
        t = (w - mu) * np.where(w < mu, inv_lo, inv_hi)
        return np.exp(-0.5 * t * t)

    x = 0.362 * g(442.0, 0.0624, 0.0374) + 1.056 * g(599.8, 0.0264, 0.0323)
    x -= 0.065 * g(501.1, 0.0490, 0.0382)
    y = 0.821 * g(568.8, 0.0213, 0.0247) + 0.286 * g(530.9, 0.0613, 0.0322)
    z = 1.217 * g(437.0, 0.0845, 0.0278) + 0.681 * g(459.0, 0.0385, 0.0725)
    return np.stack([x, y, z], axis=-1)


XYZ_TO_SRGB = np.array(
    [
        [3.2404542, -1.5371385, -0.4985314],
        [-0.9692660, 1.8760108, 0.0415560],
        [0.0556434, -0.2040259, 1.0572252],
    ]
)
"""CIE XYZ -> linear sRGB (IEC 61966-2-1, D65 white)."""
XYZ_TO_SRGB.setflags(write=False)

_BRADFORD = np.array(
    [[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]]
)
_CMF_RANGE = (360.0, 830.0)  # nm, the range of the CIE tables
_CMF_STEP = 0.25  # nm, quadrature step; the fit is smooth on this scale


def _xyz_weights(wavelengths_nm: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(L, 3) weights ``W`` with ``xyz = spectrum @ W``, and the white of the observer."""
    nodes = np.asarray(wavelengths_nm, float).ravel()
    if nodes.size == 0 or not np.all(np.isfinite(nodes)) or np.any(np.diff(nodes) <= 0):
        raise ParameterError(
            f"wavelengths {nodes.tolist()}: expected at least one finite wavelength (nm), "
            "strictly increasing"
        )
    lam = np.arange(_CMF_RANGE[0], _CMF_RANGE[1] + _CMF_STEP / 2, _CMF_STEP)
    cmf = cie1931_xyz(lam)
    # Hat functions of the piecewise-linear spectrum, constant beyond the end nodes.
    hats = np.empty((nodes.size, lam.size))
    for k in range(nodes.size):
        e = np.zeros(nodes.size)
        e[k] = 1.0
        hats[k] = np.interp(lam, nodes, e)
    quad = np.full(lam.size, _CMF_STEP)
    quad[[0, -1]] *= 0.5  # trapezoid rule
    white = quad @ cmf  # the equal-energy white of these observer functions
    return (hats * quad) @ cmf / white[1], white / white[1]


def _adapt_to_d65(white_xyz: np.ndarray) -> np.ndarray:
    """Bradford chromatic adaptation from ``white_xyz`` to the D65 white of sRGB."""
    d65 = np.linalg.solve(XYZ_TO_SRGB, np.ones(3))  # sRGB (1, 1, 1), exactly
    gain = (_BRADFORD @ d65) / (_BRADFORD @ white_xyz)
    return np.linalg.solve(_BRADFORD, gain[:, None] * _BRADFORD)


def spectrum_to_xyz(
    wavelengths_nm: Float[ArrayLike, " l"], values: Float[ArrayLike, "n l"]
) -> Float[np.ndarray, "n 3"]:
    """CIE XYZ of spectra under the equal-energy illuminant E, ``Y = c`` for a flat ``c``.

    The spectrum is the piecewise-linear interpolant of the samples, held constant
    beyond the first and last wavelength (as Mitsuba's ``measured`` plugin does),
    integrated against :func:`cie1931_xyz` over 360-830 nm (trapezoid rule, 0.25 nm).

    Arguments:
    - ``wavelengths_nm``: (L,) strictly increasing wavelengths in nm.
    - ``values``: (N, L) spectra (e.g. BRDF values in 1/sr per wavelength).

    Returns: (N, 3) XYZ in the unit of ``values``.
    """
    w, _ = _xyz_weights(wavelengths_nm)
    return np.asarray(values, float) @ w


def spectral_weights(wavelengths_nm: Float[ArrayLike, " l"]) -> Float[np.ndarray, "l 3"]:
    """The (L, 3) matrix ``W`` with ``spectrum_to_rgb(wl, s) = s @ W``."""
    w, white = _xyz_weights(wavelengths_nm)
    return w @ _adapt_to_d65(white).T @ XYZ_TO_SRGB.T


def spectrum_to_rgb(
    wavelengths_nm: Float[ArrayLike, " l"], values: Float[ArrayLike, "n l"]
) -> Float[np.ndarray, "n 3"]:
    """Linear sRGB of spectra sampled at ``wavelengths_nm``, for reflectance quantities.

    :func:`spectrum_to_xyz` (illuminant E), then Bradford adaptation from the white of
    E (as seen by the same observer functions) to the D65 white of sRGB, then
    :data:`XYZ_TO_SRGB`. So a flat spectrum ``c`` gives ``(c, c, c)``; a saturated one
    may give a negative channel (outside the sRGB gamut), returned as it is.

    Arguments: as :func:`spectrum_to_xyz`.

    Returns: (N, 3) linear sRGB in the unit of ``values``.
    """
    return np.asarray(values, float) @ spectral_weights(wavelengths_nm)
