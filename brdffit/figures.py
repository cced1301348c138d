"""Pictures people look at: lit spheres, in-plane curves and theta_h x theta_d images.

Each figure takes a fit (a :class:`~brdffit.result.FitResult`, or a ``(model, params)``
pair) and the :class:`~brdffit.measurements.Measurements` it was fitted to, and returns
a matplotlib :class:`~matplotlib.figure.Figure` (``constrained_layout``, not registered
with pyplot, so nothing needs closing); nothing here calls a solver. The
data side needs samples on the MERL grid or a strided sub-grid of it
(:func:`brdffit.merl.merl_grid`): it is read by nearest-bin lookup, the MERL reader's
rule (:func:`brdffit.geometry.merl_indices`), a strided sample standing for its whole
coarse cell. A bin marked invalid (not measured, or its centre below the horizon)
gives NaN and is drawn in magenta, never as black.

Sphere set-up (:func:`render_sphere`): a unit sphere seen by an orthographic camera
along -z (image up = +y, right = +x), so ``wo`` is the world +z in each pixel's local
frame: the normal ``n`` as z, the world x axis projected on the tangent plane as the
tangent (defined on every visible pixel). Two lightings:

* a distant point light (a directional light) of unit irradiance normal to it:
  ``L = f(wi, wo) cos(theta_i)``;
* an environment, a sky/ground gradient (:class:`Environment`), integrated per pixel
  with a fixed quadrature of half vectors: ``L = sum_k f(wi_k, wo) L_env(wi_k)
  cos(theta_k) dw_k`` over the ``wi_k`` above the horizon (see :class:`Environment`).

Tone map: ``sRGB(clip(exposure L, 0, 1))`` with the exact sRGB transfer curve (IEC
61966-2-1); the exposure, the same for data and fit, is ``1 / (99th percentile of the
fit's brightest channel on the sphere)`` unless given, and is printed on the figure.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import matplotlib
import numpy as np
from matplotlib.figure import Figure

from brdffit.abstract_model import AbstractModel
from brdffit.errors import MeasurementsError
from brdffit.geometry import MERL_SHAPE, above_horizon, io_to_halfdiff, merl_indices
from brdffit.measurements import Measurements
from brdffit.merl import merl_grid
from brdffit.plots import model_of
from brdffit.result import FitResult

Fit = FitResult | tuple[AbstractModel, Mapping[str, object]]
Brdf = Callable[[np.ndarray, np.ndarray], np.ndarray]
INVALID_RGBA = (1.0, 0.0, 1.0, 1.0)
"""Magenta: pixels whose data bin is not measured."""
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
"""Rec. 709 / sRGB luminance weights of linear RGB."""
_ODD_DIVISORS = (1, 3, 5, 9, 15, 45)  # odd divisors of 90 and of 180
_CHUNK = 16384  # rows per jitted model evaluation


# --------------------------------------------------------------------------- model and data


def model_brdf(fit: Fit) -> tuple[AbstractModel, Brdf]:
    """The model of ``fit`` and ``f(wi, wo)`` -> (n, 3) numpy values in 1/sr (float64)."""
    if isinstance(fit, FitResult):
        model, params = model_of(fit), fit.params
    else:
        model, params = fit
    p = {k: jnp.asarray(v, float) for k, v in params.items()}

    def brdf(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        n = len(wi)
        up = np.broadcast_to([0.0, 0.0, 1.0], (-n % _CHUNK, 3))  # pad: one compiled shape
        pairs = jnp.asarray(np.stack([np.concatenate([wi, up]), np.concatenate([wo, up])]))
        out = [_eval(model, p, *pairs[:, i : i + _CHUNK]) for i in range(0, pairs.shape[1], _CHUNK)]
        return np.concatenate([np.asarray(o) for o in out])[:n]

    return model, brdf


@eqx.filter_jit
def _eval(model: AbstractModel, params: dict, wi: jax.Array, wo: jax.Array) -> jax.Array:
    return model.eval(params, wi, wo)


def merl_stride(data: Measurements) -> tuple[int, int, int]:
    """The stride of the MERL (sub-)grid ``data`` lies on, in file order.

    Raises :class:`MeasurementsError` naming the source when the samples are scattered
    directions rather than a MERL grid (:func:`brdffit.merl.merl_grid`).
    """
    if data.grid == MERL_SHAPE:
        return (1, 1, 1)
    for s in itertools.product(_ODD_DIVISORS, repeat=3):
        shape = [n // k for n, k in zip(MERL_SHAPE, s, strict=True)]
        if int(np.prod(shape)) != data.n:
            continue
        g = merl_grid(s)
        if all(
            np.allclose(getattr(g, a), getattr(data, a), rtol=0, atol=1e-9)
            for a in ("theta_h", "theta_d", "phi_d")
        ):
            return s
    raise MeasurementsError(
        f"{data.source!r}: {data.n} samples are not a MERL grid or strided sub-grid in file "
        "order; the data side of a figure needs one (read a MERL file, or resample)"
    )


def nearest_bin(data: Measurements, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Data values (n, 3) in 1/sr at arbitrary directions, by nearest MERL bin.

    As MERL's ``lookup_brdf_val`` (:func:`brdffit.merl.lookup`), on the full grid or a
    strided one (a sample stands for its coarse cell). Directions below the horizon give
    0; a bin that ``data.valid`` marks invalid gives NaN.
    """
    stride = np.array(merl_stride(data))
    shape = tuple(int(n) for n in np.array(MERL_SHAPE) // stride)
    th, td, pd, _ = io_to_halfdiff(wi, wo)
    fine = merl_indices(th, td, pd)
    flat = np.ravel_multi_index(tuple(i // s for i, s in zip(fine, stride, strict=True)), shape)
    out = np.where(data.valid[flat, None], data.values[flat], np.nan)
    out[~above_horizon(wi, wo)] = 0.0
    return out


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


def tonemap(radiance: np.ndarray, exposure: float) -> np.ndarray:
    """Display sRGB in [0, 1]: the sRGB transfer curve of ``clip(exposure radiance, 0, 1)``."""
    x = np.clip(exposure * np.nan_to_num(radiance), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def _auto_exposure(radiance: np.ndarray, inside: np.ndarray) -> float:
    peak = np.nanpercentile(radiance[inside].max(axis=-1), 99)
    return float(1.0 / peak) if np.isfinite(peak) and peak > 0 else 1.0


def _sphere_rgba(radiance: np.ndarray, inside: np.ndarray, exposure: float) -> np.ndarray:
    rgba = np.concatenate([tonemap(radiance, exposure), inside[..., None] * 1.0], axis=-1)
    rgba[inside & np.isnan(radiance).any(axis=-1)] = INVALID_RGBA
    return rgba


def sphere_images(
    fit: Fit,
    data: Measurements,
    size: int,
    *,
    light: Sequence[float] | None = DEFAULT_LIGHT,
    environment: Environment | None = None,
    max_missing: float = 0.05,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Radiance images (size, size, 3) of the data, the fit, and data minus fit.

    Each is :func:`render_sphere` (same arguments) of the data by :func:`nearest_bin`,
    of the fit, and of ``f_data - f_fit`` per direction, so that the directions the
    data miss are left out of both sides of the difference alike.
    """
    _, f_model = model_brdf(fit)
    merl_stride(data)  # fail early, naming the data, when they are not on a grid
    q = _quadrature(size, light, environment)
    f_data = q.evaluate(lambda wi, wo: nearest_bin(data, wi, wo))
    f_fit = q.evaluate(f_model)
    return tuple(q.integrate(f, max_missing) for f in (f_data, f_fit, f_data - f_fit))


def sphere_figure(
    fit: Fit,
    data: Measurements,
    *,
    size: int = 128,
    light: Sequence[float] = DEFAULT_LIGHT,
    environment: Environment | None = None,
    exposure: tuple[float, float] | None = None,
):
    """Spheres from the data and from the fit, and their difference, under two lightings.

    Rows: the point light, then the environment (module docstring). Columns: data
    (nearest bin), fit, and the luminance of ``(data - fit) x exposure`` (display units,
    1 = white) on a diverging scale (:func:`sphere_images`). Magenta: data not measured
    (under the environment: more than 5% of a pixel's cosine weight missing; less is
    left out of the data and of the difference).

    Arguments:
    - ``fit``: a :class:`FitResult` or ``(model, params)``; ``data``: MERL-grid measurements.
    - ``size``: pixels per sphere side; ``light``, ``environment``: as :func:`render_sphere`
      (default :class:`Environment`).
    - ``exposure``: (point light, environment) exposures; default from the fit's images.
    """
    env = environment or Environment()
    _, inside = sphere_normals(size)
    fig = Figure(figsize=(9.6, 6.4), layout="constrained")
    axes = fig.subplots(2, 3)
    lightings = (("point light", {"light": light}), ("environment", {"environment": env}))
    for row, (name, kw) in enumerate(lightings):
        measured, fitted, difference = sphere_images(fit, data, size, **kw)
        e = exposure[row] if exposure else _auto_exposure(fitted, inside)
        diff = np.where(inside, (difference @ LUMINANCE) * e, np.nan)
        finite = np.abs(diff[np.isfinite(diff)])
        lim = max(float(np.percentile(finite, 99)) if finite.size else 0.0, 0.02)
        axes[row, 0].imshow(_sphere_rgba(measured, inside, e), interpolation="nearest")
        axes[row, 1].imshow(_sphere_rgba(fitted, inside, e), interpolation="nearest")
        im = axes[row, 2].imshow(diff, cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest")
        bad = np.zeros((size, size, 4))
        bad[inside & np.isnan(measured).any(axis=-1)] = INVALID_RGBA
        axes[row, 2].imshow(bad, interpolation="nearest")
        fig.colorbar(im, ax=axes[row, 2], shrink=0.85, label="(data - fit) luminance x exposure")
        for ax, what in zip(axes[row], ("data", "fit", "difference"), strict=True):
            ax.set_title(f"{what}, {name}", fontsize=9)
            ax.set_axis_off()
        note = f"exposure {e:.3g}, sRGB"
        axes[row, 0].text(0, -0.04, note, transform=axes[row, 0].transAxes, fontsize=7, va="top")
    fig.suptitle(f"{_name(fit)} on {_short(data.source)}; magenta: not measured", fontsize=10)
    return fig


# --------------------------------------------------------------------------- in-plane curves


def in_plane_directions(
    theta_i_deg: float, theta_o_deg: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo) in the plane of incidence (x-z plane; ``phi_d = 0``).

    ``wi = (-sin theta_i, 0, cos theta_i)``, ``wo = (sin theta_o, 0, cos theta_o)``: a
    positive ``theta_o`` lies on the specular side (mirror direction at ``theta_o =
    theta_i``), a negative one on the side of the light (backscatter at ``-theta_i``).
    """
    to = np.deg2rad(np.asarray(theta_o_deg, float))
    ti = np.deg2rad(theta_i_deg)
    wi = np.broadcast_to([-np.sin(ti), 0.0, np.cos(ti)], (to.size, 3)).copy()
    wo = np.stack([np.sin(to), np.zeros_like(to), np.cos(to)], axis=-1)
    return wi, wo


def polar_figure(
    fit: Fit,
    data: Measurements,
    *,
    incidence_deg: Sequence[float] = (0.0, 20.0, 40.0, 60.0),
    n_angles: int = 179,
):
    """In-plane BRDF ``f`` (1/sr, no cosine) against the signed viewing angle, per channel.

    One panel per incidence angle; lines: the fit (``model.eval`` at
    :func:`in_plane_directions`), dots: the data by nearest bin (missing bins left out).
    Log y axis; the dotted line marks the mirror direction.
    """
    _, f_model = model_brdf(fit)
    theta_o = np.linspace(-89.0, 89.0, n_angles)
    k = len(incidence_deg)
    fig = Figure(figsize=(3.2 * k + 0.6, 3.6), layout="constrained")
    axes = fig.subplots(1, k, sharey=True, squeeze=False)
    for ax, ti in zip(axes[0], incidence_deg, strict=True):
        wi, wo = in_plane_directions(ti, theta_o)
        f_fit, f_data = f_model(wi, wo), nearest_bin(data, wi, wo)
        for c, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
            ax.semilogy(theta_o, f_fit[:, c], color=colour, lw=1.3, label=f"fit {'RGB'[c]}")
            ok = np.isfinite(f_data[:, c]) & (f_data[:, c] > 0)
            ax.semilogy(
                theta_o[ok], f_data[ok, c], ".", color=colour, ms=2.5, label=f"data {'RGB'[c]}"
            )
        ax.axvline(ti, color="0.5", lw=0.8, ls=":")
        ax.set_title(f"theta_i = {ti:g} deg", fontsize=9)
        ax.set_xlabel("theta_o (deg), + = specular side")
        ax.set_xlim(-90, 90)
        ax.set_xticks([-90, -60, -30, 0, 30, 60, 90])
    axes[0, 0].set_ylabel("f in the plane of incidence (1/sr)")
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside right upper", fontsize=8)
    fig.suptitle(f"{_name(fit)} on {_short(data.source)}: in-plane BRDF (phi_d = 0)", fontsize=10)
    return fig


# --------------------------------------------------------------------------- half/difference


def halfdiff_figure(fit: Fit, data: Measurements, *, channel: int = 1, phi_d_deg: float = 90.0):
    """Images over (theta_h, theta_d) of data, fit and ``ln(data / fit)``, one channel.

    The slice is the data's ``phi_d`` bin nearest ``phi_d_deg`` (the actual value is in
    the title); the fit is evaluated at the same bin-centre directions. theta_h runs on
    MERL's square-root axis (bin index), labelled in degrees. Grey: not measured.
    """
    _, f_model = model_brdf(fit)
    stride = merl_stride(data)
    shape = tuple(n // s for n, s in zip(MERL_SHAPE, stride, strict=True))
    pd_axis = data.phi_d.reshape(shape)[0, 0]
    k = int(np.argmin(np.abs(pd_axis - np.deg2rad(phi_d_deg))))
    cells = np.arange(data.n).reshape(shape)[:, :, k].ravel()
    valid = data.valid[cells]
    f_data = np.where(valid, data.values[cells, channel], np.nan).reshape(shape[:2])
    f_fit = f_model(data.wi[cells], data.wo[cells])[:, channel].reshape(shape[:2])
    with np.errstate(divide="ignore", invalid="ignore"):
        log_data, log_fit = np.log10(f_data), np.log10(f_fit)
        ratio = np.log(f_data / f_fit)
    ratio[~np.isfinite(ratio)] = np.nan
    u_edges = np.arange(shape[0] + 1) * stride[0] / MERL_SHAPE[0]  # u = sqrt(theta_h / 90 deg)
    td_edges = np.arange(shape[1] + 1) * stride[1] * 90.0 / MERL_SHAPE[1]
    both = np.concatenate([log_data[np.isfinite(log_data)], log_fit[np.isfinite(log_fit)]])
    lo, hi = np.percentile(both, [1, 100]) if both.size else (-1.0, 1.0)
    r = ratio[np.isfinite(ratio)]
    lim = max(float(np.percentile(np.abs(r), 99)) if r.size else 0.0, 0.05)
    fig = Figure(figsize=(12.5, 3.9), layout="constrained")
    axes = fig.subplots(1, 3, sharey=True)
    panels = (
        (log_data, "data", "viridis", lo, hi, f"log10 f_{'RGB'[channel]} (1/sr)"),
        (log_fit, "fit", "viridis", lo, hi, f"log10 f_{'RGB'[channel]} (1/sr)"),
        (ratio, "ln(data / fit)", "RdBu_r", -lim, lim, "ln(data / fit)"),
    )
    deg_ticks = np.array([0.0, 1.0, 5.0, 10.0, 20.0, 40.0, 60.0, 90.0])
    for ax, (img, title, cmap, vmin, vmax, label) in zip(axes, panels, strict=True):
        cm = matplotlib.colormaps[cmap].with_extremes(bad="0.75")
        mesh = ax.pcolormesh(
            u_edges, td_edges, np.ma.masked_invalid(img).T, cmap=cm, vmin=vmin, vmax=vmax
        )
        fig.colorbar(mesh, ax=ax, label=label, shrink=0.9)
        ax.set_xticks(np.sqrt(deg_ticks / 90.0), [f"{t:g}" for t in deg_ticks])
        ax.set_xlabel("theta_h (deg, square-root axis)")
        ax.set_title(title, fontsize=9)
    axes[0].set_ylabel("theta_d (deg)")
    fig.suptitle(
        f"{_name(fit)} on {_short(data.source)}: channel {'RGB'[channel]}, slice phi_d = "
        f"{np.rad2deg(pd_axis[k]):.1f} deg; grey: not measured",
        fontsize=10,
    )
    return fig


def _name(fit: Fit) -> str:
    return fit.model if isinstance(fit, FitResult) else fit[0].name


def _short(source: str, n: int = 48) -> str:
    """``source`` in ``n`` characters: the part before `` (`` (a path), else its end."""
    head = source.split(" (", 1)[0]
    return source if len(source) <= n else head if len(head) <= n else "..." + source[3 - n :]
