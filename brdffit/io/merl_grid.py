"""The MERL grid: its geometry, strided sub-grids, Measurements on it, and lookup.

Grid convention: every cell is represented by its bin centre (see
:func:`brdffit.core.geometry.merl_bin_centres`) with ``phi_h = 0``; its weight is the solid
angle measure ``dwi dwo`` of the cell (sr^2,
:func:`brdffit.core.geometry.merl_solid_angle_weights`).

Coarse grids for fast tests and fits: :func:`merl_grid` with an odd ``stride`` per axis
keeps every ``stride``-th MERL bin, the middle one of each block of ``stride`` bins, so
each sample sits at the centre of its coarse cell (in MERL's ``u = sqrt(theta_h/(pi/2))``,
``theta_d`` and ``phi_d``) and is still a MERL bin centre; its weight is the summed
weight of the fine cells of its block. :func:`merl_subgrid` picks those cells out of a
full table. :func:`lookup` reads a full table at arbitrary directions, nearest bin;
:func:`nearest_bin` reads Measurements on the grid or a strided one (:func:`merl_stride`)
the same way.

The binary file format itself: :mod:`brdffit.io.merl`.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass

import numpy as np
from jaxtyping import ArrayLike, Bool, Float, Int
from scipy.ndimage import distance_transform_edt

from brdffit.core.geometry import (
    MERL_SHAPE,
    above_horizon,
    io_to_halfdiff,
    merl_indices,
    merl_solid_angle_weights,
)
from brdffit.core.measurements import NEGATIVE_POLICIES, Measurements, readonly
from brdffit.errors import MeasurementsError, ParameterError

MERL_N_CELLS: int = int(np.prod(MERL_SHAPE))
"""Cells per channel of a MERL table (1,458,000)."""


# --------------------------------------------------------------------------- grid geometry


@dataclass(frozen=True, eq=False)
class MerlGrid:
    """Geometry of the MERL grid or of a strided sub-grid; the same for every table.

    All arrays are read-only and flat in file order (C order of ``shape``).

    Fields:
    - ``stride``: bins of the full grid per coarse cell along (theta_h, theta_d, phi_d).
    - ``shape``: the coarse grid shape, ``MERL_SHAPE // stride``.
    - ``index``: (N,) flat index of each sample's bin in the full MERL table.
    - ``theta_h``, ``theta_d``, ``phi_d``: (N,) bin-centre angles (radians, phi_d in [0, pi)).
    - ``wi``, ``wo``: (N, 3) directions from those angles with ``phi_h = 0``.
    - ``weights``: (N,) solid angle ``dwi dwo`` (sr^2) of the fine cells a sample stands for.
    - ``above``: (N,) True where both directions are above the horizon.
    """

    stride: tuple[int, int, int]
    shape: tuple[int, int, int]
    index: Int[np.ndarray, " n"]
    theta_h: Float[np.ndarray, " n"]
    theta_d: Float[np.ndarray, " n"]
    phi_d: Float[np.ndarray, " n"]
    wi: Float[np.ndarray, "n 3"]
    wo: Float[np.ndarray, "n 3"]
    weights: Float[np.ndarray, " n"]
    above: Bool[np.ndarray, " n"]

    @property
    def n(self) -> int:
        """Number of samples (cells of the coarse grid)."""
        return int(self.index.shape[0])


def _check_stride(stride: tuple[int, ...] | int) -> tuple[int, int, int]:
    s = (stride,) * 3 if isinstance(stride, int | np.integer) else tuple(stride)
    if len(s) != 3:
        raise ParameterError(f"stride must be an int or 3 ints (theta_h, theta_d, phi_d); got {s}")
    for name, k, n in zip(("theta_h", "theta_d", "phi_d"), s, MERL_SHAPE, strict=True):
        odd_divisors = [d for d in range(1, n + 1, 2) if n % d == 0]
        if int(k) != k or int(k) not in odd_divisors:
            raise ParameterError(
                f"stride for {name} is {k}; accepted: an odd divisor of {n}, one of "
                f"{odd_divisors} (odd, so that each sample is the centre of its coarse cell)"
            )
    return (int(s[0]), int(s[1]), int(s[2]))


def merl_grid(stride: tuple[int, ...] | int = (1, 1, 1)) -> MerlGrid:
    """The (strided) MERL grid geometry, computed once per stride and cached.

    Arguments:
    - ``stride``: an odd divisor of the bin count per axis (90, 90, 180), or one int for
      all three; ``(1, 1, 1)`` is the full grid. E.g. ``(5, 5, 5)`` gives 18 x 18 x 36 =
      11,664 samples, ``(9, 9, 9)`` gives 2,000.

    Returns: a :class:`MerlGrid` (read-only arrays shared between calls).
    """
    return _merl_grid_cached(_check_stride(stride))


@functools.lru_cache(maxsize=8)
def _merl_grid_cached(stride: tuple[int, int, int]) -> MerlGrid:
    n_th, n_td, n_pd = MERL_SHAPE
    s_th, s_td, s_pd = stride
    shape = (n_th // s_th, n_td // s_td, n_pd // s_pd)
    i_th = np.arange(shape[0]) * s_th + s_th // 2
    i_td = np.arange(shape[1]) * s_td + s_td // 2
    i_pd = np.arange(shape[2]) * s_pd + s_pd // 2
    th_all = ((np.arange(n_th) + 0.5) / n_th) ** 2 * (np.pi / 2)
    td_all = (np.arange(n_td) + 0.5) / n_td * (np.pi / 2)
    # Fine-cell weights depend on (theta_h, theta_d) only; sum them over each block.
    w_fine = merl_solid_angle_weights(th_all[:, None], td_all[None, :])
    w_block = w_fine.reshape(shape[0], s_th, shape[1], s_td).sum(axis=(1, 3)) * s_pd
    th1, td1, pd1 = th_all[i_th], td_all[i_td], (i_pd + 0.5) / n_pd * np.pi
    th, td, pd = np.meshgrid(th1, td1, pd1, indexing="ij")
    wi, wo = _grid_directions(th1, td1, pd1)
    index = np.ravel_multi_index(np.meshgrid(i_th, i_td, i_pd, indexing="ij"), MERL_SHAPE)
    weights = np.broadcast_to(w_block[:, :, None], shape)
    return MerlGrid(
        stride=stride,
        shape=shape,
        index=readonly(index.ravel()),
        theta_h=readonly(th.ravel()),
        theta_d=readonly(td.ravel()),
        phi_d=readonly(pd.ravel()),
        wi=readonly(wi),
        wo=readonly(wo),
        weights=readonly(weights.ravel()),
        above=readonly(above_horizon(wi, wo)),
    )


def _grid_directions(
    theta_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo), each (N, 3), on the product grid of three 1-D angle axes (``phi_h = 0``).

    :func:`brdffit.core.geometry.halfdiff_to_io` written out for a grid: ``wi = R_y(theta_h) d``
    and ``wo = R_y(theta_h) (-dx, -dy, dz)``, with the trigonometry on the axes only
    (about 10x faster than the general function on the 1.46 M cells).
    """
    st, ct = np.sin(theta_h)[:, None, None], np.cos(theta_h)[:, None, None]
    sd, dz = np.sin(theta_d)[None, :, None], np.cos(theta_d)[None, :, None]
    dx = sd * np.cos(phi_d)[None, None, :]
    dy = sd * np.sin(phi_d)[None, None, :]
    shape = (theta_h.size, theta_d.size, phi_d.size)
    wi, wo = np.empty((*shape, 3)), np.empty((*shape, 3))
    ct_dx, st_dz, ct_dz, st_dx = ct * dx, st * dz, ct * dz, st * dx
    wi[..., 0] = ct_dx + st_dz
    wi[..., 1] = dy
    wi[..., 2] = ct_dz - st_dx
    wo[..., 0] = st_dz - ct_dx
    wo[..., 1] = -dy
    wo[..., 2] = ct_dz + st_dx
    n = int(np.prod(shape))
    return wi.reshape(n, 3), wo.reshape(n, 3)


def merl_grid_measurements(
    values: Float[ArrayLike, "3 a b c"],
    *,
    source: str,
    stride: tuple[int, ...] | int = (1, 1, 1),
    channel_scales: ArrayLike | None = None,
    valid: Bool[ArrayLike, "a b c"] | None = None,
    negative: str = "not_measured",
    zenith_cut_deg: float | None = None,
) -> Measurements:
    """Measurements on the (strided) MERL grid from a channel-first value cube.

    A channel of a sample is fitted where both directions are above the horizon, the
    value is finite, ``valid`` (if given) is True and, under ``negative="not_measured"``,
    the value is not negative. Non-finite values are stored as -1 and masked; negatives
    are kept as they are.

    Arguments:
    - ``values``: (3, *grid shape) RGB BRDF values in 1/sr (no cosine), in
      ``[channel, theta_h, theta_d, phi_d]`` order (a MERL file body times the scales).
    - ``source``: provenance (path or description).
    - ``stride``: the grid, as in :func:`merl_grid`; ``grid=MERL_SHAPE`` is set on the
      result only for the full grid.
    - ``channel_scales``: scales the numbers were multiplied by (default 1, 1, 1).
    - ``valid``: optional extra mask of the grid shape.
    - ``negative``: what a negative channel means
      (:data:`~brdffit.core.measurements.NEGATIVE_POLICIES`).
    - ``zenith_cut_deg``: the source's zenith cut, recorded for :meth:`Measurements.mask_counts`.

    Returns: :class:`Measurements` in file order.
    """
    g = merl_grid(stride)
    cube = np.asarray(values, dtype=np.float64)
    if cube.shape != (3, *g.shape):
        raise MeasurementsError(
            f"values has shape {cube.shape}; expected (3, {g.shape[0]}, {g.shape[1]}, "
            f"{g.shape[2]}) for stride {g.stride}"
        )
    if negative not in NEGATIVE_POLICIES:
        raise MeasurementsError(
            f"negative={negative!r}; accepted: {', '.join(map(repr, NEGATIVE_POLICIES))}"
        )
    vals = np.array(cube.reshape(3, g.n).T, order="C")
    channels = np.isfinite(vals) & g.above[:, None]
    if negative == "not_measured":
        channels &= vals >= 0.0
    if valid is not None:
        channels &= np.asarray(valid, dtype=bool).reshape(g.n)[:, None]
    vals[~np.isfinite(vals)] = -1.0
    return grid_measurements(g, vals, channels, source, channel_scales, zenith_cut_deg)


def grid_measurements(
    g: MerlGrid,
    values: np.ndarray,
    channel_valid: np.ndarray,
    source: str,
    channel_scales: ArrayLike | None,
    zenith_cut_deg: float | None = None,
) -> Measurements:
    """:class:`Measurements` on grid ``g``; ``channel_valid`` (N, 3) the fitted channels."""
    scales = np.ones(3) if channel_scales is None else np.asarray(channel_scales, float)
    return Measurements(
        wi=g.wi,
        wo=g.wo,
        theta_h=g.theta_h,
        theta_d=g.theta_d,
        phi_d=g.phi_d,
        values=values,
        weights=g.weights,
        valid=channel_valid.any(axis=1),
        source=source,
        channel_scales=scales,
        grid=MERL_SHAPE if g.stride == (1, 1, 1) else None,
        channel_valid=channel_valid,
        zenith_cut_deg=zenith_cut_deg,
        stride=g.stride,
    )


def merl_subgrid(data: Measurements, stride: tuple[int, ...] | int) -> Measurements:
    """The cells of a full MERL table that form the strided grid :func:`merl_grid` (stride).

    Values and validity are those of the picked cells; weights become the coarse-cell
    weights, so weighted sums over the sub-grid approximate those over the full table.

    Arguments:
    - ``data``: a full MERL table (``data.grid == MERL_SHAPE``), e.g. from
      :func:`brdffit.io.merl.read_merl`.
    - ``stride``: as in :func:`merl_grid`.

    Returns: :class:`Measurements` with ``grid=None`` (unless the stride is 1), synthetic
    when ``data`` is (the picked cells are still a model's own values).
    """
    require_full_table(data, "merl_subgrid")
    g = merl_grid(stride)
    sub = grid_measurements(
        g,
        data.values[g.index],
        data.channel_valid[g.index],
        data.source,
        data.channel_scales,
        data.zenith_cut_deg,
    )
    return sub.replace(synthetic=data.synthetic)


def require_full_table(data: Measurements, what: str) -> None:
    """Raise :class:`MeasurementsError` unless ``data`` is a full MERL table; ``what`` names
    the caller in the message."""
    if data.grid != MERL_SHAPE:
        raise MeasurementsError(
            f"{what} needs a full MERL table (grid={MERL_SHAPE}, {MERL_N_CELLS} samples in "
            f"file order); {data.source!r} has grid={data.grid} with {data.n} samples. "
            "Resample it first with to_merl_grid."
        )


# --------------------------------------------------------------------------- lookup


def lookup(
    data: Measurements,
    wi: Float[ArrayLike, "n 3"],
    wo: Float[ArrayLike, "n 3"],
    *,
    unmeasured: str = "nan",
) -> Float[np.ndarray, "n 3"]:
    """The table value at arbitrary directions, nearest bin as MERL's reference reader.

    As ``lookup_brdf_val`` in MERL's BRDFRead.cpp: Rusinkiewicz angles of (wi, wo),
    ``phi_d`` folded into [0, pi), the bin from :func:`brdffit.core.geometry.merl_indices`, and
    the stored value (1/sr, no cosine; no interpolation). Directions below the horizon
    (``wi.z <= 0`` or ``wo.z <= 0``) give 0. A bin holding a negative number ("not
    measured") gives NaN by default, so that a missing measurement is never mistaken
    for a value; ``unmeasured="raw"`` returns the stored negative value as the
    reference does. The stored value is returned whatever ``data.valid`` says about the
    bin centre (a query above the horizon can fall in a bin whose centre is below it).

    Arguments:
    - ``data``: a full MERL table (``grid == MERL_SHAPE``).
    - ``wi``, ``wo``: (n, 3) unit directions toward the light and the viewer.
    - ``unmeasured``: ``"nan"`` or ``"raw"``, see above.

    Returns: (n, 3) RGB values in 1/sr.
    """
    require_full_table(data, "lookup")
    if unmeasured not in ("nan", "raw"):
        raise ParameterError(f"unmeasured={unmeasured!r}; accepted: 'nan' or 'raw'")
    wi = np.asarray(wi, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64)
    theta_h, theta_d, phi_d, _ = io_to_halfdiff(wi, wo)
    flat = np.ravel_multi_index(merl_indices(theta_h, theta_d, phi_d), MERL_SHAPE)
    out = data.values[flat]  # fancy indexing: a fresh, writable array
    if unmeasured == "nan":
        out[(out < 0.0).any(axis=1)] = np.nan
    out[~above_horizon(wi, wo)] = 0.0
    return out


_ODD_DIVISORS = (1, 3, 5, 9, 15, 45)  # odd divisors of 90 and of 180


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
