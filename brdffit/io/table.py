"""Plain tables of BRDF samples (CSV or NumPy ``.npz``), the form goniometer data come in.

One row per sample. Columns (the CSV header line, or the keys of an ``.npz`` archive,
each a 1-D array of the same length; names are case-insensitive, spaces ignored):

- directions, **one** of
  - ``wi_x, wi_y, wi_z, wo_x, wo_y, wo_z``: unit vectors in the local shading frame
    (z the normal, x the tangent), ``wi`` toward the light, ``wo`` toward the viewer;
    a norm off 1 by more than :data:`UNIT_TOL` is an error, smaller errors are
    normalised away;
  - ``theta_i, phi_i, theta_o, phi_o`` in **degrees**: zenith from +z, azimuth from +x
    toward +y (``w = (sin t cos p, sin t sin p, cos t)``; a signed in-plane zenith,
    ``theta < 0``, is the mirror azimuth);
- values, **one** of
  - ``r, g, b``: linear RGB BRDF in 1/sr, **without** the cosine factor;
  - spectral columns ``nm<wavelength>`` (e.g. ``nm450, nm460, nm472.5``): the BRDF in
    1/sr at each wavelength (nm), converted to linear sRGB by
    :func:`brdffit.io.spectra.spectrum_to_rgb` (CIE 1931 2-degree observer in the analytic
    form of Wyman, Sloan & Shirley 2013, equal-energy illuminant E, Bradford adaptation
    to the D65 white of sRGB: a flat spectrum ``c`` gives ``(c, c, c)``);
- ``weight`` (optional): the solid angle ``dwi dwo`` (sr^2) a sample stands for, the
  weight of its residual in the metrics. Without it every sample gets the same weight,
  ``(2 pi)^2 / N`` (samples spread evenly over both hemispheres); if the samples are
  not evenly spread (a goniometer that samples the specular peak densely), the fit then
  favours the densely sampled region: give the weights.

An ``.npz`` archive may instead hold ``wi`` and ``wo`` as (N, 3) arrays, ``rgb`` as
(N, 3), or ``spectra`` (N, L) with ``wavelengths`` (L,) in nm. CSV lines starting with
``#`` are comments; the first other line is the header.

Samples with a direction below the horizon (``z <= 0``) are kept and marked invalid.
Negative values, per source (``Measurements`` ``negative`` policy): in an RGB table a
negative channel marks that channel of that sample "not measured" (masked alone, the
other channels stay in the fit); in a spectral table the RGB values are computed and a
negative channel is a measured colour outside the sRGB gamut, kept and fitted signed.
``brdffit info`` counts masked samples and channels by reason
(:meth:`Measurements.mask_counts`), and ``Measurements.source`` says how many spectra
fell outside the gamut. Any other problem
(no such file, no rows, a missing, unknown or duplicated column, both conventions at
once, a non-finite number, a direction that is not a unit vector, a negative weight,
no valid sample) raises :class:`~brdffit.errors.MeasurementFileError` naming the file
and the problem.
"""

from __future__ import annotations

import os
import re
import warnings
import zipfile
from pathlib import Path

import numpy as np
from jaxtyping import ArrayLike

from brdffit.core.geometry import above_horizon, spherical_to_vector
from brdffit.core.measurements import Measurements
from brdffit.errors import MeasurementFileError
from brdffit.io.spectra import spectrum_to_rgb

DIRECTION_COLUMNS = ("wi_x", "wi_y", "wi_z", "wo_x", "wo_y", "wo_z")
"""Direction columns: ``wi`` then ``wo``, shading frame."""
ANGLE_COLUMNS = ("theta_i", "phi_i", "theta_o", "phi_o")
"""Angle columns, degrees."""
RGB_COLUMNS = ("r", "g", "b")
"""Linear RGB value columns, 1/sr without the cosine."""
WEIGHT_COLUMN = "weight"
"""Optional per-sample solid angle ``dwi dwo``, sr^2."""
UNIT_TOL = 1e-3
"""Largest accepted ``| |w| - 1 |`` of a direction column triple (CSV rounding)."""

_SPECTRAL = re.compile(r"^nm(\d+(?:\.\d*)?)$")
_TABLE_SUFFIXES = (".csv", ".npz")


def read_table(path: str | os.PathLike[str]) -> Measurements:
    """Read a table of samples (``.csv`` or ``.npz``, module docstring) into :class:`Measurements`.

    Arguments:
    - ``path``: the file; its suffix picks the format.

    Returns: :class:`Measurements` in file order (``grid=None``), values in 1/sr, no
    cosine, weights from the ``weight`` column or uniform; ``source`` names the file, the
    value convention and the weighting.

    Raises :class:`MeasurementFileError` naming the file and the problem.
    """
    p = Path(path)
    if p.suffix.lower() not in _TABLE_SUFFIXES:
        raise MeasurementFileError(p, f"suffix {p.suffix!r}; a table is .csv or .npz")
    if not p.is_file():
        raise MeasurementFileError(p, "no such file" if not p.exists() else "not a file")
    columns = _read_npz(p) if p.suffix.lower() == ".npz" else _read_csv(p)
    return table_measurements(columns, source=str(p))


def _read_csv(p: Path) -> dict[str, np.ndarray]:
    try:
        with open(p, encoding="utf-8-sig") as f:
            header, n_before = None, 0
            for line in f:
                n_before += 1
                if line.strip() and not line.lstrip().startswith("#"):
                    header = line
                    break
            if header is None:
                raise MeasurementFileError(p, "empty file: no header line (e.g. wi_x,...,r,g,b)")
            names = [_norm(n) for n in header.split(",")]
            with warnings.catch_warnings():  # "no data" is reported below, as an error
                warnings.filterwarnings("ignore", "loadtxt: input contained no data")
                data = np.loadtxt(f, delimiter=",", comments="#", ndmin=2, dtype=float)
    except MeasurementFileError:
        raise
    except UnicodeDecodeError as e:
        raise MeasurementFileError(p, f"not a UTF-8 text file: {e.reason}") from None
    except ValueError:
        raise MeasurementFileError(p, _bad_cell(p, n_before, names)) from None
    except OSError as e:
        raise MeasurementFileError(p, f"cannot be read: {e.strerror or e}") from None
    if data.size == 0:
        raise MeasurementFileError(p, "no data rows after the header")
    if data.shape[1] != len(names):
        raise MeasurementFileError(
            p, f"the header names {len(names)} columns but the rows hold {data.shape[1]}"
        )
    _check_names(p, names)
    return {n: data[:, k] for k, n in enumerate(names)}


def _bad_cell(p: Path, n_header: int, names: list[str]) -> str:
    """Where and why ``np.loadtxt`` refused the CSV rows: the first data line (1-based
    file line) with a field that is not a number or a wrong field count."""
    with open(p, encoding="utf-8-sig") as f:
        for number, line in enumerate(f, start=1):
            text = line.split("#", 1)[0].strip()
            if number <= n_header or not text:
                continue
            fields = text.split(",")
            if len(fields) != len(names):
                return (
                    f"line {number} has {len(fields)} fields; the header names {len(names)} columns"
                )
            for k, field in enumerate(fields):
                try:
                    float(field)
                except ValueError:
                    return (
                        f"line {number}, column {k + 1} ({names[k]!r}): {field.strip()!r} is "
                        "not a number"
                    )
    return f"not a numeric CSV table after the header (line {n_header})"


def _read_npz(p: Path) -> dict[str, np.ndarray]:
    if not zipfile.is_zipfile(p):
        raise MeasurementFileError(
            p, "not a .npz archive (expected a zip of .npy arrays, as numpy.savez writes)"
        )
    try:
        with np.load(p, allow_pickle=False) as z:
            names = [_norm(k) for k in z.files]
            _check_names(p, names)
            raw = {n: np.asarray(z[k]) for n, k in zip(names, z.files, strict=True)}
    except MeasurementFileError:
        raise
    except Exception as e:  # a damaged archive fails in zipfile, zlib or numpy's header parser
        raise MeasurementFileError(p, f"not a readable .npz archive: {e}") from None
    if not raw:
        raise MeasurementFileError(p, "empty archive: no arrays")
    cols: dict[str, np.ndarray] = {}
    stacked = {"wi": DIRECTION_COLUMNS[:3], "wo": DIRECTION_COLUMNS[3:], "rgb": RGB_COLUMNS}
    for key, arr in raw.items():
        if arr.dtype.kind not in "fiu":
            raise MeasurementFileError(p, f"array {key!r} has dtype {arr.dtype}; expected numbers")
        if key in stacked and arr.ndim == 2 and arr.shape[1] == 3:
            cols.update({c: arr[:, j] for j, c in enumerate(stacked[key])})
        elif key == "spectra" and arr.ndim == 2:
            if "wavelengths" not in raw or np.ndim(raw["wavelengths"]) != 1:
                raise MeasurementFileError(p, "'spectra' needs a 1-D 'wavelengths' array (nm)")
            wl = np.asarray(raw["wavelengths"], float)
            if wl.size != arr.shape[1]:
                raise MeasurementFileError(
                    p, f"'spectra' has {arr.shape[1]} columns but 'wavelengths' {wl.size}"
                )
            cols.update({f"nm{w:g}": arr[:, j] for j, w in enumerate(wl)})
        elif key == "wavelengths":
            continue
        elif arr.ndim == 1:
            cols[key] = arr
        else:
            raise MeasurementFileError(p, f"array {key!r} has shape {arr.shape}; expected (N,)")
    lengths = {k: v.shape[0] for k, v in cols.items()}
    if len(set(lengths.values())) > 1:
        raise MeasurementFileError(p, f"arrays of different lengths: {lengths}")
    if not next(iter(lengths.values()), 0):
        raise MeasurementFileError(p, "no samples: the arrays are empty")
    return {k: v.astype(float) for k, v in cols.items()}


def _norm(name: str) -> str:
    return "".join(name.split()).lower()


def _check_names(p: Path, names: list[str]) -> None:
    known = {*DIRECTION_COLUMNS, *ANGLE_COLUMNS, *RGB_COLUMNS, WEIGHT_COLUMN}
    known |= {"wi", "wo", "rgb", "spectra", "wavelengths"} if p.suffix.lower() == ".npz" else set()
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise MeasurementFileError(p, f"duplicated column {', '.join(dup)}")
    bad = [n for n in names if n not in known and not _SPECTRAL.match(n)]
    if bad:
        raise MeasurementFileError(
            p,
            f"unknown column {', '.join(repr(b) for b in bad)}; accepted: "
            f"{','.join(DIRECTION_COLUMNS)} or {','.join(ANGLE_COLUMNS)} (degrees), "
            f"{','.join(RGB_COLUMNS)} or nm<wavelength> columns, optional {WEIGHT_COLUMN}",
        )


# --------------------------------------------------------------------------- columns


def table_measurements(columns: dict[str, ArrayLike], *, source: str) -> Measurements:
    """:class:`Measurements` from named columns (the module docstring's names), checked.

    Arguments:
    - ``columns``: column name -> (N,) numbers, as read from a CSV or ``.npz`` file.
    - ``source``: the file (named in errors and in the result).

    Raises :class:`MeasurementFileError` (``path`` = ``source``) for a bad table.
    """
    cols = {_norm(k): np.asarray(v, float) for k, v in columns.items()}
    for name, col in cols.items():
        bad = np.flatnonzero(~np.isfinite(col))
        if bad.size:
            raise MeasurementFileError(
                source,
                f"column {name!r} holds {bad.size} non-finite value(s) (NaN or Inf), first in "
                f"data row {bad[0] + 1}; mark a missing measurement with a negative value",
            )
    wi, wo = _directions(source, cols)
    rgb, how = _values(source, cols)
    weights = cols.get(WEIGHT_COLUMN)
    if weights is not None and np.any(weights < 0):
        row = int(np.flatnonzero(weights < 0)[0]) + 1
        raise MeasurementFileError(
            source, f"negative weight {weights[row - 1]:g} in data row {row}; weights are sr^2 >= 0"
        )
    above = above_horizon(wi, wo)
    negative = above & np.any(rgb < 0, axis=1)
    policy = "signed" if how.startswith("spectral") else "not_measured"
    n = wi.shape[0]
    usable = above & (np.any(rgb >= 0, axis=1) if policy == "not_measured" else True)
    if not np.any(usable):
        raise MeasurementFileError(
            source,
            f"no valid sample: {n - int(above.sum())} of {n} below the horizon, "
            f"{int((above & np.all(rgb < 0, axis=1)).sum())} with every channel negative "
            "(not measured)",
        )
    notes = [f"{n} samples, {how}"]
    notes.append("weights from the weight column" if weights is not None else "uniform weights")
    if how.startswith("spectral") and negative.any():
        notes.append(f"{int(negative.sum())} spectra outside the sRGB gamut (a channel < 0)")
    return Measurements.from_directions(
        wi,
        wo,
        rgb,
        weights=weights,
        negative=policy,
        source=f"{source} (table: {'; '.join(notes)})",
    )


def _directions(source: str, cols: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    has_dir = [c for c in DIRECTION_COLUMNS if c in cols]
    has_ang = [c for c in ANGLE_COLUMNS if c in cols]
    if has_dir and has_ang:
        raise MeasurementFileError(
            source,
            f"mixed conventions: direction columns {has_dir} and angle columns {has_ang}; "
            "give one of the two sets",
        )
    if has_ang:
        _require(source, cols, ANGLE_COLUMNS, "angle")
        t_i, p_i, t_o, p_o = (np.radians(cols[c]) for c in ANGLE_COLUMNS)
        return spherical_to_vector(t_i, p_i), spherical_to_vector(t_o, p_o)
    _require(source, cols, DIRECTION_COLUMNS, "direction")
    wi = np.stack([cols[c] for c in DIRECTION_COLUMNS[:3]], axis=1)
    wo = np.stack([cols[c] for c in DIRECTION_COLUMNS[3:]], axis=1)
    return _unit(source, wi, "wi"), _unit(source, wo, "wo")


def _require(source: str, cols: dict, names: tuple[str, ...], kind: str) -> None:
    missing = [c for c in names if c not in cols]
    if missing:
        raise MeasurementFileError(
            source,
            f"missing column {', '.join(missing)}: the {kind} columns are {','.join(names)}"
            + ("" if kind != "direction" else f" (or angles {','.join(ANGLE_COLUMNS)})"),
        )


def _unit(source: str, w: np.ndarray, name: str) -> np.ndarray:
    norm = np.linalg.norm(w, axis=1)
    off = np.abs(norm - 1.0)
    if np.any(off > UNIT_TOL):
        row = int(np.argmax(off > UNIT_TOL))
        raise MeasurementFileError(
            source,
            f"{name} in data row {row + 1} has norm {norm[row]:.6g}, not a unit vector "
            f"({int(np.sum(off > UNIT_TOL))} rows off by more than {UNIT_TOL:g})",
        )
    return w / norm[:, None]


def _values(source: str, cols: dict[str, np.ndarray]) -> tuple[np.ndarray, str]:
    has_rgb = [c for c in RGB_COLUMNS if c in cols]
    spectral = sorted(
        ((float(m.group(1)), c) for c in cols if (m := _SPECTRAL.match(c))), key=lambda t: t[0]
    )
    if has_rgb and spectral:
        raise MeasurementFileError(
            source,
            f"mixed conventions: RGB columns {has_rgb} and spectral columns "
            f"{[c for _, c in spectral]}; give one of the two",
        )
    if spectral:
        wl = np.array([w for w, _ in spectral])
        if np.any(np.diff(wl) <= 0):
            raise MeasurementFileError(source, f"repeated wavelength among {wl.tolist()} nm")
        spectra = np.stack([cols[c] for _, c in spectral], axis=1)
        how = f"spectral {wl[0]:g}-{wl[-1]:g} nm ({wl.size} bands) to linear sRGB"
        return spectrum_to_rgb(wl, spectra), how
    if not has_rgb:
        raise MeasurementFileError(
            source, f"missing value columns: give {','.join(RGB_COLUMNS)} or nm<wavelength> columns"
        )
    _require(source, cols, RGB_COLUMNS, "RGB value")
    return np.stack([cols[c] for c in RGB_COLUMNS], axis=1), "linear RGB"
