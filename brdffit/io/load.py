"""Open a measurement file by its kind, picked by its suffix.

``load_measurements(path)`` reads a MERL binary (any other name), evaluates an NBRDF
network (``<name>.json`` with ``<name>.h5`` beside it, either path given) or an RGL-EPFL
``.bsdf`` file (:mod:`brdffit.io.rgl`, needs Mitsuba 3) on the MERL grid, or reads a table
of samples, ``.csv`` or ``.npz`` (:mod:`brdffit.io.table`). ``stride`` keeps a strided
sub-grid (odd divisors of 90, 90, 180), which makes fits several times faster at the
price of resolution; a table is read as it is (``stride`` must be 1).
"""

from __future__ import annotations

import os
from pathlib import Path

from brdffit.core.measurements import Measurements
from brdffit.errors import MeasurementFileError, ParameterError
from brdffit.io.merl import read_merl
from brdffit.io.merl_grid import merl_subgrid
from brdffit.io.nbrdf import read_nbrdf
from brdffit.io.rgl import read_rgl
from brdffit.io.table import read_table


def load_measurements(
    path: str | os.PathLike[str], *, stride: tuple[int, int, int] | int = 1
) -> Measurements:
    """Measurements from ``path``: MERL binary, NBRDF .json/.h5, RGL .bsdf, or .csv/.npz table.

    Grid sources are evaluated on the (strided) MERL grid; a table keeps its samples.

    Raises :class:`MeasurementFileError` naming the file when it cannot be read, and
    :class:`~brdffit.errors.ParameterError` for a stride other than 1 on a table.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in (".csv", ".npz"):
        if stride not in (1, (1, 1, 1)):
            raise ParameterError(
                f"stride {stride} for {p}: a table of samples is read as it is; "
                "stride applies to MERL-grid sources (MERL, NBRDF, RGL .bsdf)"
            )
        return read_table(p)
    if suffix == ".bsdf":
        return read_rgl(p, stride=stride)
    if p.suffix in (".json", ".h5"):
        return read_nbrdf(p).to_measurements(stride=stride)
    if not p.exists():
        raise MeasurementFileError(p, "file not found")
    data = read_merl(p)
    return data if stride in (1, (1, 1, 1)) else merl_subgrid(data, stride)
