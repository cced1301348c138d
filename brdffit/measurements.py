"""One container for measured or synthetic reflectance samples.

A :class:`Measurements` holds N samples: the directions ``wi`` and ``wo`` (N, 3) in the
local shading frame, their Rusinkiewicz angles, linear RGB BRDF values (N, 3) in 1/sr
(no cosine), per-sample weights (N,) (the solid angle ``dwi dwo`` in sr^2 a sample
stands for), a validity mask (N,) and provenance. Arrays are read-only numpy arrays;
the container is frozen and never changed by a fit.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from brdffit.errors import MeasurementsError
from brdffit.geometry import above_horizon, fold_phi_d, io_to_halfdiff


@dataclass(frozen=True)
class MaskCounts:
    """Why samples of a :class:`Measurements` are invalid; each counted once, under the
    first of these reasons that applies:

    - ``below_horizon``: ``wi.z <= 0`` or ``wo.z <= 0`` (for a MERL table, at the bin
      centre: about 24% of the cells by geometry alone);
    - ``not_measured``: every channel negative (MERL's "not measured" mark; a non-finite
      value is stored as -1, so an all-NaN sample counts here);
    - ``negative_channel``: some channels negative, others not (bad data in one channel,
      e.g. a measurement's blue channel);
    - ``other``: masked by the reader or the caller for another reason (an extra mask).

    ``n`` is the number of samples, valid or not.
    """

    n: int
    below_horizon: int
    not_measured: int
    negative_channel: int
    other: int

    @property
    def n_masked(self) -> int:
        """Number of invalid samples."""
        return self.below_horizon + self.not_measured + self.negative_channel + self.other

    def text(self) -> str:
        """One line: ``349,920 of 1,458,000 samples: 349,920 below the horizon, ...``."""
        reasons = [
            (self.below_horizon, "below the horizon"),
            (self.not_measured, "not measured (every channel negative)"),
            (self.negative_channel, "with a negative channel (the others not)"),
            (self.other, "masked by the reader for another reason"),
        ]
        parts = [f"{k:,} {why}" for k, why in reasons if k]
        if not parts:
            return f"none of {self.n:,} samples"
        return f"{self.n_masked:,} of {self.n:,} samples: {', '.join(parts)}"


def readonly(a: np.ndarray) -> np.ndarray:
    """A C-contiguous, read-only view or copy of ``a``."""
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Measurements:
    """Reflectance samples; build with :meth:`from_directions` or a reader.

    Fields:
    - ``wi``, ``wo``: (N, 3) unit directions, light and viewer.
    - ``theta_h``, ``theta_d``, ``phi_d``: (N,) Rusinkiewicz angles (radians),
      ``phi_d`` folded into [0, pi).
    - ``values``: (N, 3) linear RGB BRDF in 1/sr, without the cosine.
    - ``weights``: (N,) solid-angle measure of each sample, sr^2.
    - ``valid``: (N,) True where the sample was measured and both directions lie
      above the horizon. Invalid samples are kept (file order) but never fitted.
    - ``source``: where the samples came from (a path or a description).
    - ``channel_scales``: (3,) RGB scales applied to the raw numbers (MERL: 1/1500,
      1.15/1500, 1.66/1500; 1 for data already in 1/sr).
    - ``grid``: the MERL table shape when the samples are a full MERL table in file
      order, else ``None``.
    """

    wi: np.ndarray
    wo: np.ndarray
    theta_h: np.ndarray
    theta_d: np.ndarray
    phi_d: np.ndarray
    values: np.ndarray
    weights: np.ndarray
    valid: np.ndarray
    source: str = "unknown"
    channel_scales: np.ndarray = field(default_factory=lambda: np.ones(3))
    grid: tuple[int, int, int] | None = None

    def __post_init__(self) -> None:
        n = np.shape(self.wi)[0] if np.ndim(self.wi) == 2 else -1
        expected = {
            "wi": (n, 3),
            "wo": (n, 3),
            "theta_h": (n,),
            "theta_d": (n,),
            "phi_d": (n,),
            "values": (n, 3),
            "weights": (n,),
            "valid": (n,),
            "channel_scales": (3,),
        }
        for name, shape in expected.items():
            arr = np.asarray(getattr(self, name))
            if arr.shape != shape:
                raise MeasurementsError(
                    f"Measurements.{name} has shape {arr.shape}; expected {shape} "
                    f"(N = {n} samples from wi)"
                )
            dtype = bool if name == "valid" else np.float64
            object.__setattr__(self, name, readonly(arr.astype(dtype, copy=False)))
        if self.grid is not None and int(np.prod(self.grid)) != n:
            raise MeasurementsError(f"Measurements.grid {self.grid} does not hold N = {n} samples")

    @classmethod
    def from_directions(
        cls,
        wi: np.ndarray,
        wo: np.ndarray,
        values: np.ndarray,
        *,
        weights: np.ndarray | None = None,
        valid: np.ndarray | None = None,
        source: str = "unknown",
        channel_scales: np.ndarray | None = None,
        grid: tuple[int, int, int] | None = None,
    ) -> Measurements:
        """Build from directions and values; angles are derived, invalid cells marked.

        ``weights`` defaults to equal weights summing to ``(2 pi)^2`` (samples spread
        uniformly over both hemispheres). Samples with a non-finite or negative value
        (any channel) or a direction below the horizon are marked invalid in addition
        to ``valid``.
        """
        wi = np.asarray(wi, float)
        wo = np.asarray(wo, float)
        values = np.asarray(values, float)
        if wi.ndim != 2 or wi.shape[-1] != 3 or wo.shape != wi.shape:
            raise MeasurementsError(f"wi and wo must both be (N, 3); got {wi.shape} and {wo.shape}")
        if values.shape != wi.shape:
            raise MeasurementsError(f"values must be (N, 3) = {wi.shape}; got {values.shape}")
        n = wi.shape[0]
        theta_h, theta_d, phi_d, _ = io_to_halfdiff(wi, wo)
        ok = above_horizon(wi, wo) & np.all(np.isfinite(values), axis=-1)
        ok &= np.all(values >= 0.0, axis=-1)
        if valid is not None:
            ok &= np.asarray(valid, bool)
        if weights is None:
            weights = np.full(n, (2 * np.pi) ** 2 / max(n, 1))
        clean = np.where(np.isfinite(values), values, -1.0)
        return cls(
            wi=wi,
            wo=wo,
            theta_h=theta_h,
            theta_d=theta_d,
            phi_d=fold_phi_d(phi_d),
            values=clean,
            weights=np.asarray(weights, float),
            valid=ok,
            source=source,
            channel_scales=np.ones(3) if channel_scales is None else channel_scales,
            grid=grid,
        )

    @property
    def n(self) -> int:
        """Number of samples, valid or not."""
        return int(self.wi.shape[0])

    @property
    def n_valid(self) -> int:
        """Number of valid samples."""
        return int(np.count_nonzero(self.valid))

    def replace(self, **changes: object) -> Measurements:
        """A copy with some fields changed (the original is untouched)."""
        return dataclasses.replace(self, **changes)

    def mask_counts(self) -> MaskCounts:
        """Why the invalid samples are masked (:class:`MaskCounts`), from the fields alone."""
        below = ~above_horizon(self.wi, self.wo)
        negative = self.values < 0.0  # non-finite values are stored as -1
        every = negative.all(axis=1) & ~below
        some = negative.any(axis=1) & ~every & ~below
        masked = ~self.valid
        counts = [int(np.count_nonzero(masked & m)) for m in (below, every, some)]
        return MaskCounts(self.n, *counts, int(np.count_nonzero(masked)) - sum(counts))

    def summary(self) -> str:
        """A few lines for ``brdffit info``: size, validity and why samples are masked,
        value range, provenance."""
        v = self.values[self.valid]
        lines = [
            f"source          {self.source}",
            f"samples         {self.n} ({self.n_valid} valid, {self.n - self.n_valid} masked)",
            f"masked          {self.mask_counts().text()}",
            f"grid            {self.grid if self.grid else 'scattered directions'}",
            f"channel scales  {', '.join(f'{s:.6g}' for s in self.channel_scales)}",
        ]
        if v.size:
            for c, name in enumerate("RGB"):
                lo, med, hi = np.percentile(v[:, c], [0, 50, 100])
                lines.append(f"{name} (1/sr)        min {lo:.4g}  median {med:.4g}  max {hi:.4g}")
        return "\n".join(lines)
