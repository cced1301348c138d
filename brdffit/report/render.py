"""The radiometric core of the figures: lit spheres under two lightings, tone map, colour
difference.

Nothing here draws or calls a solver; everything returns numpy arrays (float64).
:mod:`brdffit.report.figures` turns them into pictures.

Units and conventions: BRDF values ``f(wi, wo)`` are in 1/sr, per linear RGB channel;
``wi`` and ``wo`` are unit (n, 3) directions in the local shading frame (normal +z), ``wi``
toward the light, ``wo`` toward the viewer. Radiance is linear RGB in the units of the
lighting (unit irradiance for the point light, relative units for :class:`Environment`).

The fit and the data at the pixels' directions come from :mod:`brdffit.report.lookup`
(:func:`~brdffit.report.lookup.model_brdf`, :func:`~brdffit.io.merl_grid.nearest_bin`,
unmeasured bins filled from the nearest measured one; :func:`sphere_images` says which
pixels rest on filled bins).

Sphere set-up (:func:`render_sphere`, :func:`sphere_images`): a unit sphere seen by an
orthographic camera along -z (image up = +y, right = +x; :func:`sphere_normals`), so
``wo`` is the world +z in each pixel's local frame: the normal ``n`` as z, the world x
axis projected on the tangent plane as the tangent (defined on every visible pixel). Two
lightings:

* a distant point light (a directional light) of unit irradiance normal to it:
  ``L = f(wi, wo) cos(theta_i)``;
* an environment, a sky/ground gradient (:class:`Environment`), integrated per pixel
  with a fixed quadrature of half vectors: ``L = sum_k f(wi_k, wo) L_env(wi_k)
  cos(theta_k) dw_k`` over the ``wi_k`` above the horizon (see :class:`Environment`).

Tone map (:func:`tonemap`): ``sRGB(clip(exposure L, 0, 1))`` with the exact sRGB transfer
curve (IEC 61966-2-1).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from brdffit.core.measurements import Measurements
from brdffit.io.merl_grid import merl_stride, nearest_bin
from brdffit.report.lookup import Brdf, Fit, model_brdf

# --------------------------------------------------------------------------- sphere


@dataclass(frozen=True)
class Environment:
    """A sky/ground gradient and the fixed quadrature that integrates it.

    Radiance (linear RGB, relative units) of a world direction with up component ``y``
    (world up is +y, image up): the sky ``horizon + (zenith - horizon) max(y, 0)`` blended
    into ``ground`` by a smoothstep over ``-soft < y < soft``: a soft horizon, so that the
    fixed quadrature does not band a sharp reflected horizon line.

    Quadrature, the same in every pixel's local frame, two fixed sets combined by the
    balance heuristic (deterministic multiple importance sampling, Veach 1997):

    * ``n_theta x n_phi`` half vectors, rings at MERL's spacing ``theta_h = (pi/2) u^2``
      (``u`` at bin centres: the first ring 0.16 deg from the normal for 12 rings), each
      giving ``wi = 2 (wo.h) h - wo``: samples on every pixel's mirror direction, so glossy
      highlights come out smooth, not as a pattern of spots; density over ``wi``
      ``n_h / (8 pi^2 u sin(theta_h) (wo.h))``;
    * ``n_cosine`` cosine-distributed directions (a Fibonacci spiral on the unit disk
      lifted to the hemisphere), density ``n_cosine cos(theta_i) / pi``: the broad
      diffuse part without banding.

    Each sample weighs ``dw = 1 / (sum of both densities)`` sr.
    """

    zenith: tuple[float, float, float] = (0.35, 0.55, 1.0)
    horizon: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ground: tuple[float, float, float] = (0.25, 0.2, 0.15)
    soft: float = 0.2
    n_theta: int = 12
    n_phi: int = 12
    n_cosine: int = 64

    def radiance(self, y: np.ndarray) -> np.ndarray:
        """Radiance (n, 3) arriving from world directions whose up components are ``y`` (n,)."""
        sky = np.add(
            self.horizon, np.outer(np.clip(y, 0, None), np.subtract(self.zenith, self.horizon))
        )
        t = np.clip((y + self.soft) / (2 * self.soft), 0.0, 1.0)[:, None]
        s = t * t * (3.0 - 2.0 * t)
        return s * sky + (1.0 - s) * np.asarray(self.ground)

    def half_vectors(self) -> np.ndarray:
        """The ``n_theta x n_phi`` local half vectors (K, 3)."""
        u = (np.arange(self.n_theta) + 0.5) / self.n_theta
        phi = (np.arange(self.n_phi) + 0.5) * 2.0 * np.pi / self.n_phi
        t, p = (a.ravel() for a in np.meshgrid((np.pi / 2) * u**2, phi, indexing="ij"))
        return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)

    def cosine_directions(self) -> np.ndarray:
        """The ``n_cosine`` local directions (K, 3) spread with density ``cos(theta) / pi``."""
        j = np.arange(self.n_cosine) + 0.5
        r, phi = np.sqrt(j / self.n_cosine), j * np.pi * (3.0 - np.sqrt(5.0))
        return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - r**2)], axis=-1)

    def solid_angle(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """The weight ``dw`` (n,) in sr of samples ``wi`` (n, 3) of either set, for ``wo``."""
        h = wi + wo
        h /= np.linalg.norm(h, axis=-1, keepdims=True)
        sin_h = np.hypot(h[:, 0], h[:, 1])
        u = np.sqrt(np.arctan2(sin_h, h[:, 2]) / (np.pi / 2))
        with np.errstate(divide="ignore"):  # h = n: infinite half-vector density, dw = 0
            dens_h = self.n_theta * self.n_phi / (8 * np.pi**2 * u * sin_h * np.sum(wi * h, -1))
        return 1.0 / (dens_h + self.n_cosine * wi[:, 2] / np.pi)


DEFAULT_LIGHT = (-0.45, 0.55, 0.70)
"""Direction toward the point light (world; normalised when used): upper left, front."""


def sphere_normals(size: int) -> tuple[np.ndarray, np.ndarray]:
    """World normals (size, size, 3) at pixel centres and the mask of pixels on the sphere."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    x, y = np.meshgrid(c, -c)  # row 0 is the top of the image (+y)
    r2 = x**2 + y**2
    inside = r2 < 1.0
    z = np.sqrt(np.clip(1.0 - r2, 0.0, None))
    return np.stack([x, y, z], axis=-1), inside


def _frame(n: np.ndarray) -> np.ndarray:
    """Rows (t, b, n) of each pixel's local frame, (P, 3, 3): world -> local is ``F @ v``.

    ``t`` is world x projected on the tangent plane (defined wherever ``n.z > 0``).
    """
    t = np.array([1.0, 0.0, 0.0]) - n[:, :1] * n
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    return np.stack([t, np.cross(n, t), n], axis=1)


@dataclass(frozen=True)
class _Quadrature:
    """The M (pixel, direction) pairs that light the sphere, flat; P pixels on the sphere."""

    inside: np.ndarray  # (size, size) pixels on the sphere, P of them
    pixel: np.ndarray  # (M,) which of the P pixels
    wi: np.ndarray  # (M, 3) local, above the horizon
    wo: np.ndarray  # (M, 3) local
    cos_dw: np.ndarray  # (M,) cos(theta_i) dw (sr); dw = 1 for the point light
    weight: np.ndarray  # (M, 3) incident radiance (irradiance for the point light) x cos_dw

    def integrate(self, f: np.ndarray, max_missing: float) -> np.ndarray:
        """``sum f weight`` per pixel as an image; NaN f left out, NaN over ``max_missing``."""
        p = int(self.inside.sum())
        missing = np.isnan(f).any(axis=-1)
        total = np.bincount(self.pixel, self.cos_dw, p)
        frac = np.bincount(self.pixel, self.cos_dw * missing, p) / np.maximum(total, 1e-300)
        f = np.where(np.isnan(f), 0.0, f) * self.weight
        rad = np.stack([np.bincount(self.pixel, f[:, c], p) for c in range(3)], axis=-1)
        out = np.zeros((*self.inside.shape, 3))
        out[self.inside] = np.where(frac[:, None] > max_missing, np.nan, rad)
        return out

    def evaluate(self, brdf: Brdf) -> np.ndarray:
        """``brdf`` (M, 3) at every pair."""
        return brdf(self.wi, self.wo)


def _quadrature(
    size: int, light: Sequence[float] | None, environment: Environment | None
) -> _Quadrature:
    normals, inside = sphere_normals(size)
    frame = _frame(normals[inside])
    wo = frame[:, :, 2]  # the camera looks along -z: wo is world +z in each local frame
    if environment is None:
        d = np.asarray(light, float) / np.linalg.norm(light)
        wi = frame @ d
        pix = np.flatnonzero(wi[:, 2] > 0.0)
        cos = wi[pix, 2]
        return _Quadrature(inside, pix, wi[pix], wo[pix], cos, np.repeat(cos[:, None], 3, 1))
    h = environment.half_vectors()
    cos_d = wo @ h.T  # (P, K)
    wi_z = 2.0 * cos_d * h[:, 2] - wo[:, 2:3]
    pix, k = np.nonzero((cos_d > 0.0) & (wi_z > 0.0))
    wi = 2.0 * cos_d[pix, k, None] * h[k] - wo[pix]
    cos_set = environment.cosine_directions()
    pix = np.concatenate([pix, np.repeat(np.arange(len(wo)), len(cos_set))])
    wi = np.concatenate([wi, np.tile(cos_set, (len(wo), 1))])
    cos_dw = wi[:, 2] * environment.solid_angle(wi, wo[pix])
    world_y = np.einsum("mj,mj->m", frame[:, :, 1][pix], wi)  # world up of wi: (F^T wi).y
    weight = environment.radiance(world_y) * cos_dw[:, None]
    return _Quadrature(inside, pix, wi, wo[pix], cos_dw, weight)


def render_sphere(
    brdf: Brdf,
    size: int,
    *,
    light: Sequence[float] | None = DEFAULT_LIGHT,
    environment: Environment | None = None,
    max_missing: float = 0.05,
) -> np.ndarray:
    """Linear RGB radiance (size, size, 3) of a sphere with BRDF ``brdf`` (module docstring).

    Arguments:
    - ``brdf``: ``f(wi, wo)`` on (n, 3) local directions -> (n, 3) in 1/sr, NaN = unmeasured.
    - ``size``: image side, pixels.
    - ``light``: direction toward a distant point light of unit irradiance (world);
      used when ``environment`` is None.
    - ``environment``: an :class:`Environment` instead of the point light.
    - ``max_missing``: a pixel is NaN when unmeasured directions carry more than this
      fraction of its ``sum cos(theta_i) dw``; below it they are left out (count 0).

    Returns: radiance, 0 outside the disk, NaN where the data are missing.
    """
    q = _quadrature(size, light, environment)
    return q.integrate(q.evaluate(brdf), max_missing)


def delta_e(a: np.ndarray, b: np.ndarray, exposure: float) -> np.ndarray:
    """CIEDE2000 colour difference (..., ) of two linear-RGB radiance images as displayed.

    Each image is scaled by ``exposure`` and clipped to [0, 1] (what :func:`tonemap`
    shows), read as linear sRGB, taken to CIE XYZ and CIELAB (D65 white) and compared
    with the CIEDE2000 formula (``colour-science``). 1 is about a just noticeable
    difference; a hue shift counts as much as a change of lightness. NaN in either
    image gives NaN.
    """
    import colour  # deferred: heavy, colour difference only

    def lab(x: np.ndarray) -> np.ndarray:
        rgb = np.clip(exposure * np.nan_to_num(x), 0.0, 1.0)
        return colour.XYZ_to_Lab(colour.RGB_to_XYZ(rgb, "sRGB"))

    out = np.asarray(colour.delta_E(lab(a), lab(b), method="CIE 2000"), float)
    return np.where(np.isnan(a).any(axis=-1) | np.isnan(b).any(axis=-1), np.nan, out)


def tonemap(radiance: np.ndarray, exposure: float) -> np.ndarray:
    """Display sRGB in [0, 1]: the sRGB transfer curve of ``clip(exposure radiance, 0, 1)``."""
    x = np.clip(exposure * np.nan_to_num(radiance), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def sphere_images(
    fit: Fit,
    data: Measurements,
    size: int,
    *,
    light: Sequence[float] | None = DEFAULT_LIGHT,
    environment: Environment | None = None,
    max_missing: float = 0.05,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Radiance images (size, size, 3) of the data, the fit, and the data as measured.

    The data image is :func:`render_sphere` (same arguments) of the data by
    :func:`nearest_bin` with unmeasured bins filled from their nearest measured bin, so
    it is whole wherever the data exist; the fit's is of the model. The third image is
    the data without filling: NaN where unmeasured directions carry more than
    ``max_missing`` of a pixel's cosine weight. Compare data and fit where it is finite.
    """
    _, f_model = model_brdf(fit)
    merl_stride(data)  # fail early, naming the data, when they are not on a grid
    q = _quadrature(size, light, environment)
    f_filled = q.evaluate(lambda wi, wo: nearest_bin(data, wi, wo, fill=True))
    f_data = q.evaluate(lambda wi, wo: nearest_bin(data, wi, wo))
    f_fit = q.evaluate(f_model)
    return tuple(q.integrate(f, max_missing) for f in (f_filled, f_fit, f_data))
