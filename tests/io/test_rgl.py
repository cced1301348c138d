"""RGL-EPFL ``.bsdf`` files through Mitsuba 3, on files the tests write (tests/rgl_fixture.py).

Exactness: a table multilinear in the plugin's interpolation coordinates is reproduced
to float32 by Mitsuba, so the reader must return the closed form divided by cos(theta_o)
to float32 precision; any slip in the directions (wi/wo swapped, the wrong cosine, the
relative azimuth) breaks that. A Lambertian file checks a physical BRDF against the
interpolation error bound.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import json

import numpy as np
import pytest

import brdffit
from brdffit import (
    MeasurementFileError,
    MissingDependencyError,
    ParameterError,
    load_measurements,
    models,
    read_merl,
    read_rgl,
    read_rgl_at,
    write_merl,
)
from brdffit.cli import main
from brdffit.core.geometry import MERL_SHAPE
from brdffit.io import rgl
from brdffit.io.merl_grid import merl_grid
from brdffit.io.rgl import rgl_header
from brdffit.sweep import rgl_materials
from tests import rgl_fixture as fx

pytest.importorskip("mitsuba")  # the reader evaluates files through it

F32 = 2e-6  # float32 tables and Mitsuba's float32 arithmetic: a few ulp (1.2e-7) per step
KD = (0.2, 0.5, 0.8)


def _directions(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n pairs over the upper hemisphere, away from the relative-azimuth wrap."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2, n, 3))
    v[..., 2] = np.abs(v[..., 2])
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return v[0], v[1]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("rgl")
    out = {
        (a, j): fx.linear_file(d / f"lin_{a}_{j}.bsdf", anisotropic=a, jacobian=j)
        for a in (False, True)
        for j in (False, True)
    }
    out["spectral"] = fx.linear_file(d / "spec.bsdf", spectral=True)
    out["lambert"] = fx.lambert_file(d / "lambert.bsdf", KD)
    return out


def test_header_is_read_without_mitsuba(files):
    h = rgl_header(files[(True, True)])
    assert not h.isotropic and not h.spectral and h.description == "brdffit test: multilinear"
    np.testing.assert_allclose(h.theta_i_deg, np.degrees(fx.THETA_I), rtol=1e-6)
    assert h.resolution == (fx.N_U, fx.N_U)
    assert rgl_header(files[(False, False)]).isotropic and rgl_header(files["spectral"]).spectral


@pytest.mark.parametrize("anisotropic", [False, True])
@pytest.mark.parametrize("jacobian", [False, True])
def test_values_are_eval_over_cos_theta_o_exactly(files, anisotropic, jacobian):
    wi, wo = _directions(1500, seed=int(anisotropic) + 2 * int(jacobian))
    data = read_rgl_at(files[(anisotropic, jacobian)], wi, wo, grazing_deg=89.0)
    ok = data.valid
    expected = fx.linear_fcos(wi, wo, anisotropic=anisotropic, jacobian=jacobian) / wo[:, 2:3]
    err = np.abs(data.values[ok] / expected[ok] - 1).max()
    print(f"anisotropic={anisotropic} jacobian={jacobian}: max relative error {err:.2e}")
    assert err < F32
    cut = np.cos(np.radians(89.0))
    np.testing.assert_array_equal(ok, (wi[:, 2] >= cut) & (wo[:, 2] >= cut))


def test_spectral_file_is_converted_to_srgb(files):
    wi, wo = _directions(300, seed=7)
    data = read_rgl_at(files["spectral"], wi, wo)
    # every wavelength holds the value of channel 0: a flat spectrum, grey in sRGB
    grey = fx.linear_fcos(wi, wo)[:, :1] / wo[:, 2:3]
    ok = data.valid
    assert ok.sum() > 250 and "spectral to linear sRGB" in data.source
    np.testing.assert_allclose(data.values[ok], np.repeat(grey[ok], 3, axis=1), rtol=F32)


def test_lambert_within_the_interpolation_bound_and_cut_at_grazing(files):
    bound = fx.lambert_error_bound(33)
    f = np.array(KD) / np.pi
    for data in (
        read_rgl(files["lambert"], stride=(5, 5, 5)),
        read_rgl_at(files["lambert"], *_directions(3000)),
    ):
        ok = data.valid
        cos_o = data.wo[ok, 2:3]
        # the table holds f cos(theta_o): its error, not that of f, obeys the bound
        err = np.abs(data.values[ok] / f - 1) * cos_o
        print(f"max |f cos error| / (kd/pi) = {err.max():.4f}, bound {bound:.4f}")
        assert err.max() <= bound + F32
        assert np.abs(data.values[ok] / f - 1).max() < bound / np.cos(np.radians(rgl.GRAZING_DEG))
    # without the cut, eval / cos amplifies the same error by up to 1/cos(89.9 deg) = 573
    wi, wo = _directions(3000)
    raw = read_rgl_at(files["lambert"], wi, wo, grazing_deg=89.9)
    beyond = raw.valid & (np.minimum(wi[:, 2], wo[:, 2]) < np.cos(np.radians(rgl.GRAZING_DEG)))
    assert beyond.any() and np.abs(raw.values[beyond] / f - 1).max() > 2 * err.max()


def test_merl_grid_cells_weights_and_masked_counts(files):
    stride = (9, 9, 9)
    data = read_rgl(files[(False, False)], stride=stride)
    g = merl_grid(stride)
    np.testing.assert_array_equal(data.wi, g.wi)
    np.testing.assert_array_equal(data.weights, g.weights)
    cut = np.cos(np.radians(rgl.GRAZING_DEG))
    inside = g.above & (g.wi[:, 2] >= cut) & (g.wo[:, 2] >= cut)
    np.testing.assert_array_equal(data.valid, inside)
    assert np.all(data.values[g.above & ~inside] == -1.0) and np.all(data.values[~g.above] == 0)
    n_cut = int(g.above.sum() - inside.sum())
    assert (
        n_cut > 0
        and f"{n_cut:,} of {g.n:,} samples beyond the reader's 85 deg zenith cut" in data.source
    )
    expected = fx.linear_fcos(g.wi[inside], g.wo[inside]) / g.wo[inside, 2:3]
    np.testing.assert_allclose(data.values[inside], expected, rtol=F32)


def test_rotated_grid_sees_another_azimuth_of_an_anisotropic_file(files):
    path = files[(True, False)]
    data = read_rgl(path, stride=(9, 9, 9), phi_h_deg=30.0)
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    g = merl_grid((9, 9, 9))
    np.testing.assert_allclose(data.wi, g.wi @ rot.T, atol=1e-15)
    np.testing.assert_array_equal(data.theta_h, g.theta_h)  # invariant under the rotation
    ok = data.valid
    expected = fx.linear_fcos(data.wi, data.wo, anisotropic=True) / data.wo[:, 2:3]
    np.testing.assert_allclose(data.values[ok], expected[ok], rtol=F32)
    assert not np.allclose(read_rgl(path, stride=(9, 9, 9)).values[ok], data.values[ok])


def test_variant_fallback_and_bad_variants(files, monkeypatch):
    wi, wo = _directions(50)
    monkeypatch.setattr(rgl, "VARIANTS", ("no_such_variant", "scalar_rgb"))
    monkeypatch.setattr(rgl, "_BROKEN", {})
    data = read_rgl_at(files[(False, False)], wi, wo)
    assert data.valid.sum() > 40 and "no_such_variant" in rgl._BROKEN
    with pytest.raises(MeasurementFileError, match="no_such_variant: exit 4"):
        read_rgl_at(files[(False, False)], wi, wo, variant="no_such_variant")
    with pytest.raises(ParameterError, match="grazing_deg"):
        read_rgl_at(files[(False, False)], wi, wo, grazing_deg=95.0)


def test_bad_files_raise_naming_file_and_problem(files, tmp_path, monkeypatch):
    from mitsuba.python import tensor_io

    with contextlib.redirect_stdout(io.StringIO()):  # tensor_io prints a line
        fields = tensor_io.read(str(files[(False, False)]))
    no_rgb = {k: v for k, v in fields.items() if k != "rgb"}
    bad_shape = dict(fields, vndf=fields["vndf"][:, :3])  # theta_i count disagrees
    good = files[(False, False)].read_bytes()
    cases = {
        tmp_path / "absent.bsdf": "no such file",
        tmp_path / "text.bsdf": "not a Mitsuba tensor file",
        tmp_path / "short.bsdf": "truncated",
        fx._write(tmp_path / "no_rgb.bsdf", **no_rgb): "missing field rgb",
        fx._write(tmp_path / "shape.bsdf", **bad_shape): "cannot load it: ",
    }
    (tmp_path / "text.bsdf").write_text("RGB BRDF, honest")
    (tmp_path / "short.bsdf").write_bytes(good[: len(good) // 2])
    wi, wo = _directions(10)
    for path, needle in cases.items():
        with pytest.raises(MeasurementFileError) as e:
            read_rgl_at(path, wi, wo)
        assert str(path) in str(e.value) and needle in str(e.value), str(e.value)
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "mitsuba" else real(name, *a)
    )
    with pytest.raises(MissingDependencyError, match=r"pip install 'brdffit\[rgl\]'"):
        read_rgl(files[(False, False)], stride=(15, 15, 15))


def test_cli_info_fit_and_sweep_listing_on_a_bsdf(files, tmp_path, capsys):
    path = files["lambert"]
    assert load_measurements(path, stride=(15, 15, 15)).n == 6 * 6 * 12
    assert main(["info", str(path), "--stride", "9", "9", "9"]) == 0
    out = capsys.readouterr().out
    assert "RGL isotropic, RGB 'brdffit test: Lambert'" in out and "zenith cut" in out
    js = tmp_path / "fit.json"
    argv = ["fit", str(path), "--model", "lambert", "--stride", "9", "9", "9", "--json", str(js)]
    assert main(argv) == 0
    # two cuts, each named by its owner wherever it is printed: the reader's (the file's
    # data end at 85 deg) and the fit's (the metric's samples end at 80 deg)
    out = capsys.readouterr().out
    assert "the reader's 85 deg zenith cut" in out
    assert "fit's angle cut: theta_i, theta_o < 80 deg" in out
    assert out.count("zenith cut") == out.count("reader's 85 deg zenith cut")
    kd = json.loads(js.read_text())["params"]["kd"]
    with capsys.disabled():
        print("kd fitted:", kd)
    # the file holds f cos to within 1.06% of kd/pi (lambert_error_bound); fitted: 0.25% off
    np.testing.assert_allclose(kd, KD, rtol=0.01)
    (m,) = [m for m in rgl_materials(path.parent) if m.name == "lambert"]
    assert m.kind == "rgl" and m.path == str(path.resolve())
    assert main(["info", str(tmp_path / "nothing.bsdf")]) == 2
    assert "nothing.bsdf: no such file" in capsys.readouterr().err


@pytest.mark.slow
def test_full_grid_converts_to_a_merl_binary(files, tmp_path):
    """The whole MERL grid (17-30 s on two busy cores): an RGL file becomes a MERL binary."""
    data = read_rgl(files["lambert"])
    assert data.grid == MERL_SHAPE and data.n_valid > 10**6
    write_merl(tmp_path / "lambert.binary", data)
    back = read_merl(tmp_path / "lambert.binary")
    np.testing.assert_array_equal(back.valid, data.valid)
    np.testing.assert_allclose(back.values[back.valid], data.values[data.valid], rtol=1e-15)


def test_negative_channels_are_measured_values_kept_and_fitted(tmp_path):
    """RGB converted from spectra holds genuine negative channels: a cell with one is
    kept whole (a per-cell mask dropped every cell of this file), counted as outside the
    cut only beyond 85 degrees, and the other channels' colour is fitted."""
    albedo = (0.5, 0.3, -0.02)
    path = fx.lambert_file(tmp_path / "out_of_gamut.bsdf", albedo)
    stride = (9, 9, 9)
    data = read_rgl(path, stride=stride)
    g = merl_grid(stride)
    cut = np.cos(np.radians(rgl.GRAZING_DEG))
    inside = g.above & (g.wi[:, 2] >= cut) & (g.wo[:, 2] >= cut)
    np.testing.assert_array_equal(data.valid, inside)
    assert data.channel_valid[inside].all()
    blue = data.values[inside, 2]
    assert (blue < 0).all()
    # the interpolation bound holds for f cos; f = (f cos) / wo.z with wo.z >= cos 85 deg
    bound = fx.lambert_error_bound(33) * abs(albedo[2]) / np.pi / cut
    np.testing.assert_allclose(blue, albedo[2] / np.pi, rtol=F32, atol=bound)
    counts = data.mask_counts()
    assert counts.outside_cut == int((g.above & ~inside).sum()) and counts.no_channel == 0
    assert counts.channels_masked == (0, 0, 0)
    assert "outside the reader's 85 deg zenith cut" in counts.text()
    for metric in ("low_e2", "ngan"):
        kd = np.asarray(brdffit.fit(models.get("lambert"), data, metric=metric).params["kd"])
        np.testing.assert_allclose(kd[:2], albedo[:2], rtol=0.01)  # as the grey file above
        assert kd[2] == 0.0  # at its bound: the nearest a non-negative albedo can come
