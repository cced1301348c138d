"""The fit and the data at any directions: model evaluation, nearest-bin lookup, slices.

Nothing here draws; everything returns numpy arrays (float64). Units and conventions as
:mod:`brdffit.report.render`: ``f(wi, wo)`` in 1/sr per linear RGB channel, unit (n, 3)
directions in the local shading frame (normal +z), ``wi`` toward the light.

Fit side (:func:`model_brdf`): a fit (a :class:`~brdffit.core.result.FitResult`, or a
``(model, params)`` pair) evaluated by its jitted ``model.eval`` at any directions.

Data side: :func:`brdffit.io.merl_grid.nearest_bin` reads measurements at any directions
(nearest MERL bin); :func:`slice_indices` here picks one measured (theta_d, phi_d) line.

In-plane directions: :func:`brdffit.core.geometry.in_plane_directions`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import jax.numpy as jnp
import numpy as np

from brdffit import models
from brdffit.core.abstract_model import AbstractModel, eval_compiled
from brdffit.core.measurements import Measurements
from brdffit.core.result import FitResult
from brdffit.errors import MeasurementsError

Fit = FitResult | tuple[AbstractModel, Mapping[str, object]]
Brdf = Callable[[np.ndarray, np.ndarray], np.ndarray]
_CHUNK = 16384  # rows per jitted model evaluation


# --------------------------------------------------------------------------- model and data


def model_brdf(fit: Fit) -> tuple[AbstractModel, Brdf]:
    """The model of ``fit`` and ``f(wi, wo)`` -> (n, 3) numpy values in 1/sr (float64)."""
    if isinstance(fit, FitResult):
        model, params = models.model_of(fit), fit.params
    else:
        model, params = fit
    p = {k: jnp.asarray(v, float) for k, v in params.items()}

    def brdf(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        n = len(wi)
        up = np.broadcast_to([0.0, 0.0, 1.0], (-n % _CHUNK, 3))  # pad: one compiled shape
        pairs = jnp.asarray(np.stack([np.concatenate([wi, up]), np.concatenate([wo, up])]))
        ends = range(0, pairs.shape[1], _CHUNK)
        out = [eval_compiled(model, p, *pairs[:, i : i + _CHUNK]) for i in ends]
        return np.concatenate([np.asarray(o) for o in out])[:n]

    return model, brdf


def slice_indices(
    data: Measurements, theta_d_deg: float, phi_d_deg: float
) -> tuple[np.ndarray, float, float]:
    """The valid samples of ``data`` on one (theta_d, phi_d) line, sorted by theta_h.

    The line is the measured (theta_d, phi_d) pair nearest to the asked one (degrees);
    returns the sample indices and that pair in degrees. ``phi_d`` = 0 is the plane of
    incidence (light, normal and viewer in one plane).
    """
    td, pd = np.rad2deg(data.theta_d), np.rad2deg(data.phi_d)
    ok = np.flatnonzero(data.valid)
    if ok.size == 0:
        raise MeasurementsError(f"{data.source}: no valid samples to slice")
    near_td = td[ok][np.argmin(np.abs(td[ok] - theta_d_deg))]
    near_pd = pd[ok][np.argmin(np.abs(pd[ok] - phi_d_deg))]
    idx = np.flatnonzero(data.valid & np.isclose(td, near_td) & np.isclose(pd, near_pd))
    return idx[np.argsort(data.theta_h[idx])], float(near_td), float(near_pd)
