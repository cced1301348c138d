"""Figures from results: data against fitted models, posterior corner plots.

Each function takes measurements and results (never solvers) and returns a
matplotlib figure; saving is the caller's business (:func:`brdffit.util.atomic.save_figure`).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from brdffit import models
from brdffit.core.measurements import Measurements
from brdffit.core.result import FitResult


def plot_slices(
    data: Measurements,
    results: Sequence[FitResult],
    *,
    theta_d_deg: Sequence[float] = (5.0, 30.0, 60.0),
    phi_d_deg: float = 90.0,
    channel: int = 1,
):
    """``f cos(theta_i)`` against ``theta_h`` at a few ``theta_d``, data dots and model lines.

    The samples nearest to each (theta_d, phi_d) slice are taken from ``data`` (valid
    samples only); the y axis is logarithmic.
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(
        1, len(theta_d_deg), figsize=(4.2 * len(theta_d_deg), 3.6), sharey=True, squeeze=False
    )
    td = np.rad2deg(data.theta_d)
    pd = np.rad2deg(data.phi_d)
    for ax, t in zip(axes[0], theta_d_deg, strict=True):
        near_td = td[data.valid][np.argmin(np.abs(td[data.valid] - t))]
        near_pd = pd[data.valid][np.argmin(np.abs(pd[data.valid] - phi_d_deg))]
        sel = data.valid & np.isclose(td, near_td) & np.isclose(pd, near_pd)
        idx = np.flatnonzero(sel)
        idx = idx[np.argsort(data.theta_h[idx])]
        th = np.rad2deg(data.theta_h[idx])
        cos_i = data.wi[idx, 2]
        ax.semilogy(th, data.values[idx, channel] * cos_i, ".", color="k", ms=3, label="data")
        for r in results:
            m = models.model_of(r)
            f = np.asarray(
                m.eval({k: jnp.asarray(v) for k, v in r.params.items()}, data.wi[idx], data.wo[idx])
            )
            ax.semilogy(
                th, np.maximum(f[:, channel] * cos_i, 1e-8), label=f"{r.model} ({r.loss:.3g})"
            )
        ax.set_title(f"theta_d = {near_td:.1f} deg, phi_d = {near_pd:.0f} deg")
        ax.set_xlabel("theta_h (deg)")
    axes[0][0].set_ylabel(f"f cos theta_i, channel {'RGB'[channel]} (1/sr)")
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    return fig
