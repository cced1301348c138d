"""Tiny RGL-EPFL ``.bsdf`` files (Dupuy & Jakob 2018) written from closed forms, for tests.

The format is Mitsuba's tensor file (``mitsuba.python.tensor_io.write``): ``description``
(uint8 text), ``theta_i`` and ``phi_i`` (float32 parameter nodes, radians), ``ndf`` and
``sigma`` (2-D), ``vndf`` and ``luminance`` (phi_i x theta_i x n x n), ``rgb``
(phi_i x theta_i x 3 x n x n) or ``spectra`` with ``wavelengths`` (nm), and
``jacobian`` (uint8). Mitsuba's ``measured`` plugin (``src/bsdfs/measured.cpp``) returns,
for ``si.wi = wi`` and ``wo``,

    f cos(theta_o) = S(sample, phi_i, theta_i) [x ndf(u_m) / (4 sigma(u_wi)) if jacobian]

with ``u = (sqrt(theta / (pi/2)), (phi + pi) / (2 pi))`` of the half vector ``m`` (its
azimuth taken relative to ``phi_i`` for an isotropic file, one with at most 2 ``phi_i``
nodes) and of ``wi``; ``sample`` = the VNDF warp's inverse at ``u_m``, the identity
for the uniform ``vndf`` written here; every table is interpolated multilinearly on the
uniform ``u`` grid and linearly between parameter nodes (clamped beyond them).

So a table holding a function that is multilinear in those coordinates is reproduced
exactly (to float32): :func:`linear_file` writes such files, and :func:`linear_fcos` is
the closed form they hold. Absolute values ``|u_phi - 1/2|`` keep the functions
continuous across the azimuth wrap and mirror-symmetric (Mitsuba may mirror the
directions of an anisotropic file); their kink lies on a node (odd ``n``).
:func:`lambert_file` tabulates a Lambertian BRDF, reproduced up to interpolation error.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np

N_U = 17  # u-grid nodes per axis (odd: u = 1/2 is a node)
THETA_I = np.radians(np.linspace(0.0, 85.0, 6))  # incidence nodes (radians)
PHI_I_ANISO = np.radians(np.linspace(-180.0, 180.0, 9))  # reduction 1: no mirroring

# S = a[c] + b u_theta_m + c |u_phi_m - 1/2| + d theta_i + e |phi_i| (anisotropic only)
COEF = {"a": (0.2, 0.3, 0.4), "b": 0.3, "c": 0.15, "d": 0.1, "e": 0.05}
NDF = (0.5, 1.0, 0.4)  # ndf = n0 + n1 u_theta_m + n2 |u_phi_m - 1/2|
SIGMA = (0.6, 0.3)  # sigma = s0 + s1 u_theta_i
LAMBERT_THETA_I = np.radians(np.linspace(0.0, 85.0, 18))  # incidence nodes of lambert_file


def _write(path: Path, **fields) -> Path:
    from mitsuba.python import tensor_io

    with contextlib.redirect_stdout(io.StringIO()):  # tensor_io prints a line
        tensor_io.write(str(path), **fields)
    return path


def _u_axes(n: int = N_U) -> tuple[np.ndarray, np.ndarray]:
    """(u_theta, u_phi) on the [y = phi, x = theta] table layout, each (n, n)."""
    u = np.linspace(0.0, 1.0, n)
    return np.meshgrid(u, u, indexing="xy")


def linear_file(
    path: Path, *, anisotropic: bool = False, jacobian: bool = False, spectral: bool = False
) -> Path:
    """Write a file holding :func:`linear_fcos` exactly; returns ``path``.

    ``spectral``: a ``spectra`` field over 4 wavelengths instead of ``rgb``, every
    wavelength holding the value of channel 0 (so its sRGB is that value, grey).
    """
    phi_i = PHI_I_ANISO if anisotropic else np.array([0.0])
    ut, up = _u_axes()
    n_c = 4 if spectral else 3
    s = np.empty((phi_i.size, THETA_I.size, n_c, N_U, N_U))
    for j, p in enumerate(phi_i):
        for k, t in enumerate(THETA_I):
            for c in range(n_c):
                a = COEF["a"][0 if spectral else c]
                e = COEF["e"] * abs(p) if anisotropic else 0.0
                s[j, k, c] = a + COEF["b"] * ut + COEF["c"] * np.abs(up - 0.5) + COEF["d"] * t + e
    ndf = NDF[0] + NDF[1] * ut + NDF[2] * np.abs(up - 0.5)
    sigma = SIGMA[0] + SIGMA[1] * ut
    ones = np.ones((phi_i.size, THETA_I.size, N_U, N_U), np.float32)
    values = {"rgb": s.astype(np.float32)}
    if spectral:
        wl = np.array([400.0, 500.0, 600.0, 700.0], np.float32)
        values = {"spectra": s.astype(np.float32), "wavelengths": wl}
    return _write(
        path,
        description="brdffit test: multilinear",
        theta_i=THETA_I.astype(np.float32),
        phi_i=phi_i.astype(np.float32),
        ndf=(ndf if jacobian else np.ones_like(ndf)).astype(np.float32),
        sigma=(sigma if jacobian else np.ones_like(sigma)).astype(np.float32),
        vndf=ones,
        luminance=ones,
        **values,
        jacobian=np.array([1 if jacobian else 0], np.uint8),
    )


def _angles(wi: np.ndarray, wo: np.ndarray):
    """(u_theta_m, u_phi_m relative or absolute, theta_i, phi_i) as Mitsuba computes them."""
    m = wi + wo
    m = m / np.linalg.norm(m, axis=1, keepdims=True)
    theta_m = np.arccos(np.clip(m[:, 2], -1.0, 1.0))
    theta_i = np.arccos(np.clip(wi[:, 2], -1.0, 1.0))
    phi_i = np.arctan2(wi[:, 1], wi[:, 0])
    phi_m = np.arctan2(m[:, 1], m[:, 0])
    return np.sqrt(theta_m / (np.pi / 2)), phi_m, theta_i, phi_i


def linear_fcos(
    wi: np.ndarray, wo: np.ndarray, *, anisotropic: bool = False, jacobian: bool = False
) -> np.ndarray:
    """The closed form held by :func:`linear_file`: f cos(theta_o), (N, 3), above the horizon."""
    ut, phi_m, theta_i, phi_i = _angles(wi, wo)
    rel = phi_m if anisotropic else phi_m - phi_i
    up = ((rel + np.pi) / (2 * np.pi)) % 1.0
    t = np.clip(theta_i, THETA_I[0], THETA_I[-1])  # parameters are clamped to the nodes
    base = COEF["b"] * ut + COEF["c"] * np.abs(up - 0.5) + COEF["d"] * t
    if anisotropic:
        base = base + COEF["e"] * np.abs(phi_i)
    s = np.stack([a + base for a in COEF["a"]], axis=1)
    if jacobian:
        ndf = NDF[0] + NDF[1] * ut + NDF[2] * np.abs(up - 0.5)
        sigma = SIGMA[0] + SIGMA[1] * np.sqrt(theta_i / (np.pi / 2))
        s = s * (ndf / (4 * sigma))[:, None]
    return s


def lambert_file(path: Path, albedo: tuple[float, float, float], n: int = 33) -> Path:
    """Write a Lambertian BRDF ``albedo / pi`` (jacobian 0, uniform VNDF) on an n x n grid.

    The table holds ``f cos(theta_o) = albedo / pi wo.z`` at each node, ``wo`` being ``wi``
    mirrored about the node's half vector ``m`` (``wo = 2 (wi.m) m - wi``). Where ``wo``
    falls below the horizon the table keeps the smooth continuation (negative; the
    plugin returns 0 there), so the interpolation error obeys the smooth-function bound
    of :func:`lambert_error_bound` everywhere. 18 incidence nodes, 0 to 85 degrees.
    """
    theta_i = LAMBERT_THETA_I
    ut, up = _u_axes(n)
    theta_m = ut**2 * (np.pi / 2)
    phi_m = up * 2 * np.pi - np.pi  # relative to phi_i = 0
    m = np.stack(
        [np.sin(theta_m) * np.cos(phi_m), np.sin(theta_m) * np.sin(phi_m), np.cos(theta_m)], -1
    )
    s = np.empty((1, theta_i.size, 3, n, n))
    for k, t in enumerate(theta_i):
        wi = np.array([np.sin(t), 0.0, np.cos(t)])
        wo_z = 2 * (m @ wi) * m[..., 2] - wi[2]
        for c in range(3):
            s[0, k, c] = albedo[c] / np.pi * wo_z
    ones = np.ones((1, theta_i.size, n, n), np.float32)
    return _write(
        path,
        description="brdffit test: Lambert",
        theta_i=theta_i.astype(np.float32),
        phi_i=np.zeros(1, np.float32),
        ndf=np.ones((n, n), np.float32),
        sigma=np.ones((n, n), np.float32),
        vndf=ones,
        luminance=ones,
        rgb=s.astype(np.float32),
        jacobian=np.array([0], np.uint8),
    )


def _lambert_wo_z(ut: np.ndarray, up: np.ndarray, theta_i: np.ndarray) -> np.ndarray:
    """``wo.z`` for ``wi`` at zenith ``theta_i`` (azimuth 0) and the half vector at ``u``."""
    tm, pm = ut**2 * (np.pi / 2), 2 * np.pi * up - np.pi
    dot = np.sin(theta_i) * np.sin(tm) * np.cos(pm) + np.cos(theta_i) * np.cos(tm)
    return 2 * dot * np.cos(tm) - np.cos(theta_i)


def lambert_error_bound(n: int) -> float:
    """Bound on ``|interpolated - exact| / (albedo / pi)`` of ``f cos`` for :func:`lambert_file`.

    The table is interpolated by tensor-product linear interpolation in
    ``(u_theta_m, u_phi_m, theta_i)``; its error is at most
    ``sum_k h_k^2 / 8 max |d^2 g / dx_k^2|`` for a smooth ``g`` (the 1-D bound per axis;
    each 1-D interpolation operator has max-norm 1). ``g = wo.z``; the second
    derivatives are estimated by second differences on a 201 x 201 x 61 grid (the
    estimate is 0.24% below that of a 401 x 401 x 121 grid; the test keeps a wide margin).
    """
    k = 201
    ut = np.linspace(0.0, 1.0, k)[:, None, None]
    up = np.linspace(0.0, 1.0, k)[None, :, None]
    t = np.linspace(LAMBERT_THETA_I[0], LAMBERT_THETA_I[-1], 61)[None, None, :]
    g = _lambert_wo_z(ut, up, t)
    h, ht = 1.0 / (k - 1), float(t[0, 0, 1] - t[0, 0, 0])
    d2 = [np.abs(np.diff(g, 2, axis=a)).max() / s**2 for a, s in ((0, h), (1, h), (2, ht))]
    grid = (1.0 / (n - 1), 1.0 / (n - 1), float(LAMBERT_THETA_I[1] - LAMBERT_THETA_I[0]))
    return float(sum(s**2 / 8 * d for s, d in zip(grid, d2, strict=True)))
