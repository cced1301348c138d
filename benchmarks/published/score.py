"""The published metrics, computed here from BRDF values alone, for scoring two fits alike.

Both fits of a comparison (brdffit's, evaluated by its model; the published one,
evaluated by bbm's C++) are scored by these few lines of NumPy on the same cells, so
neither side's own loss code decides the comparison. The definitions are those of
brdffit's metric table (``brdffit.engine.metrics``), written again from the papers:

* ``ngan`` (Ngan et al. 2005): ``sqrt(3 sum w (fm ci - fd ci)^2 / sum w)`` over the
  channels fitted, ``w`` the cell's solid-angle weight (each channel's weighted mean
  square, summed over the three channels);
* ``low_e1`` (Löw et al. 2012, E1): ``sum ((fm - fd) ci)^2 sin(theta_i)``;
* ``low_e2`` (E2): ``sum (ln(1 + fm ci) - ln(1 + fd ci))^2 sin(theta_i)``.

Cells: valid, both zenith angles below 80 degrees (Ngan's cut, brdffit's default). A
channel is left out where the data do not measure it and, for E2, where ``fd ci <=
-0.999`` (outside the log's domain; NBRDF data never reach it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CUT_DEG = 80.0
LOG_FLOOR = -0.999


@dataclass(frozen=True)
class Cells:
    """The cells a comparison scores: cosines, weights, data values and channel mask."""

    cos_i: np.ndarray  # (N,)
    sin_i: np.ndarray  # (N,)
    weight: np.ndarray  # (N,) solid angle, sr^2
    values: np.ndarray  # (N, 3) measured f, 1/sr
    use: np.ndarray  # (N, 3) bool
    index: np.ndarray  # (N,) indices into the measurements


def cells(data) -> Cells:
    """The scored cells of a :class:`brdffit.Measurements`."""
    c = np.cos(np.deg2rad(CUT_DEG))
    keep = np.flatnonzero(data.valid & (data.wi[:, 2] > c) & (data.wo[:, 2] > c))
    cos_i = data.wi[keep, 2]
    use = data.channel_valid[keep] if data.channel_valid is not None else np.ones((keep.size, 3))
    return Cells(
        cos_i=cos_i,
        sin_i=np.sqrt(np.clip(1.0 - cos_i**2, 0.0, None)),
        weight=data.weights[keep],
        values=data.values[keep],
        use=np.asarray(use, bool),
        index=keep,
    )


def loss(metric: str, f_model: np.ndarray, at: Cells) -> float:
    """The loss of ``metric`` for model values ``f_model`` ((N, 3) at ``at``, 1/sr)."""
    fm = np.asarray(f_model, float) * at.cos_i[:, None]
    fd = at.values * at.cos_i[:, None]
    if metric == "ngan":
        w = at.weight[:, None] * at.use
        return float(np.sqrt(3.0 * np.sum(w * (fm - fd) ** 2) / np.sum(w)))
    if metric == "low_e1":
        return float(np.sum(at.sin_i[:, None] * at.use * (fm - fd) ** 2))
    if metric == "low_e2":
        use = at.use & (fd > LOG_FLOOR)
        e = np.log1p(np.maximum(fm, LOG_FLOOR)) - np.log1p(np.maximum(fd, LOG_FLOOR))
        return float(np.sum(at.sin_i[:, None] * use * e**2))
    raise ValueError(f"unknown metric {metric!r}; known: ngan, low_e1, low_e2")


METRICS = ("ngan", "low_e1", "low_e2")
