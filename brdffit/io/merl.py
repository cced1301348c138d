"""The MERL binary BRDF format: read and write.

Format (Matusik et al. 2003; DESIGN.md "MERL binary format (exact)"): a header of three
little-endian int32 ``(90, 90, 180)`` = (n_theta_h, n_theta_d, n_phi_d), then
3 x 1,458,000 little-endian float64, channel-planar (all R, then G, then B), each channel
in ``[theta_h, theta_d, phi_d]`` C order. Physical value (1/sr, no cosine) = raw x scale,
scales R 1/1500, G 1.15/1500, B 1.66/1500. Negative numbers mean "not measured": they
are kept as they are (never clamped to 0) and that channel of that cell is masked; the
cell's other channels stay in the fit (``Measurements.channel_valid``).

The grid the cells stand for, sub-grids and lookup: :mod:`brdffit.io.merl_grid`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from brdffit.core.geometry import MERL_SHAPE
from brdffit.core.measurements import Measurements
from brdffit.errors import MeasurementFileError, MeasurementsError, reading
from brdffit.io.merl_grid import MERL_N_CELLS, grid_measurements, merl_grid, require_full_table
from brdffit.util.atomic import write_atomic

MERL_SCALES: np.ndarray = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
"""RGB scales of the MERL format: physical value (1/sr) = raw x scale."""
MERL_SCALES.setflags(write=False)

MERL_FILE_BYTES: int = 12 + 3 * MERL_N_CELLS * 8
"""Size of a MERL binary file in bytes (34,992,012)."""

_HEADER_DTYPE = np.dtype("<i4")
_BODY_DTYPE = np.dtype("<f8")


# --------------------------------------------------------------------------- reading


def read_merl(path: str | os.PathLike[str]) -> Measurements:
    """Read a MERL binary BRDF file into :class:`Measurements` (every cell, file order).

    Values are raw x :data:`MERL_SCALES` in 1/sr (no cosine). A channel of a cell is
    fitted when it is not negative (MERL's "not measured": kept, never clamped, and
    masked for that channel alone) and both bin-centre directions are above the horizon;
    a cell is valid while one channel is. ``weights`` are the cells' solid angles (sr^2),
    ``grid`` is ``MERL_SHAPE``, ``channel_scales`` the MERL scales. How many cells and
    channels are masked and why: :meth:`Measurements.mask_counts`, printed by
    ``brdffit info``.

    Arguments:
    - ``path``: the ``.binary`` file.

    Returns: :class:`Measurements` with N = 1,458,000.

    Raises :class:`MeasurementFileError` (naming the file and the problem) when the file
    is missing or unreadable, has the wrong header or size, holds NaN/Inf, or has no
    valid cell.
    """
    p = Path(path)
    raw = _read_body(p)
    n_bad = raw.size - int(np.count_nonzero(np.isfinite(raw)))
    if n_bad:
        n_nan = int(np.count_nonzero(np.isnan(raw)))
        raise MeasurementFileError(
            p,
            f"{n_nan} NaN and {n_bad - n_nan} infinite values among the {raw.size} numbers; "
            "a MERL file holds finite numbers (negative = not measured)",
        )
    planes = raw.reshape(3, MERL_N_CELLS)
    g = merl_grid()
    values = np.empty((MERL_N_CELLS, 3))
    for c in range(3):
        np.multiply(planes[c], MERL_SCALES[c], out=values[:, c])
    channels = (planes >= 0).T & g.above[:, None]
    if not channels.any():
        raise MeasurementFileError(
            p,
            "no valid cell: every cell above the horizon is negative (not measured); "
            "expected at least one measured cell",
        )
    return grid_measurements(g, values, channels, str(p), MERL_SCALES)


def _read_body(p: Path) -> np.ndarray:
    """The file's 3 x 1,458,000 raw float64 (native byte order) after the size/header checks."""
    with reading(p, "a MERL .binary file"), open(p, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        header = f.read(12)
        if len(header) < 12:
            raise MeasurementFileError(
                p,
                f"truncated: {size} bytes, too short for the 12-byte header; "
                f"a MERL file has {MERL_FILE_BYTES:,} bytes",
            )
        _check_header(p, header)
        if size != MERL_FILE_BYTES:
            kind = "truncated" if size < MERL_FILE_BYTES else "too long"
            raise MeasurementFileError(
                p, f"{kind}: {size:,} bytes; expected {MERL_FILE_BYTES:,} for a 90x90x180 table"
            )
        raw = np.fromfile(f, dtype=_BODY_DTYPE, count=3 * MERL_N_CELLS)
    if raw.size != 3 * MERL_N_CELLS:  # the file shrank while being read
        raise MeasurementFileError(
            p, f"truncated: read {raw.size} of {3 * MERL_N_CELLS} float64 values"
        )
    return raw.astype(np.float64, copy=False)


def _check_header(p: Path, header: bytes) -> None:
    dims = tuple(int(v) for v in np.frombuffer(header, dtype=_HEADER_DTYPE))
    if dims == MERL_SHAPE:
        return
    hint = ""
    if tuple(int(v) for v in np.frombuffer(header, dtype=">i4")) == MERL_SHAPE:
        hint = " (the file is big-endian; MERL files are little-endian)"
    elif dims == (90, 90, 360):
        hint = " (a full-phi_d 360 table; only the standard 180 table is supported)"
    raise MeasurementFileError(
        p, f"wrong header: found {dims}, expected {MERL_SHAPE} as three little-endian int32{hint}"
    )


# --------------------------------------------------------------------------- writing


def write_merl(path: str | os.PathLike[str], data: Measurements) -> None:
    """Write a full MERL table to a MERL binary file, atomically.

    Raw = value / :data:`MERL_SCALES` (the standard scales, whatever
    ``data.channel_scales`` says: the values are in 1/sr); masked channels
    (``data.channel_valid``) are written as -1 ("not measured"), and so are the
    negative values of a signed source, which the format cannot hold. The file is
    written to a temporary file in the same folder, fsynced and moved into place with
    ``os.replace``: readers see the old file or the new one, never a partial one.
    ``read_merl(write_merl(x))`` gives back every value bit for bit when it came from a
    MERL file, and within 1 ulp otherwise (``v / s * s`` cannot always be exact).

    Arguments:
    - ``path``: the file to write (replaced if it exists).
    - ``data``: :class:`Measurements` with ``grid == MERL_SHAPE`` (file order).

    Raises :class:`MeasurementsError` if ``data`` is not a full table or a valid cell is
    not finite, :class:`MeasurementFileError` if the file cannot be written.
    """
    require_full_table(data, "write_merl")
    bad = (data.channel_valid & ~np.isfinite(data.values)).any(axis=1)
    if bad.any():
        raise MeasurementsError(
            f"{int(bad.sum())} valid cells of {data.source!r} hold NaN/Inf; a MERL file "
            "accepts finite values (mark them invalid to write them as not measured)"
        )
    raw = _to_raw(data.values, data.channel_valid & (data.values >= 0.0))
    header = np.asarray(MERL_SHAPE, dtype=_HEADER_DTYPE).tobytes()
    try:
        write_atomic(path, [header, raw.astype(_BODY_DTYPE, copy=False)])
    except OSError as e:
        raise MeasurementFileError(path, f"cannot be written: {e.strerror or e}") from e


def _to_raw(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(3, N) raw numbers such that raw * scale == value wherever such a float exists;
    -1 where ``valid`` ((N, 3)) is False."""
    raw = np.empty((3, values.shape[0]))
    for c in range(3):
        v, s = values[:, c], MERL_SCALES[c]
        r = v / s
        # fl(v / s) is the exact preimage whenever one exists, except at rounding ties:
        # try both neighbours where the product misses.
        miss = (r * s != v) & np.isfinite(v)
        for direction in (np.inf, -np.inf):
            step = np.nextafter(r[miss], direction)
            hit = step * s == v[miss]
            idx = np.flatnonzero(miss)[hit]
            r[idx] = step[hit]
            miss[idx] = False
        raw[c] = np.where(valid[:, c], r, -1.0)
    return raw
