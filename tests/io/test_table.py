"""Tables of samples (CSV / npz): round trips, colour conversion, typed errors, CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from brdffit import MeasurementFileError, ParameterError, load_measurements, read_table
from brdffit.cli import main
from brdffit.io.spectra import XYZ_TO_SRGB, cie1931_xyz, spectrum_to_rgb, spectrum_to_xyz
from brdffit.sweep import table_materials

DIRS = "wi_x,wi_y,wi_z,wo_x,wo_y,wo_z"
FILES = settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def _sphere(rng: np.random.Generator, n: int) -> np.ndarray:
    """Unit vectors over the whole sphere (a quarter of them below the horizon, roughly)."""
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) * rng.choice([1.0, 1.0, 1.0, -1.0], n)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _write_csv(path, header: str, rows: np.ndarray) -> None:
    np.savetxt(path, rows, delimiter=",", header=header, comments="", fmt="%.17g")


# --------------------------------------------------------------------------- round trips


@FILES
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 40),
    weighted=st.booleans(),
    fmt=st.sampled_from(["csv", "npz", "npz-stacked"]),
)
def test_directions_and_values_round_trip(tmp_path, seed, n, weighted, fmt):
    rng = np.random.default_rng(seed)
    wi, wo = _sphere(rng, n), _sphere(rng, n)
    wi[0, 2] = wo[0, 2] = abs(wi[0, 2]) + 0.1  # at least one valid sample
    wi[0] /= np.linalg.norm(wi[0])
    wo[0] /= np.linalg.norm(wo[0])
    rgb = rng.lognormal(-1.0, 2.0, (n, 3)) * rng.choice([1.0, 1.0, 1.0, -1.0], (n, 3))
    rgb[0] = np.abs(rgb[0])
    w = rng.uniform(0.0, 2.0, n)
    path = tmp_path / f"t.{fmt[:3]}"
    if fmt == "csv":
        cols = np.column_stack([wi, wo, rgb, w] if weighted else [wi, wo, rgb])
        _write_csv(path, DIRS + ",r,g,b" + (",weight" if weighted else ""), cols)
    elif fmt == "npz":
        names = [*DIRS.split(","), "r", "g", "b"]
        arrays = dict(zip(names, np.column_stack([wi, wo, rgb]).T, strict=True))
        np.savez(path, **arrays, **({"weight": w} if weighted else {}))
    else:
        np.savez(path, wi=wi, wo=wo, rgb=rgb, **({"WEIGHT": w} if weighted else {}))
    data = read_table(path)
    assert data.n == n and str(path) in data.source
    np.testing.assert_allclose(data.wi, wi, rtol=0, atol=1e-15)  # %.17g: exact up to renorm
    np.testing.assert_allclose(data.wo, wo, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(data.values, rgb)  # kept as they are, negatives too
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    # an RGB table: a negative channel is that channel "not measured", the others stay
    np.testing.assert_array_equal(data.channel_valid, above[:, None] & (rgb >= 0))
    np.testing.assert_array_equal(data.valid, above & (rgb >= 0).any(axis=1))
    np.testing.assert_array_equal(data.weights, w if weighted else (2 * np.pi) ** 2 / n)
    assert ("uniform weights" in data.source) != weighted


@FILES
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 30), npz=st.booleans())
def test_angles_in_degrees_round_trip(tmp_path, seed, n, npz):
    rng = np.random.default_rng(seed)
    ang = np.column_stack(
        [
            rng.uniform(0, 89, n),
            rng.uniform(-180, 360, n),
            rng.uniform(0, 89, n),
            rng.uniform(-180, 360, n),
        ]
    )
    rgb = rng.uniform(0.0, 5.0, (n, 3))
    path = tmp_path / ("a.npz" if npz else "a.csv")
    names = ["theta_i", "phi_i", "theta_o", "phi_o", "r", "g", "b"]
    if npz:
        np.savez(path, **dict(zip(names, np.column_stack([ang, rgb]).T, strict=True)))
    else:
        _write_csv(path, " Theta_I, phi_i ,theta_o,PHI_O,R,G,B", np.column_stack([ang, rgb]))
    data = read_table(path)

    def vec(t, p):  # the convention of the module docstring, written out
        t, p = np.radians(t), np.radians(p)
        return np.column_stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])

    np.testing.assert_allclose(data.wi, vec(ang[:, 0], ang[:, 1]), atol=1e-14)
    np.testing.assert_allclose(data.wo, vec(ang[:, 2], ang[:, 3]), atol=1e-14)
    np.testing.assert_array_equal(data.values, rgb)
    assert data.valid.all()
    # the Rusinkiewicz angles are derived from the directions
    cos_h = ((data.wi + data.wo) / np.linalg.norm(data.wi + data.wo, axis=1)[:, None])[:, 2]
    np.testing.assert_allclose(np.cos(data.theta_h), cos_h, atol=1e-12)


def test_comments_crlf_and_small_rounding_are_accepted(tmp_path):
    path = tmp_path / "g.csv"
    text = "# goniometer export\r\n# units: 1/sr\r\nwi_x,wi_y,wi_z,wo_x,wo_y,wo_z,r,g,b\r\n"
    text += "0,0,1.0004,0.6,0,0.8,0.1,0.2,0.3\r\n# a comment line\r\n0,0.6,0.8,0,0,1,1,2,3\r\n"
    path.write_text(text)
    data = read_table(path)
    assert data.n == 2 and data.valid.all()
    np.testing.assert_allclose(np.linalg.norm(data.wi, axis=1), 1.0, atol=1e-15)  # renormalised


# --------------------------------------------------------------------------- colour


def test_wyman_cmf_fit_is_close_to_mitsubas_cie_1931_table():
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    lam = np.arange(360.0, 831.0, 1.0)
    ref = np.array([list(mi.cie1931_xyz(float(x))) for x in lam])
    err = np.abs(cie1931_xyz(lam) - ref).max(axis=0)
    print("max |fit - CIE table| (x, y, z):", err)
    # the multi-lobe fit's largest deviation is 0.034 (z near 433 nm, 2% of its 1.78 peak)
    assert np.all(err < 0.035)
    np.testing.assert_allclose(cie1931_xyz(np.array([555.0]))[0, 1], 1.0, atol=0.01)  # y peaks at 1


def test_spectrum_to_xyz_matches_mitsuba_and_flat_spectra_are_grey():
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    wl = np.linspace(360.0, 830.0, 48)
    spectra = np.stack(
        [
            np.ones_like(wl),
            np.exp(-0.5 * ((wl - 550.0) / 80.0) ** 2),
            0.2 + 0.5 * (wl > 600.0),
            0.5 + 0.3 * np.sin(wl / 40.0),
        ]
    )
    ours = spectrum_to_xyz(wl, spectra) @ XYZ_TO_SRGB.T  # illuminant E, no adaptation
    theirs = np.array(
        [list(mi.spectrum_list_to_srgb(wl.tolist(), s.tolist(), False, False)) for s in spectra]
    )
    print("max |ours - mitsuba| (sRGB, illuminant E):", np.abs(ours - theirs).max())
    # the fitted CMFs integrate to within 0.6% of the tabulated ones over these spectra
    np.testing.assert_allclose(ours, theirs, rtol=0.01, atol=2e-3)
    # E white adapted to D65: a flat spectrum c is (c, c, c), exactly up to rounding
    np.testing.assert_allclose(spectrum_to_rgb(wl, np.outer([0.3, 2.0], np.ones_like(wl))),
                               [[0.3] * 3, [2.0] * 3], rtol=1e-12)  # fmt: skip


def test_spectral_table_becomes_linear_srgb(tmp_path):
    rng = np.random.default_rng(3)
    n, wl = 20, np.arange(400.0, 701.0, 25.0)
    spectra = rng.uniform(0.0, 1.0, (n, wl.size))
    spectra[0] = 2.0  # flat: (2, 2, 2)
    spectra[1] = 0.0
    spectra[1, -1] = 5.0  # a deep red: blue and green well outside the sRGB gamut
    wi = wo = np.tile([0.0, 0.0, 1.0], (n, 1))
    path = tmp_path / "s.csv"
    header = DIRS + "," + ",".join(f"nm{w:g}" for w in wl)
    _write_csv(path, header, np.column_stack([wi, wo, spectra]))
    data = read_table(path)
    np.testing.assert_allclose(data.values, spectrum_to_rgb(wl, spectra), rtol=1e-12)
    np.testing.assert_allclose(data.values[0], 2.0, rtol=1e-12)
    # a spectral table is signed: the out-of-gamut red is a measured colour, kept whole
    assert data.valid[1] and data.valid[0] and data.channel_valid[:2].all()
    assert (data.values[1] < 0).any()
    assert "400-700 nm" in data.source and "outside the sRGB gamut" in data.source
    np.savez(tmp_path / "s.npz", wi=wi, wo=wo, spectra=spectra, wavelengths=wl)
    np.testing.assert_array_equal(read_table(tmp_path / "s.npz").values, data.values)


# --------------------------------------------------------------------------- errors

GOOD = DIRS + ",r,g,b\n0,0,1,0,0,1,0.1,0.2,0.3\n0.6,0,0.8,0,0,1,0.1,0.2,0.3\n"


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("", "empty file"),
        ("\n\n", "empty file"),
        ("# only a comment\n\n", "empty file"),
        (DIRS + ",r,g,b\n", "no data rows"),
        ("wi_x,wi_y,wi_z,wo_x,wo_y,r,g,b\n0,0,1,0,0,0.1,0.2,0.3\n", "missing column wo_z"),
        ("wi_x,wi_y,wi_z,wo_x,wo_y,wo_z,r,g\n0,0,1,0,0,1,0.1,0.2\n", "missing column b"),
        (DIRS + "\n0,0,1,0,0,1\n", "missing value columns"),
        (DIRS + ",r,g,b,colour\n0,0,1,0,0,1,1,1,1,7\n", "unknown column 'colour'"),
        (DIRS + ",r,g,b,r\n0,0,1,0,0,1,1,1,1,1\n", "duplicated column r"),
        (DIRS + ",theta_i,r,g,b\n0,0,1,0,0,1,0,1,1,1\n", "mixed conventions"),
        (DIRS + ",r,g,b,nm500\n0,0,1,0,0,1,1,1,1,1\n", "mixed conventions"),
        (DIRS + ",r,g,b\n0,0,1,0,0,1,nan,1,1\n", "non-finite"),
        (DIRS + ",r,g,b\n0,0,1,0,0,1,inf,1,1\n", "non-finite"),
        (DIRS + ",r,g,b\n0,0,2,0,0,1,1,1,1\n", "not a unit vector"),
        (DIRS + ",r,g,b\n0,0,1,0,0,1,1,1,1\n0,0,1,0,0,1,1,1\n", "line 3 has 8 fields"),
        (DIRS + ",r,g,b\n0,0,1,0,0,1,1,x,1\n", "line 2, column 8 ('g')"),
        (DIRS + ",r,g,b,weight\n0,0,1,0,0,1,1,1,1,-2\n", "negative weight"),
        (DIRS + ",r,g,b\n0,0,-1,0,0,1,1,1,1\n0,0,1,0,0,1,-1,-1,-1\n", "no valid sample"),
        (DIRS + ",r,g,b\n0,0,1,0,0,1,1,1\n", "the header names 9 columns but the rows hold 8"),
    ],
)
def test_bad_csv_raises_naming_file_and_problem(tmp_path, text, needle):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(MeasurementFileError) as e:
        read_table(path)
    assert str(e.value).count(str(path)) == 1 and needle in str(e.value)  # named once


def test_bad_files_and_npz(tmp_path):
    cases = {
        tmp_path / "missing.csv": "no such file",
        tmp_path / "junk.npz": "not a .npz archive",
        tmp_path / "ragged.npz": "different lengths",
        tmp_path / "empty.npz": "empty archive",
        tmp_path / "nowl.npz": "needs a 1-D 'wavelengths'",
        tmp_path / "x.txt": "a table is .csv or .npz",
    }
    (tmp_path / "junk.npz").write_bytes(b"not a zip file")
    (tmp_path / "x.txt").write_text(GOOD)
    np.savez(
        tmp_path / "ragged.npz", wi=np.eye(3), wo=np.eye(3), r=[1, 2], g=[1, 2, 3], b=[1, 2, 3]
    )
    np.savez(tmp_path / "empty.npz")
    np.savez(tmp_path / "nowl.npz", wi=np.eye(3), wo=np.eye(3), spectra=np.ones((3, 4)))
    for path, needle in cases.items():
        with pytest.raises(MeasurementFileError) as e:
            read_table(path)
        assert str(e.value).count(str(path)) == 1 and needle in str(e.value), str(e.value)


@FILES
@given(
    seed=st.integers(0, 2**32 - 1),
    bad=st.sampled_from(["nan", "-inf", "abc", "", "1,2", "0x1g"]),
)
def test_any_corrupted_cell_is_refused(tmp_path, seed, bad):
    """A valid table with one cell replaced by junk never reads silently."""
    rng = np.random.default_rng(seed)
    n = 5
    wi = _sphere(rng, n)
    wi[:, 2] = np.abs(wi[:, 2])
    rows = np.column_stack([wi, wi, rng.uniform(0, 1, (n, 3))])
    lines = [",".join(f"{v:.17g}" for v in r) for r in rows]
    i, j = rng.integers(n), rng.integers(9)
    cells = lines[i].split(",")
    cells[j] = bad
    lines[i] = ",".join(cells)
    path = tmp_path / "c.csv"
    path.write_text(DIRS + ",r,g,b\n" + "\n".join(lines) + "\n")
    with pytest.raises(MeasurementFileError, match="c.csv"):
        read_table(path)


# --------------------------------------------------------------------------- dispatch, CLI


@pytest.fixture
def lambert_csv(tmp_path):
    """A Lambertian table, albedo (0.2, 0.5, 0.8), 400 directions, 3% multiplicative noise."""
    rng = np.random.default_rng(11)
    n = 400
    wi, wo = _sphere(rng, n), _sphere(rng, n)
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    f = np.array([0.2, 0.5, 0.8]) / np.pi * rng.lognormal(0.0, 0.03, (n, 3))
    path = tmp_path / "lambert.csv"
    _write_csv(path, DIRS + ",r,g,b", np.column_stack([wi, wo, f]))
    return path


def test_load_measurements_dispatches_tables_and_refuses_a_stride(lambert_csv):
    data = load_measurements(lambert_csv)
    assert data.n == 400 and data.grid is None
    with pytest.raises(ParameterError, match="read as it is"):
        load_measurements(lambert_csv, stride=(5, 5, 5))
    (m,) = table_materials(lambert_csv.parent)
    assert m.kind == "table" and m.name == "lambert"


def test_cli_info_and_fit_on_a_csv(lambert_csv, tmp_path, capsys):
    assert main(["info", str(lambert_csv)]) == 0
    out = capsys.readouterr().out
    assert "400 valid" in out and "uniform weights" in out
    js = tmp_path / "fit.json"
    assert main(["fit", str(lambert_csv), "--model", "lambert", "--json", str(js)]) == 0
    kd = json.loads(js.read_text())["params"]["kd"]
    with capsys.disabled():
        print("kd fitted:", kd)
    np.testing.assert_allclose(kd, [0.2, 0.5, 0.8], rtol=0.01)  # 3% noise over 400 samples
    assert main(["info", str(lambert_csv), "--stride", "5", "5", "5"]) == 2
    assert "read as it is" in capsys.readouterr().err


def test_cli_sweep_over_a_table_folder_ignores_the_stride(lambert_csv, tmp_path, capsys):
    out = tmp_path / "sweep"
    argv = ["sweep", str(out), "--table-dir", str(lambert_csv.parent), "--models", "lambert"]
    argv += ["--stride", "9", "9", "9", "--restarts", "0", "--jobs", "1", "--no-progress"]
    assert main(argv) == 0, capsys.readouterr().err
    d = json.loads((out / "lambert" / "lambert__low_e2.json").read_text())
    data = read_table(lambert_csv)
    cut = np.cos(np.radians(80.0))  # the default zenith cut of the metric
    n_in = int(np.sum(data.valid & (data.wi[:, 2] > cut) & (data.wo[:, 2] > cut)))
    assert d["material"] == "lambert" and d["n_data"] == 3 * n_in  # every sample, no stride
    np.testing.assert_allclose(d["params"]["kd"], [0.2, 0.5, 0.8], rtol=0.01)
