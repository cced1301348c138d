"""brdffit: fit analytic BRDF models to measured reflectance.

Public API (everything else may change): :func:`read_merl`, :func:`write_merl`,
:func:`synthesize`, :func:`fit`, :func:`sample`, :func:`rank`, :class:`Measurements`,
:class:`FitResult`, :class:`Posterior`, :mod:`brdffit.models` and the error types.

Importing brdffit turns on JAX's 64-bit mode: fits run in float64 by default because
measured BRDF values span 1e-4 to 1e4. float32 evaluation still works by passing
float32 directions.
"""

import jax

jax.config.update("jax_enable_x64", True)

from brdffit import models  # noqa: E402
from brdffit.errors import (  # noqa: E402
    BrdffitError,
    ChainTooShortError,
    FitError,
    MeasurementFileError,
    MeasurementsError,
    ParameterError,
)
from brdffit.measurements import Measurements  # noqa: E402

__all__ = [
    "BrdffitError",
    "ChainTooShortError",
    "FitError",
    "MeasurementFileError",
    "MeasurementsError",
    "Measurements",
    "ParameterError",
    "models",
]
