"""Render-space error of a fitted material against a measurement: :func:`render_error`.

What :func:`brdffit.export.material.best_material` chooses a form by:

* **albedo error**: the directional albedo ``a(wo) = integral of f cos(theta_i) dwi``
  (``theta_i`` < 80 degrees) at views 0, 30, 60 and 75 degrees, ``||a_fit - a_data|| /
  ||a_data||`` over views and R, G, B: what a render under a white environment shows
  (a channel the material barely reflects weighs as little as it shows; a per-channel
  ratio would explode on it: RGL cg_sunflower's blue albedo is near 0). The integral is
  taken over half vectors, ``dwi = 4 (wo.h) dwh``, with Gauss-Legendre panels in ``1 -
  cos(theta_h)`` spaced geometrically from 1e-10 (:func:`_albedo_pairs`), so a lobe as
  narrow as alpha 1e-4 carries its energy into the albedo as a render's importance
  sampling would; a grid uniform in ``wi`` steps over it. (The 80-degree edge is a
  step across the panels: a Lambertian's albedo comes out 1.1% high at normal view, on
  the fit and the data alike);
* **point-light error**: ``||fit - data|| / ||data||`` over the pixels and channels of a
  unit sphere seen along its axis under a distant light from (3, 3, 4) (the scene of
  ``benchmarks/render_check.py``): 48 x 48 pixels, those whose footprint lies wholly on
  the sphere, each the mean of ``f cos(theta_i)`` at 3 x 3 points of its footprint. A
  pixel averages over the normals it sees, as a render does: a lobe far narrower than a
  pixel (a fit's alpha of 1e-4 chasing a peak) shows as the little it adds to the
  pixel, where a sample on the exact mirror direction read it as 1e7 (in-plane slices
  at whole degrees did: point errors of 1e4 on RGL cg_sunflower and ilm_solo_m_68).

The data side reads the measurement at those directions by nearest MERL bin, a channel
the reader left out taking its nearest measured bin's value
(:func:`brdffit.io.merl_grid.nearest_bin`), so the data must lie on a MERL grid or a
strided one (MERL, NBRDF and RGL-EPFL files do; a table of scattered samples does not).
Fits may run on a strided grid, but scores are read from the full-resolution grid
(``measured``; ``brdffit material`` reads the file twice): on a coarse grid a sample
stands for its whole cell, and near a highlight that step is part of the point-light
error.

An export that is not exact (``Export.exact`` false) adds its own errors against the fit:
its relative error of ``f cos(theta_i)`` to the point-light error and its albedo error
(:func:`brdffit.export._match.albedo_error`) to the albedo error; by the triangle
inequality the written material's error is at most about the sum. (Without the albedo
term, a two-lobe fit of RGL satin_rosaline whose nested blend had to darken the diffuse
was chosen and rendered at 0.58-0.67 of the measured brightness.)
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from brdffit import models
from brdffit.core.measurements import Measurements
from brdffit.core.result import FitResult
from brdffit.export.api import Export
from brdffit.io.merl_grid import merl_stride, nearest_bin

ALBEDO_VIEWS_DEG = (0.0, 30.0, 60.0, 75.0)
LIGHT = np.array([3.0, 3.0, 4.0]) / np.sqrt(34.0)
"""Direction toward the light of the point-light sphere (render_check's light position)."""
PIXELS, SUBSAMPLES = 48, 3


DARK = 0.05
"""A channel whose measured albedo at normal view is below this fraction of the brightest
channel's is not reported as a colour ratio (its ratio is noise over ~0)."""


@dataclass(frozen=True)
class RenderError:
    """Render-space error of a material against a measurement (module docstring):
    ``albedo`` (relative error of the directional albedo over views and channels),
    ``point`` (relative error of the point-light sphere, the export's own error
    included), ``fit_rgb`` and ``data_rgb`` (the albedo at normal view, R, G, B)."""

    albedo: float
    point: float
    fit_rgb: tuple[float, float, float]
    data_rgb: tuple[float, float, float]

    @property
    def ratio(self) -> tuple[float, ...]:
        """Fit over data albedo at normal view per channel (``nan`` for a :data:`DARK` one)."""
        top = max(self.data_rgb)
        return tuple(
            f / d if d > DARK * top else math.nan
            for f, d in zip(self.fit_rgb, self.data_rgb, strict=True)
        )

    @property
    def score(self) -> float:
        """``albedo + point``: what a form is chosen by."""
        return self.albedo + self.point

    def text(self) -> str:
        r = ", ".join(f"{x:.2f}" for x in self.ratio)
        return (
            f"albedo error {self.albedo:.3f}, point-light error {self.point:.3f}, albedo ratio {r}"
        )


@functools.lru_cache(maxsize=1)
def _albedo_pairs() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(wi, wo, weight)`` of the albedo quadrature at each view of
    :data:`ALBEDO_VIEWS_DEG`, in view order with equal counts (module docstring): 30
    panels of 8 Gauss-Legendre nodes in ``t = 1 - cos(theta_h)`` (``dwh = dt dphi``), 48
    azimuths; ``weight`` (sr) is 0 where ``wi`` lies beyond the 80-degree cut."""
    ends = np.concatenate([[0.0], np.geomspace(1e-10, 1.0, 30)])
    x, w = np.polynomial.legendre.leggauss(8)
    lo, hi = ends[:-1, None], ends[1:, None]
    t = (0.5 * (hi - lo) * x + 0.5 * (hi + lo)).ravel()
    wt = (0.5 * (hi - lo) * w).ravel()
    phi = (np.arange(48) + 0.5) * 2.0 * np.pi / 48
    tt, pp = (a.ravel() for a in np.meshgrid(t, phi, indexing="ij"))
    ww = np.repeat(wt, len(phi)) * 2.0 * np.pi / len(phi)
    cz = 1.0 - tt
    sz = np.sqrt(np.maximum(1.0 - cz**2, 0.0))
    h = np.stack([sz * np.cos(pp), sz * np.sin(pp), cz], axis=1)
    out = []
    for view in np.radians(ALBEDO_VIEWS_DEG):
        wo = np.array([np.sin(view), 0.0, np.cos(view)])
        oh = h @ wo
        wi = 2.0 * oh[:, None] * h - wo
        ok = (oh > 0.0) & (wi[:, 2] > np.cos(np.radians(80.0)))
        wi = np.where(ok[:, None], wi, np.array([0.0, 0.0, 1.0]))
        out.append((wi, np.broadcast_to(wo, wi.shape), np.where(ok, 4.0 * oh * ww, 0.0)))
    return tuple(np.concatenate(parts) for parts in zip(*out, strict=True))


@functools.lru_cache(maxsize=1)
def _sphere_pairs() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local ``(wi, wo)`` at the sub-pixel points of the point-light sphere, and each
    point's pixel (module docstring). The frame at normal ``n`` is Duff et al.'s (2017)
    branchless orthonormal basis; the BRDF is isotropic, so its choice does not matter."""
    step = 2.0 / PIXELS
    centres = -1.0 + step * (np.arange(PIXELS) + 0.5)
    cx, cy = (a.ravel() for a in np.meshgrid(centres, centres))
    keep = np.hypot(cx, cy) + np.sqrt(2.0) * step / 2 < 1.0
    offsets = step * ((np.arange(SUBSAMPLES) + 0.5) / SUBSAMPLES - 0.5)
    ox, oy = (a.ravel() for a in np.meshgrid(offsets, offsets))
    x = (cx[keep][:, None] + ox[None, :]).ravel()
    y = (cy[keep][:, None] + oy[None, :]).ravel()
    pixel = np.repeat(np.arange(int(keep.sum())), SUBSAMPLES**2)
    n = np.stack([x, y, np.sqrt(1.0 - x**2 - y**2)], axis=1)
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    u = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)

    def local(v: np.ndarray) -> np.ndarray:
        return np.stack([t @ v, u @ v, n @ v], axis=1)

    return local(LIGHT), local(np.array([0.0, 0.0, 1.0])), pixel


def _pooled(fit: np.ndarray, data: np.ndarray) -> float:
    """``||fit - data|| / ||data||`` over every value given."""
    return float(np.linalg.norm(fit - data) / max(np.linalg.norm(data), 1e-300))


def _albedos(f: np.ndarray) -> np.ndarray:
    """Directional albedos (views, 3) of values ``f`` at :func:`_albedo_pairs`."""
    wi, _, weight = _albedo_pairs()
    return (f * (wi[:, 2] * weight)[:, None]).reshape(len(ALBEDO_VIEWS_DEG), -1, 3).sum(axis=1)


def _sphere_image(f: np.ndarray) -> np.ndarray:
    """Point-light sphere pixels (P, 3) of values ``f`` at :func:`_sphere_pairs` (each pixel
    the sum over its points, which the relative error does not see)."""
    wi, _, pixel = _sphere_pairs()
    fc = f * np.maximum(wi[:, 2:3], 0.0)
    return np.stack([np.bincount(pixel, fc[:, c], pixel.max() + 1) for c in range(3)], axis=1)


@dataclass(frozen=True, eq=False)
class Measured:
    """The measurement's side of :func:`render_error`, read once per file: its albedos
    (views, 3) and point-light sphere (P, 3), by nearest bin with the reader's missing
    channels filled (:func:`brdffit.io.merl_grid.nearest_bin`, a distance transform over
    the whole grid per call, so not once per form)."""

    albedo: np.ndarray
    sphere: np.ndarray

    @classmethod
    def of(cls, data: Measurements) -> Measured:
        """Raises :class:`~brdffit.errors.MeasurementsError` naming the file when ``data``
        is not on a MERL grid."""
        merl_stride(data)
        wi, wo, _ = _albedo_pairs()
        albedo = _albedos(nearest_bin(data, wi, wo, fill=True))
        wi, wo, _ = _sphere_pairs()
        return cls(albedo, _sphere_image(nearest_bin(data, wi, wo, fill=True)))


def render_error(
    data: Measurements | Measured, fitted: FitResult, export: Export | None = None
) -> RenderError:
    """The render-space error of ``fitted`` against ``data`` (module docstring; pass
    :class:`Measured` to read the data once for several fits); an inexact ``export`` of
    it adds its own errors."""
    ref = data if isinstance(data, Measured) else Measured.of(data)
    model = models.model_of(fitted)
    params = {k: np.asarray(v) for k, v in fitted.params.items()}
    wi, wo, _ = _albedo_pairs()
    albedo = _albedos(np.asarray(model.eval(params, wi, wo), float))
    wi, wo, _ = _sphere_pairs()
    sphere = _sphere_image(np.asarray(model.eval(params, wi, wo), float))
    extra = (0.0, 0.0) if export is None or export.exact else (export.albedo_error, export.error)
    rgb = tuple(tuple(float(x) for x in a[0]) for a in (albedo, ref.albedo))
    return RenderError(
        _pooled(albedo, ref.albedo) + extra[0], _pooled(sphere, ref.sphere) + extra[1], *rgb
    )
