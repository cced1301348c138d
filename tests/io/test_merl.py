"""The MERL binary format: exact reading and writing, masked cells counted by reason (in
``brdffit info`` too), bad files."""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np
import pytest

from brdffit import MeasurementFileError, MeasurementsError, read_merl, write_merl
from brdffit.cli import main
from brdffit.core.geometry import MERL_SHAPE
from brdffit.io.merl import MERL_FILE_BYTES, MERL_SCALES
from brdffit.io.merl_grid import MERL_N_CELLS, merl_grid, merl_grid_measurements, merl_subgrid

N = MERL_N_CELLS
HEADER = np.array([90, 90, 180], dtype="<i4").tobytes()


@functools.cache
def _raw() -> np.ndarray:
    """(3, N) raw numbers of a synthetic table: lognormal, 3% of cells "not measured"."""
    rng = np.random.default_rng(1)
    raw = rng.lognormal(2.0, 2.0, (3, N))
    raw[:, rng.random(N) < 0.03] = -1.0
    raw[1, rng.random(N) < 0.001] = -0.5  # a few cells negative in one channel only
    return raw


@pytest.fixture(scope="module")
def merl_file(tmp_path_factory) -> Path:
    """A full-size MERL file written independently of brdffit (plain bytes)."""
    path = tmp_path_factory.mktemp("merl") / "synthetic.binary"
    path.write_bytes(HEADER + _raw().astype("<f8").tobytes())
    return path


@pytest.fixture(scope="module")
def table(merl_file) -> object:
    return read_merl(merl_file)


# --------------------------------------------------------------------------- reading


def test_read_values_mask_and_geometry(table, merl_file):
    raw = _raw()
    g = merl_grid()
    assert table.n == N and table.grid == MERL_SHAPE and table.source == str(merl_file)
    np.testing.assert_array_equal(table.values, (raw * MERL_SCALES[:, None]).T)
    np.testing.assert_array_equal(table.channel_scales, MERL_SCALES)
    # per channel: a negative number masks that channel of that cell alone
    np.testing.assert_array_equal(table.channel_valid, g.above[:, None] & (raw >= 0).T)
    np.testing.assert_array_equal(table.valid, g.above & (raw >= 0).any(axis=0))
    np.testing.assert_array_equal(table.weights, g.weights)
    np.testing.assert_array_equal(table.theta_h, g.theta_h)


def test_negative_cells_masked_not_clamped(table):
    every = (_raw() < 0).all(axis=0)
    assert not table.valid[every].any()
    assert (table.values[every].max(axis=1) < 0).all()  # kept as stored, never set to 0
    np.testing.assert_array_equal(table.values[every][:, 0], -MERL_SCALES[0])


def test_one_negative_channel_masks_that_channel_only(table):
    """MERL's "not measured" mark in one channel leaves the other two in the fit (a
    per-cell mask threw the red and blue of these cells away)."""
    g = merl_grid()
    one = g.above & (_raw()[1] == -0.5) & (_raw()[0] >= 0)
    assert one.sum() > 100
    assert table.valid[one].all()
    np.testing.assert_array_equal(table.channel_valid[one], [[True, False, True]] * one.sum())
    counts = table.mask_counts()
    assert counts.channel_negative[1] == int((g.above & (_raw()[1] < 0)).sum())
    assert (
        counts.channel_negative[0]
        == counts.channel_negative[2]
        == int((g.above & (_raw()[0] < 0)).sum())
    )
    assert counts.no_channel == int((g.above & (_raw() < 0).all(axis=0)).sum())
    assert "channels masked inside the cut: R " in counts.text()


def test_info_says_how_many_cells_are_masked_and_why(tmp_path, capsys):
    # a MERL file written by hand: 30% of the cells with a negative blue channel, 10%
    # with every channel negative (MERL's "not measured")
    rng = np.random.default_rng(0)
    shape = (90, 90, 180)
    raw = np.ones((3, *shape))
    one = rng.random(shape) < 0.3
    every = (rng.random(shape) < 0.1) & ~one
    raw[2][one] = -0.5
    raw[:, every] = -1.0
    path = tmp_path / "bad-blue.binary"
    path.write_bytes(np.asarray(shape, "<i4").tobytes() + raw.astype("<f8").tobytes())
    # the horizon from DESIGN.md's closed form at the bin centres, not from brdffit
    th = ((np.arange(90) + 0.5) / 90) ** 2 * np.pi / 2
    td = (np.arange(90) + 0.5) / 90 * np.pi / 2
    pd = (np.arange(180) + 0.5) / 180 * np.pi
    th, td, pd = np.meshgrid(th, td, pd, indexing="ij")
    a, b = np.cos(td) * np.cos(th), np.sin(td) * np.cos(pd) * np.sin(th)
    below = ~((a - b > 0) & (a + b > 0))
    n_below, n_every, n_one = (int(m.sum()) for m in (below, every & ~below, one & ~below))
    assert 0.2 < n_below / below.size < 0.3  # about 24% by geometry alone (DESIGN.md)
    code = main(["info", str(path)])
    out, _ = capsys.readouterr()
    assert code == 0
    line = next(x for x in out.splitlines() if x.startswith("masked"))
    total = n_below + n_every
    # a cell with only its blue negative keeps red and green in the fit (issue 28)
    neg = n_every + n_one
    assert line.split(None, 1)[1] == (
        f"{total:,} of 1,458,000 samples: {n_below:,} below the horizon, {n_every:,} with no "
        f"channel measured; channels masked inside the cut: R {n_every:,} negative (not "
        f"measured), G {n_every:,} negative (not measured), B {neg:,} negative (not measured)"
    )


# --------------------------------------------------------------------------- writing


def test_write_read_round_trip_is_exact(table, tmp_path):
    out = tmp_path / "copy.binary"
    write_merl(out, table)
    back = read_merl(out)
    assert out.stat().st_size == MERL_FILE_BYTES
    np.testing.assert_array_equal(back.channel_valid, table.channel_valid)
    v = table.channel_valid
    np.testing.assert_array_equal(back.values[v], table.values[v])  # bit for bit
    raw = np.fromfile(out, dtype="<f8", offset=12).reshape(3, N)
    assert (raw.T[~v] == -1.0).all()  # masked channels written as "not measured"
    assert not list(tmp_path.glob(".*.tmp"))


def test_round_trip_of_arbitrary_values_within_one_ulp(tmp_path):
    g = merl_grid()
    rng = np.random.default_rng(3)
    data = merl_grid_measurements(rng.lognormal(0, 3, (3, *MERL_SHAPE)), source="x")
    write_merl(tmp_path / "x.binary", data)
    back = read_merl(tmp_path / "x.binary")
    v = data.valid
    assert (back.valid == g.above).all()
    # raw = v / s and back raw * s: when no float x has fl(x * s) == v (about 12% of
    # arbitrary values for these scales) the nearest one is 1 ulp off; values read
    # from a MERL file always come back exactly (test above).
    np.testing.assert_array_max_ulp(back.values[v], data.values[v], maxulp=1)


def test_write_needs_a_full_table(table, tmp_path):
    with pytest.raises(MeasurementsError, match="to_merl_grid"):
        write_merl(tmp_path / "x.binary", merl_subgrid(table, 3))
    assert not list(tmp_path.iterdir())


def test_write_rejects_non_finite_valid_cells(table, tmp_path):
    values = table.values.copy()
    values[np.flatnonzero(table.valid)[0]] = np.inf
    with pytest.raises(MeasurementsError, match="NaN/Inf"):
        write_merl(tmp_path / "x.binary", table.replace(values=values))


@pytest.mark.parametrize("exc", [OSError("disk full"), KeyboardInterrupt()])
def test_interrupted_write_leaves_target_untouched(table, tmp_path, monkeypatch, exc):
    target = tmp_path / "material.binary"
    target.write_bytes(b"old content")

    def fail(*args, **kwargs):
        raise exc

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(MeasurementFileError if isinstance(exc, OSError) else KeyboardInterrupt):
        write_merl(target, table)
    assert target.read_bytes() == b"old content"
    assert [p.name for p in tmp_path.iterdir()] == ["material.binary"]  # temp file removed


def test_write_to_missing_folder_names_the_file(table, tmp_path):
    target = tmp_path / "no" / "such" / "x.binary"
    with pytest.raises(MeasurementFileError, match="cannot be written") as e:
        write_merl(target, table)
    assert str(target) in str(e.value)


# --------------------------------------------------------------------------- bad files


def _sparse(path: Path, header: bytes, size: int, patches: dict[int, float] | None = None) -> Path:
    """A file of ``size`` bytes: ``header``, zeros (sparse) and float64 ``patches`` by index."""
    with open(path, "wb") as f:
        f.write(header)
        f.truncate(size)
        for i, v in (patches or {}).items():
            f.seek(12 + 8 * i)
            f.write(np.array([v], "<f8").tobytes())
    return path


def _directory(p: Path) -> Path:
    p.mkdir()
    return p


FULL = MERL_FILE_BYTES
NAN_INF = {7: np.nan, 3 * N - 1: np.nan, 9: -np.inf}
H360 = np.array([90, 90, 360], "<i4").tobytes()
HBIG = np.array([90, 90, 180], ">i4").tobytes()
# case: (make the file at a path, a fragment the message must hold)
BAD_FILES = {
    "missing": (lambda p: p, "no such file"),
    "directory": (_directory, "is a directory"),
    "empty": (lambda p: _sparse(p, b"", 0), "truncated: 0 bytes"),
    "wrong header": (lambda p: _sparse(p, H360, 12), "found (90, 90, 360), expected (90, 90, 180)"),
    "garbage header": (lambda p: _sparse(p, b"not a MERL f", 40), "wrong header: found"),
    "big-endian": (lambda p: _sparse(p, HBIG, 12), "big-endian"),
    "truncated": (
        lambda p: _sparse(p, HEADER, FULL - 8),
        "truncated: 34,992,004 bytes; expected 34,992,012",
    ),
    "too long": (lambda p: _sparse(p, HEADER, FULL + 3), "too long: 34,992,015 bytes"),
    "nan and inf": (lambda p: _sparse(p, HEADER, FULL, NAN_INF), "2 NaN and 1 infinite values"),
}


@pytest.mark.parametrize("case", BAD_FILES)
def test_bad_file_raises_naming_file_and_problem(case, tmp_path):
    make, problem = BAD_FILES[case]
    path = make(tmp_path / "bad.binary")
    with pytest.raises(MeasurementFileError) as e:
        read_merl(path)
    assert e.value.path == str(path)
    assert str(path) in str(e.value) and problem in str(e.value), str(e.value)


def test_no_valid_cell(tmp_path):
    raw = np.full((3, N), -1.0)
    raw[:, ~merl_grid().above] = 1.0  # measured values only below the horizon
    path = tmp_path / "empty.binary"
    path.write_bytes(HEADER + raw.tobytes())
    with pytest.raises(MeasurementFileError, match="no valid cell") as e:
        read_merl(path)
    assert str(path) in str(e.value)


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root reads anything")
def test_unreadable_file(merl_file, tmp_path):
    path = tmp_path / "locked.binary"
    path.write_bytes(merl_file.read_bytes()[:100])
    path.chmod(0)
    with pytest.raises(MeasurementFileError, match="permission denied"):
        read_merl(path)
