"""Open a measurement file by its kind: a MERL binary or an NBRDF network.

``load_measurements(path)`` reads a MERL binary (any name), or evaluates an NBRDF
network (``<name>.json`` with ``<name>.h5`` beside it, either path given) on the MERL
grid. ``stride`` keeps a strided sub-grid (odd divisors of 90, 90, 180), which makes
fits several times faster at the price of resolution.
"""

from __future__ import annotations

import os
from pathlib import Path

from brdffit.errors import MeasurementFileError
from brdffit.measurements import Measurements
from brdffit.merl import merl_subgrid, read_merl


def load_measurements(
    path: str | os.PathLike[str], *, stride: tuple[int, int, int] | int = 1
) -> Measurements:
    """Measurements from ``path`` (MERL binary or NBRDF .json/.h5), on the (strided) MERL grid.

    Raises :class:`MeasurementFileError` naming the file when it cannot be read.
    """
    p = Path(path)
    if p.suffix in (".json", ".h5"):
        from brdffit.nbrdf import read_nbrdf

        return read_nbrdf(p).to_measurements(stride=stride)
    if not p.exists():
        raise MeasurementFileError(p, "file not found")
    data = read_merl(p)
    return data if stride in (1, (1, 1, 1)) else merl_subgrid(data, stride)
