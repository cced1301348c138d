"""The fit and the data at any directions: model evaluation, nearest-bin lookup, slices.

Nothing here draws; everything returns numpy arrays (float64). Units and conventions as
:mod:`brdffit.report.render`: ``f(wi, wo)`` in 1/sr per linear RGB channel, unit (n, 3)
directions in the local shading frame (normal +z), ``wi`` toward the light.

Fit side (:func:`model_brdf`): a fit (a :class:`~brdffit.core.result.FitResult`, or a
``(model, params)`` pair) evaluated by its jitted ``model.eval`` at any directions.

Data side (:func:`nearest_bin`): samples on the MERL grid or a strided sub-grid of it
(:func:`brdffit.io.merl_grid.merl_grid`, :func:`merl_stride`), read by nearest-bin lookup, the
MERL reader's rule (:func:`brdffit.core.geometry.merl_indices`), a strided sample standing for
its whole coarse cell. A channel of a bin that is not fitted (not measured, outside the
reader's cut, or the bin centre below the horizon) gives NaN; with ``fill=True`` it takes
the value of the nearest bin, in grid-index distance, whose channel is measured (so a
file cut at 85 degrees, or with holes, still draws a whole sphere from the data that
exist). :func:`slice_indices` picks one measured (theta_d, phi_d) line.

In-plane directions (:func:`in_plane_directions`): the plane of incidence (x-z,
``phi_d = 0``), angles in degrees, signed so that + is the specular side.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from brdffit import models
from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import MERL_SHAPE, above_horizon, io_to_halfdiff, merl_indices
from brdffit.core.measurements import Measurements
from brdffit.core.result import FitResult
from brdffit.errors import MeasurementsError
from brdffit.io.merl_grid import merl_grid

Fit = FitResult | tuple[AbstractModel, Mapping[str, object]]
Brdf = Callable[[np.ndarray, np.ndarray], np.ndarray]
_ODD_DIVISORS = (1, 3, 5, 9, 15, 45)  # odd divisors of 90 and of 180
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
        out = [_eval(model, p, *pairs[:, i : i + _CHUNK]) for i in range(0, pairs.shape[1], _CHUNK)]
        return np.concatenate([np.asarray(o) for o in out])[:n]

    return model, brdf


@eqx.filter_jit
def _eval(model: AbstractModel, params: dict, wi: jax.Array, wo: jax.Array) -> jax.Array:
    return model.eval(params, wi, wo)


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


def merl_stride(data: Measurements) -> tuple[int, int, int]:
    """The stride of the MERL (sub-)grid ``data`` lies on, in file order.

    Raises :class:`MeasurementsError` naming the source when the samples are scattered
    directions rather than a MERL grid (:func:`brdffit.io.merl_grid.merl_grid`).
    """
    if data.grid == MERL_SHAPE:
        return (1, 1, 1)
    for s in itertools.product(_ODD_DIVISORS, repeat=3):
        shape = [n // k for n, k in zip(MERL_SHAPE, s, strict=True)]
        if int(np.prod(shape)) != data.n:
            continue
        g = merl_grid(s)
        if all(
            np.allclose(getattr(g, a), getattr(data, a), rtol=0, atol=1e-9)
            for a in ("theta_h", "theta_d", "phi_d")
        ):
            return s
    raise MeasurementsError(
        f"{data.source!r}: {data.n} samples are not a MERL grid or strided sub-grid in file "
        "order; the data side of a figure needs one (read a MERL file, or resample)"
    )


def nearest_bin(
    data: Measurements, wi: np.ndarray, wo: np.ndarray, *, fill: bool = False
) -> np.ndarray:
    """Data values (n, 3) in 1/sr at arbitrary directions, by nearest MERL bin.

    As MERL's ``lookup_brdf_val`` (:func:`brdffit.io.merl_grid.lookup`), on the full grid or a
    strided one (a sample stands for its coarse cell). Directions below the horizon give
    0; a channel that ``data.channel_valid`` marks unfitted gives NaN, or with ``fill``
    the value of the nearest bin whose channel is measured (:func:`filled_values`).
    """
    stride = np.array(merl_stride(data))
    shape = tuple(int(n) for n in np.array(MERL_SHAPE) // stride)
    th, td, pd, _ = io_to_halfdiff(wi, wo)
    fine = merl_indices(th, td, pd)
    flat = np.ravel_multi_index(tuple(i // s for i, s in zip(fine, stride, strict=True)), shape)
    if fill:
        out = filled_values(data, shape)[flat]
    else:
        out = np.where(data.channel_valid[flat], data.values[flat], np.nan)
    out[~above_horizon(wi, wo)] = 0.0
    return out


def filled_values(data: Measurements, shape: tuple[int, int, int]) -> np.ndarray:
    """(N, 3) ``data.values`` with every unfitted channel replaced by that channel's value
    in the nearest fitted bin (Euclidean distance in (theta_h, theta_d, phi_d) bin
    indices; ``scipy.ndimage.distance_transform_edt``). A channel with no fitted bin
    stays NaN."""
    from scipy.ndimage import distance_transform_edt  # deferred: scipy submodule

    out = np.full(data.values.shape, np.nan)
    for c in range(3):
        ok = data.channel_valid[:, c]
        if not ok.any():
            continue
        idx = distance_transform_edt(
            ~ok.reshape(shape), return_distances=False, return_indices=True
        )
        source = np.ravel_multi_index(tuple(idx), shape).ravel()
        out[:, c] = data.values[source, c]
    return out


# --------------------------------------------------------------------------- in-plane directions


def in_plane_directions(
    theta_i_deg: float, theta_o_deg: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo) in the plane of incidence (x-z plane; ``phi_d = 0``).

    ``wi = (-sin theta_i, 0, cos theta_i)``, ``wo = (sin theta_o, 0, cos theta_o)``: a
    positive ``theta_o`` lies on the specular side (mirror direction at ``theta_o =
    theta_i``), a negative one on the side of the light (backscatter at ``-theta_i``).
    """
    to = np.deg2rad(np.asarray(theta_o_deg, float))
    ti = np.deg2rad(theta_i_deg)
    wi = np.broadcast_to([-np.sin(ti), 0.0, np.cos(ti)], (to.size, 3)).copy()
    wo = np.stack([np.sin(to), np.zeros_like(to), np.cos(to)], axis=-1)
    return wi, wo
