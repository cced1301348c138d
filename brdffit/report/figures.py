"""Pictures people look at: lit spheres, in-plane curves and theta_h x theta_d images.

Each figure takes a fit (a :class:`~brdffit.core.result.FitResult`, or a ``(model, params)``
pair) and the :class:`~brdffit.core.measurements.Measurements` it was fitted to, and returns
a matplotlib :class:`~matplotlib.figure.Figure` (``constrained_layout``, not registered
with pyplot, so nothing needs closing); nothing here calls a solver. The images and
curves come from :mod:`brdffit.report.render` (sphere set-up, lightings, nearest-bin lookup of
the data, which needs samples on the MERL grid or a strided sub-grid of it, and tone
map); this module lays them out. Data spheres are drawn from the data that exist (an
unmeasured bin takes its nearest measured bin's value); differences are shown in colour,
as CIEDE2000 between data and fit, and only where the data were measured (grey
elsewhere). A pixel with no data at all is magenta, never black.

Exposure: the same for data and fit, ``1 / (99th percentile of the fit's brightest
channel on the sphere)`` unless given, and printed on the figure.

:func:`plot_slices` draws data against several fitted models, ``f cos(theta_i)`` along
``theta_h``; :func:`brdffit.util.atomic.save_figure` saves any of them.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import matplotlib
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure

from brdffit import models
from brdffit.core.geometry import MERL_SHAPE, in_plane_directions
from brdffit.core.measurements import Measurements
from brdffit.core.result import FitResult
from brdffit.io.merl_grid import merl_stride, nearest_bin
from brdffit.report.lookup import (
    Fit,
    model_brdf,
    slice_indices,
)
from brdffit.report.render import (
    DEFAULT_LIGHT,
    Environment,
    delta_e,
    sphere_images,
    sphere_normals,
    tonemap,
)

INVALID_RGBA = (1.0, 0.0, 1.0, 1.0)
"""Magenta: pixels with no data at all."""
UNMEASURED_RGBA = (0.75, 0.75, 0.75, 1.0)
"""Grey: difference pixels whose data rest on unmeasured bins (filled for display only)."""
NONPOSITIVE_COLOUR = "#ff7f0e"
"""Orange: cells measured at or below 0, which a log scale cannot place (measurement
noise around 0 near a peak, or a calibration offset); they are data, never "not
measured"."""
NONPOSITIVE_LABEL = "measured <= 0"
HORIZON_NOTE = (
    "environment: bright sky above, dark ground below; the band across each sphere's "
    "middle is the horizon, not a seam"
)
"""In the sphere figure's title: the change across the environment spheres' equator is
the environment's horizon (:class:`~brdffit.report.render.Environment`), seen by the
normals that face it, not a seam in the rendering."""


# --------------------------------------------------------------------------- sphere


def _auto_exposure(radiance: np.ndarray, inside: np.ndarray) -> float:
    peak = np.nanpercentile(radiance[inside].max(axis=-1), 99)
    return float(1.0 / peak) if np.isfinite(peak) and peak > 0 else 1.0


def _sphere_rgba(radiance: np.ndarray, inside: np.ndarray, exposure: float) -> np.ndarray:
    rgba = np.concatenate([tonemap(radiance, exposure), inside[..., None] * 1.0], axis=-1)
    rgba[inside & np.isnan(radiance).any(axis=-1)] = INVALID_RGBA
    return rgba


def sphere_figure(
    fit: Fit,
    data: Measurements,
    *,
    size: int = 128,
    light: Sequence[float] = DEFAULT_LIGHT,
    environment: Environment | None = None,
    exposure: tuple[float, float] | None = None,
):
    """Spheres from the data and from the fit, and their colour difference, two lightings.

    Rows: the point light, then the environment (:mod:`brdffit.report.render`). Columns: data
    (nearest bin; unmeasured bins filled from the nearest measured one), fit, and the
    CIEDE2000 difference of the two as displayed (:func:`~brdffit.report.render.delta_e`),
    grey where the data were not measured (under the environment: more than 5% of a
    pixel's cosine weight on unmeasured bins). Under each difference: the mean colour
    ratio data / fit per channel over the measured pixels, the tint a grey difference
    would hide. The title says what the band across the environment spheres is
    (:data:`HORIZON_NOTE`).

    Arguments:
    - ``fit``: a :class:`FitResult` or ``(model, params)``; ``data``: MERL-grid measurements.
    - ``size``: pixels per sphere side; ``light``, ``environment``: as
      :func:`~brdffit.report.render.render_sphere` (default
      :class:`~brdffit.report.render.Environment`).
    - ``exposure``: (point light, environment) exposures; default from the fit's images.
    """
    env = environment or Environment()
    _, inside = sphere_normals(size)
    fig = Figure(figsize=(9.6, 6.4), layout="constrained")
    axes = fig.subplots(2, 3)
    lightings = (("point light", {"light": light}), ("environment", {"environment": env}))
    for row, (name, kw) in enumerate(lightings):
        shown, fitted, measured = sphere_images(fit, data, size, **kw)
        e = exposure[row] if exposure else _auto_exposure(fitted, inside)
        diff = np.where(inside, delta_e(measured, fitted, e), np.nan)
        finite = diff[np.isfinite(diff)]
        lim = max(float(np.percentile(finite, 99)) if finite.size else 0.0, 5.0)
        axes[row, 0].imshow(_sphere_rgba(shown, inside, e), interpolation="nearest")
        axes[row, 1].imshow(_sphere_rgba(fitted, inside, e), interpolation="nearest")
        im = axes[row, 2].imshow(diff, cmap="magma", vmin=0, vmax=lim, interpolation="nearest")
        bad = np.zeros((size, size, 4))
        bad[inside & np.isnan(measured).any(axis=-1)] = UNMEASURED_RGBA
        axes[row, 2].imshow(bad, interpolation="nearest")
        fig.colorbar(im, ax=axes[row, 2], shrink=0.85, label="CIEDE2000, data vs fit")
        for ax, what in zip(axes[row], ("data", "fit", "colour difference"), strict=True):
            ax.set_title(f"{what}, {name}", fontsize=9)
            ax.set_axis_off()
        note = f"exposure {e:.3g}, sRGB"
        axes[row, 0].text(0, -0.04, note, transform=axes[row, 0].transAxes, fontsize=7, va="top")
        ratio = colour_ratio(measured, fitted, inside)
        axes[row, 2].text(
            0,
            -0.04,
            "data / fit: " + "  ".join(f"{c} {r:.3f}" for c, r in zip("RGB", ratio, strict=True)),
            transform=axes[row, 2].transAxes,
            fontsize=7,
            va="top",
        )
    fig.suptitle(
        f"{_name(fit)} on {_short(data.source)}; grey: not measured (data shown filled)\n"
        f"{HORIZON_NOTE}",
        fontsize=10,
    )
    return fig


def colour_ratio(data: np.ndarray, fit: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """(3,) mean radiance of the data over that of the fit per channel, over the pixels
    where the data image is finite (NaN where the fit's mean is 0)."""
    ok = inside & np.isfinite(data).all(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return data[ok].sum(axis=0) / fit[ok].sum(axis=0)


# --------------------------------------------------------------------------- in-plane curves


def polar_figure(
    fit: Fit,
    data: Measurements,
    *,
    incidence_deg: Sequence[float] = (0.0, 20.0, 40.0, 60.0),
    n_angles: int = 179,
):
    """In-plane BRDF ``f`` (1/sr, no cosine) against the signed viewing angle, per channel.

    One panel per incidence angle; lines: the fit (``model.eval`` at
    :func:`~brdffit.core.geometry.in_plane_directions`), dots: the data by nearest bin (missing
    bins left out; data measured at or below 0 as orange triangles on the axis floor,
    :func:`mark_nonpositive`). Log y axis; the dotted line marks the mirror direction.
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
        low = np.isfinite(f_data) & (f_data <= 0) & (np.abs(theta_o) < 90)[:, None]
        mark_nonpositive(ax, [theta_o[low[:, c]] for c in range(3)])
        ax.axvline(ti, color="0.5", lw=0.8, ls=":")
        ax.set_title(f"theta_i = {ti:g} deg", fontsize=9)
        ax.set_xlabel("theta_o (deg), + = specular side")
        ax.set_xlim(-90, 90)
        ax.set_xticks([-90, -60, -30, 0, 30, 60, 90])
    axes[0, 0].set_ylabel("f in the plane of incidence (1/sr)")
    fig.legend(*_legend_entries(axes[0]), loc="outside right upper", fontsize=8)
    fig.suptitle(f"{_name(fit)} on {_short(data.source)}: in-plane BRDF (phi_d = 0)", fontsize=10)
    return fig


# --------------------------------------------------------------------------- half/difference


def halfdiff_figure(
    fit: Fit, data: Measurements, *, channel: int | None = None, phi_d_deg: float = 90.0
):
    """Images over (theta_h, theta_d) of data, fit and ``ln(data / fit)``, one channel.

    The slice is the data's ``phi_d`` bin nearest ``phi_d_deg`` (the actual value is in
    the title); the fit is evaluated at the same bin-centre directions. theta_h runs on
    MERL's square-root axis (bin index), labelled in degrees. Grey: not measured; orange:
    measured at or below 0 (no logarithm; counted in the title). ``channel`` None shows
    the channel with the largest RMS ``ln(data / fit)`` over the slice, and the title
    gives all three, so a colour error shows even where the luminance fits.
    """
    _, f_model = model_brdf(fit)
    stride = merl_stride(data)
    shape = tuple(n // s for n, s in zip(MERL_SHAPE, stride, strict=True))
    pd_axis = data.phi_d.reshape(shape)[0, 0]
    k = int(np.argmin(np.abs(pd_axis - np.deg2rad(phi_d_deg))))
    cells = np.arange(data.n).reshape(shape)[:, :, k].ravel()
    f_all = np.where(data.channel_valid[cells], data.values[cells], np.nan)
    fit_all = f_model(data.wi[cells], data.wo[cells])
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = np.log(f_all / fit_all)
    ratios[~np.isfinite(ratios)] = np.nan
    rms = np.array([np.sqrt(np.nanmean(r**2)) if np.isfinite(r).any() else 0.0 for r in ratios.T])
    channel = int(np.argmax(rms)) if channel is None else channel
    f_data = f_all[:, channel].reshape(shape[:2])
    f_fit = fit_all[:, channel].reshape(shape[:2])
    ratio = ratios[:, channel].reshape(shape[:2])
    nonpositive = (f_data <= 0).T  # measured (f_all is NaN where not), but no logarithm
    with np.errstate(divide="ignore", invalid="ignore"):
        log_data, log_fit = np.log10(f_data), np.log10(f_fit)
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
        if title != "fit" and nonpositive.any():
            ax.pcolormesh(u_edges, td_edges, np.ma.masked_where(~nonpositive, nonpositive),
                          cmap=ListedColormap([NONPOSITIVE_COLOUR]))  # fmt: skip
        ax.set_xticks(np.sqrt(deg_ticks / 90.0), [f"{t:g}" for t in deg_ticks])
        ax.set_xlabel("theta_h (deg, square-root axis)")
        ax.set_title(title, fontsize=9)
    axes[0].set_ylabel("theta_d (deg)")
    per = ", ".join(f"{c} {v:.3f}" for c, v in zip("RGB", rms, strict=True))
    n_low = int(nonpositive.sum())
    low = f"; orange: {n_low} cells {NONPOSITIVE_LABEL}" if n_low else ""
    fig.suptitle(
        f"{_name(fit)} on {_short(data.source)}: channel {'RGB'[channel]}, slice phi_d = "
        f"{np.rad2deg(pd_axis[k]):.1f} deg; grey: not measured{low}\n"
        f"RMS ln(data / fit) over the slice: {per}",
        fontsize=10,
    )
    return fig


# --------------------------------------------------------------------------- slices


def plot_slices(
    data: Measurements,
    results: Sequence[FitResult],
    *,
    theta_d_deg: Sequence[float] = (5.0, 30.0, 60.0),
    phi_d_deg: float = 90.0,
    channel: int = 1,
) -> Figure:
    """``f cos(theta_i)`` against ``theta_h`` at a few ``theta_d``, data dots and model lines.

    The samples nearest to each (theta_d, phi_d) line are taken from ``data`` (valid
    samples only, :func:`brdffit.report.lookup.slice_indices`); the y axis is logarithmic,
    and data measured at or below 0 are orange triangles on its floor (:func:`mark_nonpositive`).
    """
    fig = Figure(figsize=(4.2 * len(theta_d_deg), 3.6), layout="constrained")
    axes = fig.subplots(1, len(theta_d_deg), sharey=True, squeeze=False)
    lows = []
    for ax, t in zip(axes[0], theta_d_deg, strict=True):
        idx, near_td, near_pd = slice_indices(data, t, phi_d_deg)
        th = np.rad2deg(data.theta_h[idx])
        cos_i = data.wi[idx, 2]
        y = data.values[idx, channel] * cos_i
        ax.semilogy(th, y, ".", color="k", ms=3, label="data")
        lows.append((ax, th[y <= 0]))
        for r in results:
            m = models.model_of(r)
            f = np.asarray(
                m.eval({k: jnp.asarray(v) for k, v in r.params.items()}, data.wi[idx], data.wo[idx])
            )
            ax.semilogy(
                th, np.maximum(f[:, channel] * cos_i, 1e-8), label=f"{r.model} ({r.loss:.3g})"
            )
        ax.set_title(f"theta_d = {near_td:.1f} deg, phi_d = {near_pd:.0f} deg")
        ax.set_xlabel("theta_h (deg)")
    for ax, x in lows:  # after every line: the shared floor is final
        mark_nonpositive(ax, [x])
    axes[0][0].set_ylabel(f"f cos theta_i, channel {'RGB'[channel]} (1/sr)")
    axes[0][-1].legend(fontsize=7)
    return fig


def mark_nonpositive(ax, xs: Sequence[np.ndarray]) -> None:
    """Data measured at or below 0 on a log-y axis: orange triangles on the axis floor at
    each x of ``xs`` (one array per series), labelled once, so that no measured value
    vanishes from a log plot. The floor is the lower y limit after the other data."""
    x = np.concatenate([np.asarray(v, float) for v in xs]) if len(xs) else np.zeros(0)
    if x.size == 0:
        return
    ax.autoscale_view()
    floor = ax.get_ylim()[0]
    ax.plot(x, np.full(x.size, floor), "v", color=NONPOSITIVE_COLOUR, ms=4, clip_on=False,
            label=f"{NONPOSITIVE_LABEL} (at the floor)")  # fmt: skip
    ax.set_ylim(bottom=floor)


def _legend_entries(axes) -> tuple[list, list]:
    """Legend handles and labels of all ``axes``, each label once (first axes first)."""
    out: dict[str, object] = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            out.setdefault(lab, h)
    return list(out.values()), list(out)


def _name(fit: Fit) -> str:
    return fit.model if isinstance(fit, FitResult) else fit[0].name


def _short(source: str, n: int = 48) -> str:
    """``source`` in ``n`` characters: the part before `` (`` (a path), else its end."""
    head = source.split(" (", 1)[0]
    return source if len(source) <= n else head if len(head) <= n else "..." + source[3 - n :]
