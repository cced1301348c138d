"""The header of a Mitsuba tensor file (an RGL-EPFL ``.bsdf`` material), read without Mitsuba.

:func:`rgl_header` checks that a file is a tensor file of Mitsuba's ``measured`` format
and says what it holds (:class:`RglFile`: description, isotropy, RGB or spectral, the
incidence nodes, the table resolution), so a bad file is refused before Mitsuba is
imported (:mod:`brdffit.io.rgl` evaluates it).
"""

from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brdffit.errors import MeasurementFileError, reading

_REQUIRED = ("description", "theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance", "jacobian")
_DTYPES = {1: "u1", 2: "i1", 3: "u2", 4: "i2", 5: "u4", 6: "i4", 7: "u8", 8: "i8"}
_DTYPES |= {9: "f2", 10: "f4", 11: "f8"}


@dataclass(frozen=True)
class RglFile:
    """What the header of a ``.bsdf`` file says.

    Fields: ``path``; ``description`` (the file's text); ``isotropic`` (at most two
    ``phi_i`` nodes); ``spectral`` (a ``wavelengths`` field; else RGB); ``theta_i_deg``,
    the incidence nodes in degrees; ``resolution``, the (n_phi, n_theta) size of each
    half-vector table; ``fields``: name -> (dtype, shape, byte offset).
    """

    path: str
    description: str
    isotropic: bool
    spectral: bool
    theta_i_deg: tuple[float, ...]
    resolution: tuple[int, int]
    fields: dict


def rgl_header(path: str | os.PathLike[str]) -> RglFile:
    """Read and check the header of a ``.bsdf`` tensor file (no Mitsuba needed).

    Format (Mitsuba's ``TensorFile``): ``"tensor_file\\0"``, version (1, 0) as two
    bytes, a uint32 field count, then per field a uint16 name length, the name, a
    uint16 rank, a uint8 dtype code, a uint64 byte offset and rank x uint64 sizes.

    Raises :class:`MeasurementFileError` for a missing file, a file that is not a tensor
    file, a truncated one, or a missing field of the ``measured`` format.
    """
    p = Path(path)
    with reading(p, "a .bsdf file"):
        size = p.stat().st_size
        with open(p, "rb") as f:
            magic = f.read(12)
            if magic != b"tensor_file\0":
                raise MeasurementFileError(
                    p, "not a Mitsuba tensor file (no 'tensor_file' header); expected an "
                    "RGL-EPFL .bsdf file",
                )  # fmt: skip
            version, (n_fields,) = f.read(2), struct.unpack("<I", _read(f, p, 4))
            if version != b"\x01\x00":
                raise MeasurementFileError(
                    p, f"tensor file version {tuple(version)}; expected (1, 0)"
                )
            fields = {}
            for _ in range(n_fields):
                (n_name,) = struct.unpack("<H", _read(f, p, 2))
                name = _read(f, p, n_name).decode("utf-8", "replace")
                ndim, code, offset = struct.unpack("<HBQ", _read(f, p, 11))
                shape = struct.unpack(f"<{ndim}Q", _read(f, p, 8 * ndim))
                if code not in _DTYPES:
                    raise MeasurementFileError(p, f"field {name!r} has unknown dtype code {code}")
                dtype = np.dtype(_DTYPES[code])
                if offset + dtype.itemsize * math.prod(shape) > size:  # Python ints: no overflow
                    raise MeasurementFileError(p, f"truncated: field {name!r} runs past the end")
                fields[name] = (dtype, tuple(int(s) for s in shape), int(offset))
            description = _field(f, fields.get("description")).tobytes().decode("utf-8", "replace")
            theta_i = _field(f, fields.get("theta_i"))
    spectral = "wavelengths" in fields
    values = ("spectra", "wavelengths") if spectral else ("rgb",)
    missing = [k for k in (*_REQUIRED, *values) if k not in fields]
    if missing:
        raise MeasurementFileError(
            p, f"missing field {', '.join(missing)}: not a file of Mitsuba's 'measured' format"
        )
    for name, rank in (("phi_i", 1), ("theta_i", 1), (values[0], 2)):
        if len(fields[name][1]) < rank:
            raise MeasurementFileError(
                p, f"field {name!r} has shape {fields[name][1]}; expected at least {rank} axes"
            )
    return RglFile(
        path=str(p),
        description=description,
        isotropic=fields["phi_i"][1][0] <= 2,
        spectral=spectral,
        theta_i_deg=tuple(float(t) for t in np.degrees(theta_i.astype(float))),
        resolution=fields[values[0]][1][-2:],
        fields=fields,
    )


def _read(f, p: Path, n: int) -> bytes:
    b = f.read(n)
    if len(b) != n:
        raise MeasurementFileError(p, "truncated tensor-file header")
    return b


def _field(f, spec) -> np.ndarray:
    if spec is None:
        return np.zeros(0, np.uint8)
    dtype, shape, offset = spec
    f.seek(offset)
    return np.fromfile(f, dtype=dtype, count=math.prod(shape)).reshape(shape)
