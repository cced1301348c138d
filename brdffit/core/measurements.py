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

from brdffit.core.geometry import above_horizon, fold_phi_d, io_to_halfdiff
from brdffit.errors import MeasurementsError

NEGATIVE_POLICIES = ("not_measured", "signed")
"""How a source's negative channel values are read (a reader states its policy):

- ``"not_measured"``: a negative number marks that channel of that sample as not measured
  (MERL binaries, RGB tables); the other channels of the sample stay in the fit.
- ``"signed"``: negative numbers are measured values and are fitted as they are (RGB
  converted from spectra and interpolated, as in RGL-EPFL ``.bsdf`` files and spectral
  tables, holds small genuine negatives). Log metrics need ``1 + f cos > 0``; see
  :func:`brdffit.engine.metrics.prepare` for the rare channel outside that domain.
"""


@dataclass(frozen=True)
class MaskCounts:
    """Why samples and channels of a :class:`Measurements` are left out of a fit.

    A sample is counted once, under the first reason that applies:

    - ``below_horizon``: ``wi.z <= 0`` or ``wo.z <= 0`` (for a MERL table, at the bin
      centre: about 24% of the cells by geometry alone);
    - ``outside_cut``: beyond the reader's zenith cut (``Measurements.zenith_cut_deg``),
      where the source was not evaluated (not a missing measurement);
    - ``no_channel``: every channel masked (e.g. MERL's "not measured" mark on all three);
    - ``other``: masked by the reader or the caller although a channel is valid.

    Inside the cut and above the horizon, a sample can still have some channels masked:
    ``channel_negative[c]`` counts channel ``c`` masked holding a negative number (read
    as "not measured" under that source's policy), ``channel_other[c]`` masked for another
    reason. Those of the ``no_channel`` samples are included. ``n`` is the number of
    samples, valid or not.
    """

    n: int
    below_horizon: int
    outside_cut: int
    no_channel: int
    other: int
    channel_negative: tuple[int, int, int] = (0, 0, 0)
    channel_other: tuple[int, int, int] = (0, 0, 0)
    zenith_cut_deg: float | None = None

    @property
    def n_masked(self) -> int:
        """Number of samples with no channel in the fit."""
        return self.below_horizon + self.outside_cut + self.no_channel + self.other

    @property
    def channels_masked(self) -> tuple[int, int, int]:
        """Per RGB channel, the samples above the horizon and inside the cut that lose
        that channel (any reason)."""
        return tuple(a + b for a, b in zip(self.channel_negative, self.channel_other, strict=True))

    def text(self) -> str:
        """One line: ``349,920 of 1,458,000 samples: 349,920 below the horizon, ...``,
        then the channels masked inside the cut per channel and reason."""
        cut = f"{self.zenith_cut_deg:g} deg " if self.zenith_cut_deg is not None else ""
        reasons = [
            (self.below_horizon, "below the horizon"),
            (self.outside_cut, f"outside the reader's {cut}zenith cut (not evaluated)"),
            (self.no_channel, "with no channel measured"),
            (self.other, "masked by the reader for another reason"),
        ]
        parts = [f"{k:,} {why}" for k, why in reasons if k]
        line = (
            f"{self.n_masked:,} of {self.n:,} samples: {', '.join(parts)}"
            if parts
            else f"none of {self.n:,} samples"
        )
        if any(self.channels_masked):
            per = []
            for name, neg, oth in zip(
                "RGB", self.channel_negative, self.channel_other, strict=True
            ):
                why = [f"{neg:,} negative (not measured)"] if neg else []
                why += [f"{oth:,} other"] if oth else []
                per.append(f"{name} {' + '.join(why) if why else 0}")
            line += "; channels masked inside the cut: " + ", ".join(per)
        return line


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
    - ``values``: (N, 3) linear RGB BRDF in 1/sr, without the cosine; signed where the
      source's negatives are measured values (:data:`NEGATIVE_POLICIES`).
    - ``weights``: (N,) solid-angle measure of each sample, sr^2.
    - ``valid``: (N,) True where the sample has at least one measured channel and both
      directions lie above the horizon. Invalid samples are kept (file order) but never
      fitted.
    - ``source``: where the samples came from (a path or a description).
    - ``channel_scales``: (3,) RGB scales applied to the raw numbers (MERL: 1/1500,
      1.15/1500, 1.66/1500; 1 for data already in 1/sr).
    - ``grid``: the MERL table shape when the samples are a full MERL table in file
      order, else ``None``.
    - ``channel_valid``: (N, 3) True where that channel of that sample is fitted; a
      channel is never valid in an invalid sample. ``None`` (the default) means every
      channel of a valid sample.
    - ``zenith_cut_deg``: the reader's zenith cut in degrees (samples beyond it were not
      evaluated: "outside the cut", not "not measured"), or ``None``.
    - ``stride``: the MERL sub-grid stride when the samples are a strided MERL grid in
      order (:func:`brdffit.io.merl_grid.merl_grid`), else ``None``.
    - ``synthetic``: True when the values are a model's own (:func:`brdffit.synthesize`),
      so a fit of that model has no model error; decides the default standard errors
      (``errors="auto"``, :mod:`brdffit.engine.uncertainty`). False for everything read
      or built from arrays.
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
    channel_valid: np.ndarray | None = None
    zenith_cut_deg: float | None = None
    stride: tuple[int, int, int] | None = None
    synthetic: bool = False

    def __post_init__(self) -> None:
        n = np.shape(self.wi)[0] if np.ndim(self.wi) == 2 else -1
        if self.channel_valid is None:
            object.__setattr__(
                self, "channel_valid", np.repeat(np.asarray(self.valid)[:, None], 3, axis=1)
            )
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
            "channel_valid": (n, 3),
        }
        for name, shape in expected.items():
            arr = np.asarray(getattr(self, name))
            if arr.shape != shape:
                raise MeasurementsError(
                    f"Measurements.{name} has shape {arr.shape}; expected {shape} "
                    f"(N = {n} samples from wi)"
                )
            dtype = bool if name in ("valid", "channel_valid") else np.float64
            object.__setattr__(self, name, readonly(arr.astype(dtype, copy=False)))
        channels = self.channel_valid & self.valid[:, None]
        valid = self.valid & channels.any(axis=1)
        if not (np.array_equal(channels, self.channel_valid) and np.array_equal(valid, self.valid)):
            object.__setattr__(self, "channel_valid", readonly(channels))
            object.__setattr__(self, "valid", readonly(valid))
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
        negative: str = "not_measured",
        source: str = "unknown",
        channel_scales: np.ndarray | None = None,
        grid: tuple[int, int, int] | None = None,
        zenith_cut_deg: float | None = None,
    ) -> Measurements:
        """Build from directions and values; angles are derived, invalid channels marked.

        ``weights`` defaults to equal weights summing to ``(2 pi)^2`` (samples spread
        uniformly over both hemispheres). A sample with a direction below the horizon, or
        ``valid`` False, is invalid. ``negative`` (:data:`NEGATIVE_POLICIES`) says what a
        negative channel means: ``"not_measured"`` masks that channel alone, ``"signed"``
        keeps it as a measured value. ``valid`` may be (N,) or (N, 3) (per channel).

        Raises :class:`MeasurementsError` on shapes that do not match, an unknown
        ``negative`` policy, or a non-finite value in a sample that ``valid`` does not
        already mark invalid (mark it invalid, or store a negative number under
        ``"not_measured"``, to say "not measured").
        """
        wi = np.asarray(wi, float)
        wo = np.asarray(wo, float)
        values = np.asarray(values, float)
        if wi.ndim != 2 or wi.shape[-1] != 3 or wo.shape != wi.shape:
            raise MeasurementsError(f"wi and wo must both be (N, 3); got {wi.shape} and {wo.shape}")
        if values.shape != wi.shape:
            raise MeasurementsError(f"values must be (N, 3) = {wi.shape}; got {values.shape}")
        if negative not in NEGATIVE_POLICIES:
            raise MeasurementsError(
                f"negative={negative!r}; accepted: {', '.join(map(repr, NEGATIVE_POLICIES))}"
            )
        n = wi.shape[0]
        theta_h, theta_d, phi_d, _ = io_to_halfdiff(wi, wo)
        channels = np.ones((n, 3), bool)
        if valid is not None:
            v = np.asarray(valid, bool)
            channels &= v if v.ndim == 2 else v[:, None]
        above = above_horizon(wi, wo)
        finite = np.isfinite(values)
        bad = ~finite & channels & above[:, None]
        if bad.any():
            row = int(np.flatnonzero(bad.any(axis=1))[0])
            raise MeasurementsError(
                f"{source}: {int(bad.sum()):,} non-finite values (NaN or inf) in samples not "
                f"marked invalid, the first in sample {row} ({values[row].tolist()}); mark "
                "them invalid with valid=, or store a negative number for not measured"
            )
        if negative == "not_measured":
            channels &= values >= 0.0
        if weights is None:
            weights = np.full(n, (2 * np.pi) ** 2 / max(n, 1))
        clean = np.where(finite, values, -1.0)
        return cls(
            wi=wi,
            wo=wo,
            theta_h=theta_h,
            theta_d=theta_d,
            phi_d=fold_phi_d(phi_d),
            values=clean,
            weights=np.asarray(weights, float),
            valid=above & channels.any(axis=1),
            source=source,
            channel_scales=np.ones(3) if channel_scales is None else channel_scales,
            grid=grid,
            channel_valid=channels,
            zenith_cut_deg=zenith_cut_deg,
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
        """A copy with some fields changed (the original is untouched).

        A new ``valid`` without a new ``channel_valid`` applies to every channel alike.
        """
        if "valid" in changes and "channel_valid" not in changes:
            changes["channel_valid"] = None
        return dataclasses.replace(self, **changes)

    def outside_cut(self) -> np.ndarray:
        """(N,) True where a direction lies beyond :attr:`zenith_cut_deg` (above the horizon)."""
        if self.zenith_cut_deg is None:
            return np.zeros(self.n, bool)
        c = np.cos(np.radians(self.zenith_cut_deg))
        return above_horizon(self.wi, self.wo) & ((self.wi[:, 2] < c) | (self.wo[:, 2] < c))

    def mask_counts(self) -> MaskCounts:
        """Why samples and channels are masked (:class:`MaskCounts`), from the fields alone."""
        below = ~above_horizon(self.wi, self.wo)
        outside = self.outside_cut() & ~below
        inside = ~below & ~outside
        none = inside & ~self.channel_valid.any(axis=1)
        masked = ~self.valid
        counts = [int(np.count_nonzero(masked & m)) for m in (below, outside, none)]
        lost = inside[:, None] & ~self.channel_valid
        negative = lost & (self.values < 0.0)
        return MaskCounts(
            self.n,
            *counts,
            int(np.count_nonzero(masked)) - sum(counts),
            channel_negative=tuple(int(k) for k in negative.sum(axis=0)),
            channel_other=tuple(int(k) for k in (lost & ~negative).sum(axis=0)),
            zenith_cut_deg=self.zenith_cut_deg,
        )

    def layout(self) -> str:
        """How the samples are laid out: the full MERL table, a strided MERL grid, or
        scattered directions."""
        if self.grid is not None:
            return f"full MERL table {self.grid[0]} x {self.grid[1]} x {self.grid[2]}"
        if self.stride is not None:
            s = self.stride
            return f"MERL grid at stride {s[0]} {s[1]} {s[2]}"
        return "scattered directions"

    def summary(self) -> str:
        """A few lines for ``brdffit info``: size, validity and why samples are masked,
        value range, provenance."""
        v = self.values
        lines = [
            f"source          {self.source}",
            f"samples         {self.n} ({self.n_valid} valid, {self.n - self.n_valid} masked)",
            f"masked          {self.mask_counts().text()}",
            f"layout          {self.layout()}",
            f"channel scales  {', '.join(f'{s:.6g}' for s in self.channel_scales)}",
        ]
        for c, name in enumerate("RGB"):
            x = v[self.channel_valid[:, c], c]
            if x.size:
                lo, med, hi = np.percentile(x, [0, 50, 100])
                neg = int(np.count_nonzero(x < 0))
                tail = f"  ({neg:,} negative values kept)" if neg else ""
                lines.append(
                    f"{name} (1/sr)        min {lo:.4g}  median {med:.4g}  max {hi:.4g}{tail}"
                )
        return "\n".join(lines)
