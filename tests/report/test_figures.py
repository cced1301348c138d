"""Figures from results: spheres, in-plane curves, theta_h x theta_d images.

Each check is against something independent of the figure code: the closed-form
Lambert shading, MERL's reference lookup, model.eval at hand-built directions, or a
data set made from the very model drawn beside it (difference and log-ratio ~ 0).
"""

from __future__ import annotations

import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from brdffit import Measurements, MeasurementsError, models, synthesize
from brdffit.core.geometry import in_plane_directions, io_to_halfdiff, merl_indices
from brdffit.io.merl_grid import (
    lookup,
    merl_grid,
    merl_grid_measurements,
    merl_stride,
    merl_subgrid,
    nearest_bin,
)
from brdffit.report.figures import halfdiff_figure, plot_slices, polar_figure, sphere_figure
from brdffit.report.lookup import (
    model_brdf,
    slice_indices,
)
from brdffit.report.render import (
    DEFAULT_LIGHT,
    Environment,
    render_sphere,
    sphere_images,
    sphere_normals,
    tonemap,
)
from tests.helpers import random_pairs

KD = np.array([0.2, 0.5, 0.8])
LAMBERT = (models.get("lambert"), {"kd": KD})
WALTER = (models.get("walter"), {**models.get("walter").defaults(), "alpha": jnp.asarray(0.15)})


@pytest.fixture(scope="module")
def lambert_data() -> Measurements:
    return synthesize(LAMBERT[0], {"kd": KD}, stride=5)


@pytest.fixture(scope="module")
def walter_data() -> Measurements:
    return synthesize(WALTER[0], WALTER[1], stride=5)


def _labels_inside(fig) -> None:
    """Everything the figure draws (titles, tick and colour-bar labels) lies inside it."""
    canvas = FigureCanvasAgg(fig)  # what savefig draws with
    canvas.draw()
    tight = fig.get_tightbbox(canvas.get_renderer())  # inches, drawn artists only
    width, height = fig.get_size_inches()
    assert tight.x0 >= -0.01 and tight.y0 >= -0.01, tight
    assert tight.x1 <= width + 0.01 and tight.y1 <= height + 0.01, (tight, width, height)


def test_point_light_lambert_is_the_cosine_law():
    n, inside = sphere_normals(40)
    light = np.array(DEFAULT_LIGHT) / np.linalg.norm(DEFAULT_LIGHT)
    expected = KD / np.pi * np.clip(n @ light, 0, None)[..., None] * inside[..., None]
    image = render_sphere(lambda wi, wo: np.broadcast_to(KD / np.pi, wi.shape), 40)
    assert np.abs(image - expected).max() < 1e-14
    assert (image[inside].max(axis=1) > 0).mean() > 0.5  # the lit side is there


def test_point_light_highlight_sits_where_the_normal_is_the_half_vector():
    # a sharp Blinn-Phong lobe peaks where n = normalize(l + v), v = +z toward the camera
    model = models.get("blinn_phong")
    params = {"kd": np.zeros(3), "ks": np.full(3, 0.5), "n": 5000.0}
    _, brdf = model_brdf((model, params))
    image = render_sphere(brdf, 64)
    light = np.array(DEFAULT_LIGHT) / np.linalg.norm(DEFAULT_LIGHT)
    h = (light + [0, 0, 1]) / np.linalg.norm(light + [0, 0, 1])
    row, col = np.unravel_index(np.argmax(image[..., 0]), image.shape[:2])
    x, y = (col + 0.5) / 32 - 1, 1 - (row + 0.5) / 32  # pixel centre, image up = +y
    assert np.hypot(x - h[0], y - h[1]) < 1.5 / 32  # within a pixel and a half


def test_environment_quadrature_integrates_the_cosine():
    # uniform unit radiance: a Lambert sphere has radiance kd wherever it is (irradiance
    # pi); the default quadrature integrates cos over the hemisphere to 1.5% (measured),
    # 2.5% leaves room for nothing else
    white = Environment(zenith=(1.0, 1.0, 1.0), horizon=(1.0, 1.0, 1.0), ground=(1.0, 1.0, 1.0))
    _, inside = sphere_normals(40)
    image = render_sphere(
        lambda wi, wo: np.broadcast_to(KD / np.pi, wi.shape), 40, environment=white
    )
    assert np.abs(image[inside] / KD - 1).max() < 0.025
    assert np.all(image[~inside] == 0)


@pytest.mark.parametrize("lighting", ["light", "environment"])
def test_sphere_from_lambert_data_equals_the_model(lambert_data, lighting):
    # the bins that miss are those with centres below the horizon (grazing); under the
    # environment a pixel is kept only when none of its directions misses (max_missing=0)
    kw = {"environment": Environment()} if lighting == "environment" else {}
    shown, fitted, measured = sphere_images(LAMBERT, lambert_data, 32, max_missing=0.0, **kw)
    _, inside = sphere_normals(32)
    ok = inside & np.isfinite(measured).all(axis=-1)
    assert ok.sum() > {"light": 0.9, "environment": 0.3}[lighting] * inside.sum()
    assert np.abs(measured[ok] - fitted[ok]).max() < 1e-12
    # the shown data sphere is whole: the grazing bins are filled from measured ones,
    # which hold the same constant here
    assert np.isfinite(shown[inside]).all()
    assert np.abs(shown[inside] - fitted[inside]).max() < 1e-12


def test_sphere_figure_panels(lambert_data):
    fig = sphere_figure(LAMBERT, lambert_data, size=32)
    panels = [ax for ax in fig.axes if ax.images]
    assert len(panels) == 6
    data_rgba, fit_rgba = (np.asarray(panels[i].images[0].get_array()) for i in (0, 1))
    _, inside = sphere_normals(32)
    assert not np.all(data_rgba[inside] == (1.0, 0.0, 1.0, 1.0), axis=-1).any()  # no magenta
    assert np.abs(data_rgba[inside] - fit_rgba[inside]).max() < 1e-9
    assert np.nanmax(np.abs(panels[2].images[0].get_array())) < 1e-6  # CIEDE2000
    _labels_inside(fig)
    plt.close(fig)


def test_a_colour_error_of_equal_luminance_shows_in_the_difference(lambert_data):
    """A fit with the data's luminance and another hue (teal data, pink fit): the
    luminance of the difference is 0, its colour difference is not."""
    lum = np.array([0.2126, 0.7152, 0.0722])
    pink = np.array([0.8, 0.35, 0.5])
    pink *= (KD @ lum) / (pink @ lum)
    fig = sphere_figure((LAMBERT[0], {"kd": pink}), lambert_data, size=32)
    de = np.asarray(fig.axes[2].images[0].get_array())
    assert np.nanmedian(de[sphere_normals(32)[1]]) > 10  # far beyond a just noticeable 1
    text = " ".join(t.get_text() for t in fig.axes[2].texts)
    ratio = KD / pink
    assert all(f"{c} {r:.3f}" in text for c, r in zip("RGB", ratio, strict=True)), text
    plt.close(fig)


def test_a_sphere_with_a_hole_in_the_data_is_drawn_whole(lambert_data):
    """Unmeasured bins (a third of the grid, every channel) are filled for display from
    measured neighbours; the difference panel marks them instead of comparing."""
    holes = np.arange(lambert_data.n) % 3 == 0
    data = lambert_data.replace(valid=lambert_data.valid & ~holes)
    shown, fitted, measured = sphere_images(LAMBERT, data, 24, environment=Environment())
    _, inside = sphere_normals(24)
    assert np.isfinite(shown[inside]).all()
    assert np.isnan(measured[inside]).any()


def test_tonemap_is_srgb():
    # sRGB (IEC 61966-2-1): linear 0.5 -> 0.735357, 0.002 -> 12.92 x 0.002; 1 and above -> 1
    out = tonemap(np.array([0.5, 0.002, 1.0, 7.0, -1.0]), 1.0)
    assert out == pytest.approx([0.735357, 0.02584, 1.0, 1.0, 0.0], abs=1e-6)
    assert tonemap(np.array([0.25]), 2.0) == pytest.approx(0.735357, abs=1e-6)


@pytest.fixture(scope="module")
def indexed_table() -> Measurements:
    """A full MERL table whose value is the cell's flat index, a quarter of it unmeasured."""
    g = merl_grid()
    idx = np.arange(g.n, dtype=float)
    valid = (np.arange(g.n) % 4 != 0).reshape(g.shape)
    return merl_grid_measurements(np.stack([idx] * 3).reshape(3, *g.shape), source="t", valid=valid)


def test_nearest_bin_is_merls_lookup(indexed_table):
    wi, wo = random_pairs(0, 5000)
    got = nearest_bin(indexed_table, wi, wo)
    ref = lookup(indexed_table, wi, wo)
    measured = indexed_table.valid[ref[:, 0].astype(int)]
    assert np.array_equal(got[measured], ref[measured])
    assert np.isnan(got[~measured]).all()


@pytest.mark.parametrize("stride", [(3, 5, 9), (15, 15, 15)])
def test_nearest_bin_on_a_subgrid_is_the_coarse_cell_around_the_direction(indexed_table, stride):
    sub = merl_subgrid(indexed_table, stride)
    assert merl_stride(sub) == stride
    wi, wo = random_pairs(1, 5000)
    got = nearest_bin(sub.replace(valid=np.ones(sub.n, bool)), wi, wo)[:, 0]
    # the picked sample is the centre bin of the block of `stride` fine bins holding the query
    fine = np.stack(merl_indices(*io_to_halfdiff(wi, wo)[:3]), axis=1)
    picked = np.stack(np.unravel_index(got.astype(int), (90, 90, 180)), axis=1)
    assert np.array_equal(picked // stride, fine // stride)
    assert np.array_equal(picked % stride, np.broadcast_to(np.array(stride) // 2, picked.shape))


def test_scattered_data_are_refused_naming_the_source():
    wi, wo = random_pairs(2, 100)
    data = Measurements.from_directions(wi, wo, np.full((100, 3), 0.1), source="gonio.csv")
    with pytest.raises(MeasurementsError, match="gonio.csv"):
        polar_figure(LAMBERT, data)


def test_in_plane_directions_are_in_the_plane():
    theta_o = np.linspace(-80, 80, 33)
    wi, wo = in_plane_directions(30.0, theta_o)
    th, td, pd, _ = io_to_halfdiff(wi, wo)
    defined = td > 1e-6  # phi_d is arbitrary at wi = wo (backscatter, theta_o = -30)
    assert np.allclose(np.sin(pd[defined]), 0, atol=1e-12)  # phi_d = 0 or pi: in the plane
    assert np.allclose(np.rad2deg(th), np.abs(theta_o - 30.0) / 2, atol=1e-9)  # mirror at +30


def test_polar_lines_are_model_eval(walter_data):
    model, params = WALTER
    fig = polar_figure(WALTER, walter_data, incidence_deg=(0.0, 45.0))
    axes = [ax for ax in fig.axes if ax.get_lines()]
    assert len(axes) == 2
    for ax, ti in zip(axes, (0.0, 45.0), strict=True):
        for c in range(3):
            (line,) = [ln for ln in ax.get_lines() if ln.get_label() == f"fit {'RGB'[c]}"]
            to = np.deg2rad(line.get_xdata())
            s, c_ = np.sin(np.deg2rad(ti)), np.cos(np.deg2rad(ti))
            wi = np.stack([np.full_like(to, -s), 0 * to, np.full_like(to, c_)], axis=1)
            wo = np.stack([np.sin(to), 0 * to, np.cos(to)], axis=1)
            f = np.asarray(model.eval(params, wi, wo))[:, c]
            assert np.allclose(line.get_ydata(), f, rtol=1e-12, atol=0)
    assert axes[0].get_yscale() == "log"
    _labels_inside(fig)
    plt.close(fig)


def test_polar_dots_are_the_data(lambert_data):
    fig = polar_figure(LAMBERT, lambert_data, incidence_deg=(30.0,))
    ax = next(ax for ax in fig.axes if ax.get_lines())
    for c in range(3):
        (dots,) = [ln for ln in ax.get_lines() if ln.get_label() == f"data {'RGB'[c]}"]
        assert len(dots.get_xdata()) > 150  # all but the bins centred below the horizon
        assert np.allclose(dots.get_ydata(), KD[c] / np.pi, rtol=1e-12, atol=0)
    plt.close(fig)


def test_halfdiff_of_data_from_the_model_has_zero_log_ratio(walter_data):
    fig = halfdiff_figure(WALTER, walter_data, channel=0)
    meshes = [ax.collections[0] for ax in fig.axes if ax.get_label() != "<colorbar>"]
    assert len(meshes) == 3
    data_img, fit_img, ratio = (np.ma.filled(m.get_array(), np.nan) for m in meshes)
    assert np.nanmax(np.abs(ratio)) < 1e-9
    assert np.allclose(data_img, fit_img, equal_nan=True)
    # the slice is the phi_d bin nearest 90 deg: its values, theta_h along x
    cube = walter_data.values[:, 0].reshape(18, 18, 36)
    k = np.argmin(np.abs(np.rad2deg(walter_data.phi_d.reshape(18, 18, 36)[0, 0]) - 90))
    ok = walter_data.valid.reshape(18, 18, 36)[:, :, k]
    assert np.allclose(data_img.reshape(18, 18).T[ok], np.log10(cube[:, :, k][ok]))
    _labels_inside(fig)
    plt.close(fig)


def _with_nonpositive(data: Measurements, channel: int = 1) -> tuple[Measurements, np.ndarray]:
    """``data`` with its measured ``channel`` at or below 0 (alternately 0 and -0.05 1/sr)
    in every other bin near the peak (theta_h < 8 deg), as measured noise around 0 is."""
    v = data.values.copy()
    idx = np.flatnonzero(data.valid & (data.theta_h < np.deg2rad(8.0)))[::2]
    v[idx, channel] = np.where(np.arange(idx.size) % 2, 0.0, -0.05)
    return data.replace(values=v), idx


def test_values_measured_at_or_below_zero_are_drawn_as_measured(walter_data):
    """A log scale cannot place them: they are marked (orange), counted, never grey."""
    data, idx = _with_nonpositive(walter_data)
    fig = halfdiff_figure(WALTER, data, channel=1)
    shape = (18, 18, 36)
    k = np.argmin(np.abs(np.rad2deg(data.phi_d.reshape(shape)[0, 0]) - 90))
    low = np.zeros(data.n, bool)
    low[idx] = True
    want = low.reshape(shape)[:, :, k].T  # (theta_d, theta_h), the image's orientation
    panels = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    for ax, marked in zip(panels, (True, False, True), strict=True):  # data, fit, ratio
        overlays = ax.collections[1:]
        if not marked:
            assert not overlays
            continue
        (overlay,) = overlays
        got = ~np.ma.getmaskarray(overlay.get_array()).reshape(want.shape)
        np.testing.assert_array_equal(got, want)
    assert f"orange: {int(want.sum())} cells measured <= 0" in fig._suptitle.get_text()
    assert want.sum() > 0
    plt.close(fig)

    fig = polar_figure(WALTER, data, incidence_deg=(30.0,))
    ax = next(ax for ax in fig.axes if ax.get_lines())
    wi, wo = in_plane_directions(30.0, np.linspace(-89.0, 89.0, 179))
    ref = nearest_bin(data, wi, wo)
    n_low = int((np.isfinite(ref) & (ref <= 0)).sum())
    (marks,) = [ln for ln in ax.get_lines() if ln.get_label().startswith("measured <= 0")]
    assert n_low > 0 and len(marks.get_xdata()) == n_low
    assert np.all(marks.get_ydata() == ax.get_ylim()[0])  # on the axis floor, in view
    plt.close(fig)

    td, pd = np.rad2deg(data.theta_d[idx[0]]), np.rad2deg(data.phi_d[idx[0]])  # a low cell
    fig = plot_slices(data, [], theta_d_deg=(td, 60.0), phi_d_deg=pd, channel=1)
    for ax, t in zip(fig.axes, (td, 60.0), strict=True):
        sel, _, _ = slice_indices(data, t, pd)
        n_low = int((data.values[sel, 1] <= 0).sum())
        marks = [ln for ln in ax.get_lines() if ln.get_label().startswith("measured <= 0")]
        got = len(marks[0].get_xdata()) if marks else 0
        assert got == n_low and (t != td or n_low > 0), (t, got, n_low)
        assert not marks or np.all(marks[0].get_ydata() == ax.get_ylim()[0])
    plt.close(fig)


def test_the_environment_spheres_say_what_the_band_across_them_is(lambert_data):
    """The sky/ground horizon crosses every environment sphere; unexplained, it reads as a
    rendering seam. The figure's title says what it is."""
    fig = sphere_figure(LAMBERT, lambert_data, size=16)
    assert "the band across each sphere's middle is the horizon" in fig._suptitle.get_text()
    plt.close(fig)
