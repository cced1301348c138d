"""The MERL binary format: exact reading and writing, bad files, lookup, coarse grids."""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from brdffit.core.geometry import (
    MERL_SHAPE,
    halfdiff_to_io,
    merl_bin_centres,
    merl_solid_angle_weights,
    spherical_to_vector,
)
from brdffit.errors import MeasurementFileError, MeasurementsError, ParameterError
from brdffit.io.merl import (
    MERL_FILE_BYTES,
    MERL_N_CELLS,
    MERL_SCALES,
    lookup,
    merl_grid,
    merl_grid_measurements,
    merl_subgrid,
    read_merl,
    write_merl,
)

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


@functools.cache
def _id_table():
    """Full table whose R value is the cell's flat index + 1; 1% of cells unmeasured."""
    cube = np.broadcast_to(np.arange(1.0, N + 1.0).reshape(MERL_SHAPE), (3, *MERL_SHAPE)).copy()
    cube[:, np.random.default_rng(2).random(MERL_SHAPE) < 0.01] = -1.0
    return merl_grid_measurements(cube, source="cell ids")


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


@pytest.mark.parametrize("stride", [(1, 1, 1), (3, 3, 3), (5, 5, 5), (9, 9, 9), (3, 5, 9)])
def test_grid_weights_sum_to_two_pi_squared(stride):
    g = merl_grid(stride)
    assert g.n == int(np.prod(g.shape))
    total = g.weights[g.above].sum() / (2 * np.pi) ** 2
    # Weights are the summed fine-cell weights of each block, so over all cells the sum
    # is the full grid's whatever the stride; over the valid cells the horizon cuts
    # coarser cells: measured 1.5e-4 (full) to 8.7e-3 (stride 9), so 1.2e-2 at most.
    assert abs(total - 1) < (1e-3 if stride == (1, 1, 1) else 1.2e-2)
    np.testing.assert_allclose(g.weights.sum(), merl_grid().weights.sum(), rtol=1e-12)


def test_grid_directions_match_geometry():
    g = merl_grid((3, 3, 3))
    wi, wo = halfdiff_to_io(g.theta_h, g.theta_d, g.phi_d)
    # The grid's separable closed form performs the same operations: same bits.
    np.testing.assert_allclose(g.wi, wi, rtol=0, atol=1e-15)
    np.testing.assert_allclose(g.wo, wo, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(g.above, (wi[:, 2] > 0) & (wo[:, 2] > 0))
    i = np.ravel_multi_index(np.indices(g.shape).reshape(3, -1) * 3 + 1, MERL_SHAPE)
    np.testing.assert_array_equal(g.index, i)
    np.testing.assert_allclose(g.theta_h, merl_bin_centres()[0].ravel()[i], rtol=1e-15)
    np.testing.assert_allclose(g.phi_d, merl_bin_centres()[2].ravel()[i], rtol=1e-15)


def test_grid_weights_match_coarse_cell_formula():
    g = merl_grid((3, 3, 3))
    coarse = merl_solid_angle_weights(g.theta_h, g.theta_d, shape=g.shape)
    ratio = (g.weights / coarse).reshape(g.shape)
    # Block sum vs the midpoint formula with coarse widths: they differ by the midpoint
    # error, ~(cell width / theta)^2 -- 89% in the first cell at theta = 0, where the
    # integrand sin(th) u dth grows like u^3, 0.7% from the sixth cell on.
    assert np.abs(ratio[5:, 5:] - 1).max() < 1e-2
    assert np.abs(ratio[0, 0, 0] - 1) < 1


@pytest.mark.parametrize("stride", [2, (1, 1, 4), (7, 1, 1), (1, 2)])
def test_bad_stride(stride):
    with pytest.raises(ParameterError, match="odd divisor|3 ints"):
        merl_grid(stride)


def test_subgrid_picks_bin_centres_of_the_full_table(table):
    sub = merl_subgrid(table, (5, 5, 5))
    g = merl_grid((5, 5, 5))
    assert sub.n == 18 * 18 * 36 and sub.grid is None
    np.testing.assert_array_equal(sub.values, table.values[g.index])
    np.testing.assert_array_equal(sub.valid, table.valid[g.index])
    np.testing.assert_array_equal(sub.theta_d, table.theta_d[g.index])
    np.testing.assert_array_equal(sub.wi, table.wi[g.index])
    np.testing.assert_array_equal(sub.weights, g.weights)


def test_grid_measurements_marks_non_finite_invalid():
    g = merl_grid((9, 9, 9))
    cube = np.ones((3, *g.shape))
    cube[1, 5, 5, 5] = np.nan
    data = merl_grid_measurements(cube, source="x", stride=(9, 9, 9))
    flat = np.ravel_multi_index((5, 5, 5), g.shape)
    assert not data.channel_valid[flat, 1] and data.values[flat, 1] == -1.0
    assert data.channel_valid[flat, [0, 2]].all() == bool(g.above[flat])
    assert data.n_valid == g.above.sum()
    with pytest.raises(MeasurementsError, match="expected"):
        merl_grid_measurements(np.ones((3, 9, 9, 9)), source="x", stride=(9, 9, 9))


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


# --------------------------------------------------------------------------- lookup


def test_lookup_at_bin_centres_returns_the_stored_cell():
    g = merl_grid((3, 3, 3))  # 54,000 bin centres spread over the whole table
    stored = _id_table().values[g.index]
    got = lookup(_id_table(), g.wi, g.wo)
    measured, above = stored[:, 0] > 0, g.above
    np.testing.assert_array_equal(got[above & measured], stored[above & measured])
    assert np.isnan(got[above & ~measured]).all()
    assert (got[~above] == 0).all()
    raw = lookup(_id_table(), g.wi[~measured], g.wo[~measured], unmeasured="raw")
    np.testing.assert_array_equal(raw[above[~measured]], -1.0)


def _brute_force_cells(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest MERL bin centre per (n, 3) pair by exhaustive search over each axis.

    Angles come from the frame of the half vector (``d = (wi.ex, wi.ey, wi.h)``), not
    from :mod:`brdffit.core.geometry`. Returns the flat cell index and a mask that is False
    where the bin is ambiguous (left to round-off).
    """
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=1, keepdims=True)
    theta_h = np.arctan2(np.hypot(h[:, 0], h[:, 1]), h[:, 2])
    phi_h = np.arctan2(h[:, 1], h[:, 0])
    ch, sh, cp, sp = np.cos(theta_h), np.sin(theta_h), np.cos(phi_h), np.sin(phi_h)
    ex = np.stack([ch * cp, ch * sp, -sh], axis=1)
    ey = np.stack([-sp, cp, np.zeros_like(cp)], axis=1)
    dx, dy, dz = (np.sum(wi * e, axis=1) for e in (ex, ey, h))
    theta_d = np.arctan2(np.hypot(dx, dy), dz)
    phi_d = np.mod(np.arctan2(dy, dx), np.pi)  # MERL folds phi_d by pi
    # phi_h or phi_d is undefined at theta_h = 0 or theta_d = 0: round-off picks the bin.
    ok = np.minimum(theta_h, theta_d) > 1e-6
    coords = (np.sqrt(theta_h / (np.pi / 2)), theta_d / (np.pi / 2), phi_d / np.pi)
    idx = []
    for axis, (x, n) in enumerate(zip(coords, MERL_SHAPE, strict=True)):
        t = x * n
        # Skip points at a bin edge. theta = 0 is no edge (bin 0 starts there);
        # phi_d = 0 = pi is one (the fold joins bins 179 and 0).
        edge = (np.abs(t - np.round(t)) < 1e-9) & ((axis == 2) | ((t > 0.5) & (t < n - 0.5)))
        ok &= ~edge
        centres = (np.arange(n) + 0.5) / n
        idx.append(np.argmin(np.abs(centres[None, :] - x[:, None]), axis=1))
    return np.ravel_multi_index(idx, MERL_SHAPE), ok


def _expected(flat: np.ndarray) -> np.ndarray:
    r = _id_table().values[flat, 0]
    return np.where(r > 0, r, np.nan)


def test_lookup_matches_brute_force_at_random_directions():
    rng = np.random.default_rng(4)
    n = 30_000
    wi = spherical_to_vector(rng.uniform(0, np.pi / 2, n), rng.uniform(0, 2 * np.pi, n))
    wo = spherical_to_vector(rng.uniform(0, np.pi / 2, n), rng.uniform(0, 2 * np.pi, n))
    flat, ok = _brute_force_cells(wi, wo)
    assert ok.mean() > 0.999
    got = lookup(_id_table(), wi, wo)[:, 0]
    np.testing.assert_array_equal(got[ok], _expected(flat[ok]))


@settings(max_examples=100, deadline=None)
@given(
    st.floats(0, np.pi / 2 - 1e-6),
    st.floats(0, 2 * np.pi),
    st.floats(0, np.pi / 2 - 1e-6),
    st.floats(0, 2 * np.pi),
)
def test_lookup_matches_brute_force_nearest_bin(t_i, p_i, t_o, p_o):
    wi = spherical_to_vector(np.array([t_i]), np.array([p_i]))
    wo = spherical_to_vector(np.array([t_o]), np.array([p_o]))
    assume(np.linalg.norm(wi + wo) > 1e-6)
    flat, ok = _brute_force_cells(wi, wo)
    assume(ok[0])
    np.testing.assert_array_equal(lookup(_id_table(), wi, wo)[:, 0], _expected(flat))


def test_lookup_below_horizon_is_zero():
    data = _id_table()
    wi = np.array([[0.0, 0.6, 0.8], [0.6, 0.0, -0.8], [1.0, 0.0, 0.0]])
    wo = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(lookup(data, wi, wo), 0.0)


def test_lookup_needs_a_full_table_and_a_known_mode(table):
    wi = np.array([[0.0, 0.0, 1.0]])
    with pytest.raises(MeasurementsError, match="full MERL table"):
        lookup(merl_subgrid(table, 3), wi, wi)
    with pytest.raises(ParameterError, match="accepted"):
        lookup(table, wi, wi, unmeasured="zero")
