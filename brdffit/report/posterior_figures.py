"""The pictures of a posterior: corner plot, walker traces, intervals, predictive band.

Each takes a :class:`~brdffit.engine.posterior.Posterior` (and, where it compares, the
:class:`~brdffit.core.result.FitResult` the chains started from, and the
:class:`~brdffit.core.measurements.Measurements`) and returns a matplotlib
:class:`~matplotlib.figure.Figure` that is not registered with pyplot: nothing needs
closing, and in Jupyter the figure shows when it is a cell's value (or is passed to
``display``). Sizes are chosen to read on a laptop screen (8 to 9 inches wide).

- :func:`corner_figure`: the ``corner`` package's plot of the kept samples, with truths
  (blue lines) and the LM estimate (orange): its value, its 95% interval on the diagonal
  and its 95% ellipse on each pair (the Gaussian of the LM covariance, chi-square with 2
  degrees of freedom: 5.99).
- :func:`trace_figure`: the walkers per sampled scalar and the log posterior (their 5-95%
  band, their median and a few walkers' paths), the burn-in shaded, each row titled
  with its integrated autocorrelation time ``tau``, the kept steps in units of ``tau``
  and the effective sample size.
- :func:`interval_figure`: per parameter scalar, the posterior's central 95% interval
  beside the LM interval (value +/- 1.96 standard errors), in units of the LM standard
  error around the LM value, with the numbers written out.
- :func:`predictive_figure`: in-plane slices of the data (``phi_d`` = 0: light, normal and
  viewer in one plane) against ``theta_h`` at a few ``theta_d``: data dots, the LM fit,
  the posterior median, the 95% band of the model over posterior draws, and the 95%
  posterior predictive band (the model plus the sampled noise of each draw,
  :mod:`brdffit.engine.sample`), with the share of data points inside that band.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import corner
import jax
import jax.numpy as jnp
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

from brdffit import models
from brdffit.core.measurements import Measurements
from brdffit.core.result import FitResult
from brdffit.engine.posterior import Posterior
from brdffit.report.figures import mark_nonpositive
from brdffit.report.lookup import slice_indices

Z95 = 1.959963984540054
"""Two-sided 95% quantile of the standard normal."""
CHI2_2_95 = 5.991464547107979
"""95% quantile of chi-square with 2 degrees of freedom: the LM ellipse on a pair."""
TITLES_UP_TO = 6
"""Most scalars whose corner panels carry a title (median and interval) at 8 inches."""
LM_COLOUR = "C1"
POST_COLOUR = "C0"
TRUTH_COLOUR = "#4682b4"  # corner's own truth colour


def _flat_truths(truths: Mapping[str, object] | None) -> dict[str, float]:
    """``{"kd": [r, g, b], "alpha": a}`` -> ``{"kd[r]": r, ..., "alpha": a}``."""
    out: dict[str, float] = {}
    for name, v in (truths or {}).items():
        v = np.atleast_1d(np.asarray(v, float))
        keys = [name] if v.size == 1 else [f"{name}[{c}]" for c in "rgb"]
        out.update(zip(keys, (float(x) for x in v), strict=True))
    return out


def _lm(fit: FitResult | None, label: str) -> tuple[float, float] | None:
    """(value, standard error) of ``label`` in ``fit``; the error NaN when it has none."""
    if fit is None or label.startswith("log_sigma"):
        return None
    name, _, ch = label.partition("[")
    if name not in fit.params:
        return None
    c = "rgb".index(ch[0]) if ch else 0
    v = float(np.atleast_1d(fit.params[name])[c])
    se = np.nan if fit.stderr is None else float(np.atleast_1d(fit.stderr[name])[c])
    return v, se if np.isfinite(se) and se > 0 else np.nan


def _corner_range(x: np.ndarray, lm: tuple[float, float] | None) -> tuple[float, float]:
    """Axis range: the samples' 0.1-99.9% quantiles and the LM 95% interval, padded 5%."""
    lo, hi = np.quantile(x, [0.001, 0.999])
    if lm is not None and np.isfinite(lm[1]):
        lo, hi = min(lo, lm[0] - 1.1 * Z95 * lm[1]), max(hi, lm[0] + 1.1 * Z95 * lm[1])
    pad = 0.05 * (hi - lo) if hi > lo else 1e-6 * max(1.0, abs(lo))
    return float(lo - pad), float(hi + pad)


def corner_figure(
    post: Posterior,
    *,
    fit: FitResult | None = None,
    truths: Mapping[str, object] | None = None,
    labels: Sequence[str] | None = None,
    size: float = 8.0,
) -> Figure:
    """Corner plot of the kept samples of ``labels`` (default: every sampled scalar).

    ``truths`` maps parameter names to values (RGB arrays expand to channels), drawn as
    blue lines; ``fit`` (the LM result) adds its value, its 95% interval on the diagonal
    and its 95% ellipse on each pair, in orange. Up to :data:`TITLES_UP_TO` scalars, the
    titles give each one's median and 95% interval (beyond, they would overlap:
    :func:`interval_figure` writes them out). ``size``: the figure's side in inches.
    """
    labels = list(post.labels if labels is None else labels)
    ix = [post.labels.index(lab) for lab in labels]
    x = post.samples()[:, ix]
    lm = [_lm(fit, lab) for lab in labels]
    flat = _flat_truths(truths)
    fig = Figure(figsize=(size, size))
    corner.corner(
        x, fig=fig, labels=labels, truths=[flat.get(lab) for lab in labels],
        range=[_corner_range(x[:, i], lm[i]) for i in range(len(labels))],
        quantiles=[0.025, 0.5, 0.975], show_titles=len(labels) <= TITLES_UP_TO, title_fmt=".4g",
        title_kwargs={"fontsize": 8}, label_kwargs={"fontsize": 9}, max_n_ticks=3,
        plot_datapoints=False, truth_color=TRUTH_COLOUR,
    )  # fmt: skip
    axes = np.asarray(fig.axes).reshape(len(labels), len(labels))
    for ax in axes.ravel():
        ax.tick_params(labelsize=7)
    if fit is not None:
        _mark_lm(axes, fit, labels, lm)
    keys = ["blue: truth"] if truths else []
    keys += ["orange: LM value, 95% interval and ellipse"] if fit is not None else []
    keys += ["dashed: posterior 2.5, 50, 97.5%"]
    fig.text(0.98, 0.98, "\n".join(keys), ha="right", va="top", fontsize=9)
    return fig


def _mark_lm(axes: np.ndarray, fit: FitResult, labels: list[str], lm: list) -> None:
    """The LM value and interval on the diagonal, its point and ellipse on the pairs."""
    where = {lab: fit.labels.index(lab) for lab in labels if lab in fit.labels}
    for i, li in enumerate(lm):
        if li is None:
            continue
        ax = axes[i, i]
        ax.axvline(li[0], color=LM_COLOUR, lw=1.2)
        if np.isfinite(li[1]):
            ax.axvspan(li[0] - Z95 * li[1], li[0] + Z95 * li[1], color=LM_COLOUR, alpha=0.2)
        for j in range(i):
            lj = lm[j]
            if lj is None:
                continue
            ax = axes[i, j]
            ax.plot(lj[0], li[0], "s", color=LM_COLOUR, ms=3)
            if fit.covariance is not None and labels[i] in where and labels[j] in where:
                a, b = where[labels[j]], where[labels[i]]
                cov = fit.covariance[np.ix_([a, b], [a, b])]
                _ellipse(ax, (lj[0], li[0]), cov)


def _ellipse(ax, centre: tuple[float, float], cov: np.ndarray) -> None:
    """The 95% ellipse of a 2-D Gaussian of covariance ``cov`` (x, y) around ``centre``."""
    w, v = np.linalg.eigh(cov)
    if not np.all(np.isfinite(w)) or w[0] <= 0:
        return
    angle = np.degrees(np.arctan2(v[1, 1], v[0, 1]))
    width, height = 2 * np.sqrt(CHI2_2_95 * w[1]), 2 * np.sqrt(CHI2_2_95 * w[0])
    ax.add_patch(Ellipse(centre, width, height, angle=angle, fill=False, color=LM_COLOUR, lw=1.2))


def trace_figure(post: Posterior, *, n_walkers_drawn: int = 3, width: float = 9.0) -> Figure:
    """Walker traces: one row per sampled scalar and one for the log posterior.

    Per step, the band holding 90% of the walkers (5-95%) and their median, and the paths
    of ``n_walkers_drawn`` walkers (evenly chosen: a stuck one shows as a flat line beside
    the band; drawing every walker hides the band and makes large pictures). The burn-in is shaded;
    each row's title gives ``tau`` (steps), the kept steps over ``tau`` and the
    effective sample size, and says when the chain is shorter than 50 ``tau`` (the
    length emcee's authors advise before trusting ``tau``).
    """
    n_steps, n_walkers, dim = post.chain.shape
    walkers = np.unique(np.linspace(0, n_walkers - 1, min(n_walkers_drawn, n_walkers)).astype(int))
    rows = dim + 1
    fig = Figure(figsize=(width, 0.8 * rows + 0.7), layout="constrained")
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    steps = np.arange(n_steps)
    kept = n_steps - post.burn
    for i, ax in enumerate(axes):
        y = post.log_prob if i == dim else post.chain[:, :, i]
        lo, med, hi = np.quantile(y, [0.05, 0.5, 0.95], axis=1)
        ax.fill_between(steps, lo, hi, color=POST_COLOUR, alpha=0.3, lw=0)
        ax.plot(steps, med, color=POST_COLOUR, lw=1.0)
        ax.plot(steps, y[:, walkers], color="k", alpha=0.6, lw=0.5)
        ax.axvspan(0, post.burn, color="0.85", zorder=0)
        if i == dim:
            ax.set_ylabel("log post.", fontsize=8)
            lo = np.quantile(post.log_prob[post.burn :], 0.01)
            ax.set_ylim(lo - 0.5 * (post.log_prob.max() - lo), None)
            continue
        ax.set_ylabel(post.labels[i], fontsize=8)
        tau = post.autocorr_time[i]
        short = "  (shorter than 50 tau)" if kept < 50 * tau else ""
        ax.set_title(
            f"tau = {tau:.1f} steps, kept {kept / max(tau, 1.0):.0f} tau, "
            f"ESS {post.ess[i]:.0f}{short}",
            fontsize=8, loc="right", color="C3" if short else "k",
        )  # fmt: skip
    for ax in axes:
        ax.tick_params(labelsize=7)
    axes[0].text(post.burn / 2, 0.5, "burn-in", transform=axes[0].get_xaxis_transform(),
                 ha="center", va="center", fontsize=8, color="0.4")  # fmt: skip
    axes[-1].set_xlabel("step")
    fig.suptitle(
        f"{post.model}: {n_walkers} walkers (band: 5-95%, line: median; {len(walkers)} drawn in "
        f"black), burn-in {post.burn} of "
        f"{n_steps} steps, acceptance {np.mean(post.acceptance_fraction):.2f}",
        fontsize=10,
    )
    return fig


def interval_figure(
    post: Posterior,
    fit: FitResult,
    *,
    truths: Mapping[str, object] | None = None,
    width: float = 9.0,
) -> Figure:
    """Each parameter scalar's posterior 95% interval beside its LM interval.

    The x axis is ``(value - LM value) / LM standard error``, so the LM interval is
    [-1.96, 1.96] on every row and the posterior shows as shifted, wider or narrower;
    the numbers themselves are written beside each row. A scalar without an LM error is
    drawn in units of its posterior half-width instead (said on the row).
    """
    labels = [lab for lab in post.labels if _lm(fit, lab) is not None]
    q = post.quantiles()
    flat = _flat_truths(truths)
    fig = Figure(figsize=(width, 0.42 * len(labels) + 1.3), layout="constrained")
    ax = fig.subplots()
    for k, lab in enumerate(labels):
        y = len(labels) - 1 - k
        v, se = _lm(fit, lab)
        lo, med, hi = q[lab]
        scale = se if np.isfinite(se) else max((hi - lo) / (2 * Z95), 1e-300)
        if np.isfinite(se):
            ax.plot([-Z95, Z95], [y + 0.12] * 2, color=LM_COLOUR, lw=4, solid_capstyle="butt")
            ax.plot(0, y + 0.12, "o", color=LM_COLOUR, ms=4)
        ax.plot([(lo - v) / scale, (hi - v) / scale], [y - 0.12] * 2, color=POST_COLOUR,
                lw=4, solid_capstyle="butt")  # fmt: skip
        ax.plot((med - v) / scale, y - 0.12, "o", color=POST_COLOUR, ms=4)
        if lab in flat:
            ax.plot((flat[lab] - v) / scale, y, "x", color="k", ms=7, mew=1.5)
        lm_text = f"{v:.4g} ± {Z95 * se:.2g}" if np.isfinite(se) else f"{v:.4g} (no LM error)"
        ratio = f"  width x{(hi - lo) / (2 * Z95 * se):.2f}" if np.isfinite(se) else ""
        ax.text(1.02, y, f"LM {lm_text} | post. {med:.4g} [{lo:.4g}, {hi:.4g}]{ratio}",
                transform=ax.get_yaxis_transform(), va="center", fontsize=8)  # fmt: skip
    ax.set_yticks(range(len(labels)), labels[::-1], fontsize=8)
    ax.axvline(0, color="0.7", lw=0.8, zorder=0)
    ax.set_xlabel("(value - LM value) / LM standard error", fontsize=9)
    ax.tick_params(labelsize=8)
    ax.set_ylim(-0.7, len(labels) - 0.3)
    fig.suptitle(
        "95% intervals: LM (orange, value ± 1.96 standard errors) and posterior (blue, "
        "2.5-97.5%)" + ("; x: truth" if flat else ""),
        fontsize=9,
    )
    return fig


def predictive_figure(
    post: Posterior,
    data: Measurements,
    fit: FitResult | None = None,
    *,
    theta_d_deg: Sequence[float] = (5.0, 30.0, 60.0),
    channel: int = 1,
    n_draws: int = 200,
    seed: int = 0,
    width: float = 9.0,
) -> Figure:
    """Posterior predictive band on the in-plane slices (``phi_d`` = 0) of ``data``.

    Per slice (the measured ``(theta_d, phi_d)`` line nearest each of ``theta_d_deg`` and
    ``phi_d`` = 0): the data (dots), the LM ``fit`` (orange, when given), the posterior
    median (blue line), the 95% band of the model over ``n_draws`` posterior draws
    (dark) and the 95% posterior predictive band (light: each draw's model with its
    sampled noise, :func:`predictive_draws`); the title gives the share of the slice's
    data inside the predictive band. Top row: ``f cos(theta_i)`` of ``channel`` on a log
    axis; bottom row: everything over the posterior median, where a few percent show.
    """
    rng = np.random.default_rng(seed)
    s = post.samples()
    draws = s[rng.choice(len(s), size=min(n_draws, len(s)), replace=False)]
    lines = [slice_indices(data, t, 0.0) for t in theta_d_deg]
    every = np.concatenate([idx for idx, _, _ in lines])
    f_all, noisy_all = predictive_draws(post, draws, data.wi[every], data.wo[every], rng)
    lm_all = None
    if fit is not None:
        p = {k: jnp.asarray(v) for k, v in fit.params.items()}
        lm_all = np.asarray(models.model_of(fit).eval(p, data.wi[every], data.wo[every]))
    fig = Figure(figsize=(width, 4.6), layout="constrained")
    axes = fig.subplots(2, len(lines), sharex="col", squeeze=False, height_ratios=(2, 1))
    start = 0
    for k, (idx, near_td, near_pd) in enumerate(lines):
        part = slice(start, start + idx.size)
        start += idx.size
        curves = {
            "th": np.rad2deg(data.theta_h[idx]),
            "y": data.values[idx, channel],
            "f": f_all[:, part, channel],
            "noisy": None if noisy_all is None else noisy_all[:, part, channel],
            "lm": None if lm_all is None else lm_all[part, channel],
        }
        share = _slice_panels(axes[0, k], axes[1, k], curves, data.wi[idx, 2])
        title = f"theta_d = {near_td:.1f} deg, phi_d = {near_pd:.1f} deg"
        if share is not None:
            title += f"\n{100 * share:.0f}% of {idx.size} points in the predictive band"
        axes[0, k].set_title(title, fontsize=8)
        axes[1, k].set_xlabel("theta_h (deg)", fontsize=9)
    axes[0, 0].set_ylabel(f"f cos theta_i, {'RGB'[channel]} (1/sr)", fontsize=9)
    axes[1, 0].set_ylabel("/ posterior median", fontsize=9)
    axes[0, -1].legend(fontsize=7)
    how = " (noise 'constant' lives on the metric's residuals: no predictive band)"
    fig.suptitle(
        f"{post.model}: posterior predictive on in-plane slices, {len(draws)} draws, noise "
        f"{post.noise}{how if post.noise == 'constant' else ''}",
        fontsize=10,
    )
    return fig


def _slice_panels(top, ratio, c: dict, cos_i: np.ndarray) -> float | None:
    """One slice: values (``top``, log axis) and the same over the posterior median
    (``ratio``). ``c`` holds theta_h ``th``, data ``y``, model draws ``f``, noisy draws
    ``noisy`` (or None) and the LM values ``lm`` (or None), one channel. Returns the
    share of the data inside the predictive band (None without one)."""
    th, y = c["th"], c["y"]
    band = np.quantile(c["f"], [0.025, 0.5, 0.975], axis=0)
    med = band[1]
    share = None
    for ax, scale in ((top, cos_i), (ratio, 1.0 / med)):
        ax.fill_between(th, band[0] * scale, band[2] * scale, color=POST_COLOUR, alpha=0.45,
                        lw=0, label="model, 95%")  # fmt: skip
        if c["noisy"] is not None:
            pb = np.quantile(c["noisy"], [0.025, 0.975], axis=0)
            ax.fill_between(th, pb[0] * scale, pb[1] * scale, color=POST_COLOUR, alpha=0.18,
                            lw=0, label="predictive, 95%")  # fmt: skip
            share = float(np.mean((y >= pb[0]) & (y <= pb[1])))
        ax.plot(th, med * scale, color=POST_COLOUR, lw=1.2, label="posterior median")
        if c["lm"] is not None:
            ax.plot(th, c["lm"] * scale, "--", color=LM_COLOUR, lw=1.2, label="LM fit")
        ax.plot(th, y * scale, ".", color="k", ms=3, label="data")
        ax.tick_params(labelsize=7)
    top.set_yscale("log")
    mark_nonpositive(top, [th[y <= 0]])
    return share


def predictive_draws(
    post: Posterior,
    draws: np.ndarray,
    wi: np.ndarray,
    wo: np.ndarray,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray | None]:
    """The model (draws, n, 3) at each posterior draw, and the same with that draw's noise.

    The noise is the likelihood's (:mod:`brdffit.engine.sample`) read on the data:
    ``multiplicative`` ``f exp(sigma e)``, ``additive`` ``f + sigma e``, ``mixed``
    ``f + sqrt(sigma_add^2 + (sigma_mult f)^2) e``, ``e`` standard normal. ``constant``
    noise lives on the metric's residuals, not on the data: None then.
    """
    params = {k: jnp.asarray(v) for k, v in post.parameter_sets(draws).items()}
    model = models.get(post.model, **dict(post.options))
    wi, wo = jnp.asarray(wi), jnp.asarray(wo)
    f = np.asarray(jax.vmap(lambda p: model.eval(p, wi, wo))(params))
    if post.noise == "constant":
        return f, None
    sig = {lab: np.exp(draws[:, i]) for i, lab in enumerate(post.labels) if "sigma" in lab}
    e = rng.standard_normal(f.shape)
    if post.noise == "multiplicative":
        return f, f * np.exp(sig["log_sigma"][:, None, None] * e)
    if post.noise == "additive":
        return f, f + sig["log_sigma"][:, None, None] * e
    sa, sm = sig["log_sigma_add"][:, None, None], sig["log_sigma_mult"][:, None, None]
    return f, f + np.sqrt(sa**2 + (sm * f) ** 2) * e
