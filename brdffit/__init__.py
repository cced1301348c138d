"""brdffit: fit analytic BRDF models to measured reflectance.

Public API (everything else may change): :func:`read_merl`, :func:`write_merl`,
:func:`read_table`, :func:`read_rgl`, :func:`read_rgl_at`,
:func:`synthesize`, :func:`fit`, :func:`fit_many`, :func:`sample`, :func:`rank`,
:func:`simplify`, :class:`Measurements`, :class:`FitResult`, :class:`Posterior`,
:class:`Reduction`, :mod:`brdffit.models`, :mod:`brdffit.export` (:class:`Export`,
:func:`write_exports`), :mod:`brdffit.figures`, :func:`write_fit_html`,
:func:`write_sweep_html` and the error types.

Importing brdffit turns on JAX's 64-bit mode: fits run in float64 by default because
measured BRDF values span 1e-4 to 1e4. float32 evaluation still works by passing
float32 directions.
"""

import os
from importlib import metadata

import jax

try:
    __version__ = metadata.version("brdffit")
except metadata.PackageNotFoundError:  # a source tree that was not installed
    __version__ = None

jax.config.update("jax_enable_x64", True)


def enable_compilation_cache(path: str | None = None) -> None:
    """Keep XLA executables on disk so later processes skip most compile time.

    ``path`` defaults to ``$BRDFFIT_JAX_CACHE`` or ``~/.cache/brdffit/jax``; setting
    ``BRDFFIT_JAX_CACHE=off`` disables it. The command line and the Dask workers call
    this; the test suite does not (see ``tests/conftest.py``).

    Entries go into a subfolder named after this host's CPU and jaxlib, because JAX's
    cache key names neither: a home folder shared by machines of different CPUs (a
    cluster's NFS home) would otherwise hand one machine code compiled for another,
    and XLA aborts the process while loading it, with no Python exception to catch.
    """
    path = path or os.environ.get("BRDFFIT_JAX_CACHE", "~/.cache/brdffit/jax")
    if path.lower() in ("off", "0", "none", ""):
        return
    folder = os.path.join(os.path.expanduser(path), _host_tag())
    jax.config.update("jax_compilation_cache_dir", folder)
    # every program, however quick to compile: a fit runs some 100 small ones (start
    # draws, affine solves), 20-30 ms each to compile and far less to load; with a 0.2 s
    # floor a fresh process compiled 93 of them again, 2.4 s of an 8.5 s first fit
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def _host_tag() -> str:
    """A short name for (machine, CPU model and flags, jaxlib version)."""
    import hashlib
    import platform

    cpu = ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            cpu = "".join(line for line in f if line.startswith(("model name", "flags")))[:20000]
    except OSError:
        cpu = platform.processor()
    try:
        jaxlib = metadata.version("jaxlib")
    except metadata.PackageNotFoundError:
        jaxlib = "unknown"
    digest = hashlib.sha256(f"{platform.machine()}|{cpu}|{jaxlib}".encode()).hexdigest()
    return f"{platform.machine()}-jaxlib{jaxlib}-{digest[:12]}"


from brdffit import models  # noqa: E402
from brdffit.errors import (  # noqa: E402
    BrdffitError,
    ChainTooShortError,
    FitError,
    MeasurementFileError,
    MeasurementsError,
    MissingDependencyError,
    ParameterError,
)
from brdffit.export import Export, ExportError, write_exports  # noqa: E402
from brdffit.fit import fit, fit_many  # noqa: E402
from brdffit.html_report import write_fit_html, write_sweep_html  # noqa: E402
from brdffit.measurements import Measurements  # noqa: E402
from brdffit.merl import read_merl, write_merl  # noqa: E402
from brdffit.rank import Ranking, rank  # noqa: E402
from brdffit.result import FitResult, Status  # noqa: E402
from brdffit.rgl import read_rgl, read_rgl_at  # noqa: E402
from brdffit.sample import Posterior, sample  # noqa: E402
from brdffit.simplify import Reduction, simplify  # noqa: E402
from brdffit.synthetic import synthesize  # noqa: E402
from brdffit.table import read_table  # noqa: E402

__all__ = [
    "enable_compilation_cache",
    "FitResult",
    "Posterior",
    "Ranking",
    "Reduction",
    "Status",
    "fit",
    "fit_many",
    "rank",
    "read_merl",
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
