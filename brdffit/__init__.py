"""brdffit: fit analytic BRDF models to measured reflectance.

Public API (everything else may change): :func:`read_merl`, :func:`write_merl`,
:func:`read_table`, :func:`read_rgl`, :func:`read_rgl_at`, :func:`read_nbrdf`,
:func:`read_nbrdf_measurements`, :func:`load_measurements` (any of them by file type),
:func:`synthesize`, :func:`fit`, :func:`fit_many`, :func:`sample`, :func:`rank`,
:func:`simplify`, :class:`Measurements`, :class:`FitResult`, :class:`Posterior`,
:class:`Reduction`, :mod:`brdffit.models`, :mod:`brdffit.export` (:class:`Export`,
:func:`write_exports`), :mod:`brdffit.report.figures`, :func:`write_fit_html`,
:func:`write_sweep_html`, :func:`keep_freed_memory` and the error types.

Importing brdffit turns on JAX's 64-bit mode: fits run in float64 by default because
measured BRDF values span 1e-4 to 1e4. float32 evaluation still works by passing
float32 directions.
"""

# first: turns on JAX's 64-bit mode before any module builds an array
from brdffit.util.jax_config import enable_compilation_cache  # isort: skip

from brdffit import models
from brdffit.core.measurements import Measurements
from brdffit.core.result import FitResult, Status
from brdffit.engine.fit import fit, fit_many
from brdffit.engine.posterior import Posterior
from brdffit.engine.sample import sample
from brdffit.errors import (
    BrdffitError,
    ChainTooShortError,
    FitError,
    MeasurementFileError,
    MeasurementsError,
    MissingDependencyError,
    ParameterError,
)
from brdffit.export import Export, ExportError, write_exports
from brdffit.io.load import load_measurements
from brdffit.io.merl import read_merl, write_merl
from brdffit.io.nbrdf import read_nbrdf, read_nbrdf_measurements
from brdffit.io.rgl import read_rgl, read_rgl_at
from brdffit.io.synthetic import synthesize
from brdffit.io.table import read_table
from brdffit.report.html import write_fit_html
from brdffit.report.sweep_html import write_sweep_html
from brdffit.selection.rank import Ranking, rank
from brdffit.selection.reduction import Reduction
from brdffit.selection.simplify import simplify
from brdffit.util.allocator import keep_freed_memory
from brdffit.util.version import __version__ as __version__

__all__ = [
    "enable_compilation_cache",
    "keep_freed_memory",
    "FitResult",
    "Posterior",
    "Ranking",
    "Reduction",
    "Status",
    "fit",
    "fit_many",
    "rank",
    "load_measurements",
    "read_merl",
    "read_nbrdf",
    "read_nbrdf_measurements",
    "read_rgl",
    "read_rgl_at",
    "read_table",
    "sample",
    "simplify",
    "synthesize",
    "write_fit_html",
    "write_merl",
    "write_sweep_html",
    "export",
    "Export",
    "ExportError",
    "write_exports",
    "BrdffitError",
    "ChainTooShortError",
    "FitError",
    "MeasurementFileError",
    "MeasurementsError",
    "MissingDependencyError",
    "Measurements",
    "ParameterError",
    "models",
]
