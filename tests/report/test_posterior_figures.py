"""The posterior's pictures: what each draws is what the posterior and the LM fit hold.

One short emcee run of Walter/GGX (alpha free, kd and f0 held fixed) on synthetic
log-normal data serves every test; the predictive band is checked against the data the
likelihood was written for (its coverage), the corner marks against the LM covariance
(the ellipse's boundary lies at the chi-square quantile), the traces and intervals
against the posterior's own numbers.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

from brdffit import fit, models, sample, synthesize
from brdffit.engine import metrics
from brdffit.engine.posterior import ChainTooShortWarning
from brdffit.report import corner_figure, interval_figure, predictive_figure, trace_figure
from brdffit.report.posterior_figures import CHI2_2_95, Z95, predictive_draws

TRUTH = {"kd": [0.2, 0.35, 0.5], "f0": [0.05, 0.05, 0.05], "alpha": 0.2}
SIGMA = 0.05


@pytest.fixture(scope="module")
def run():
    """Data, LM fit (kd and alpha free) and a posterior with f0 held fixed."""
    m = models.get("walter", specular_weight=False)
    data = synthesize(m, TRUTH, stride=(9, 9, 9), noise_mult=SIGMA, seed=3)
    r = fit(m, data, "low_e2", n_restarts=0, freeze={"f0": TRUTH["f0"]})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ChainTooShortWarning)
        post = sample(m, data, init=r, freeze={"f0": TRUTH["f0"]}, noise="multiplicative",
                      n_steps=400, burn=150, n_walkers=16, progress=False, seed=1)  # fmt: skip
    return data, r, post


def _data_x(patch) -> np.ndarray:
    """The data x of a span's corners (a Rectangle in matplotlib >= 3.9, else a Polygon)."""
    if hasattr(patch, "get_width"):
        return np.array([patch.get_x(), patch.get_x() + patch.get_width()])
    return patch.get_xy()[:, 0]


def test_parameter_sets_name_every_parameter_with_the_fixed_ones(run):
    _, _, post = run
    s = post.samples()[:5]
    sets = post.parameter_sets(s)
    assert set(sets) == {"kd", "f0", "alpha"}
    assert sets["kd"].shape == (5, 3) and sets["alpha"].shape == (5,)
    np.testing.assert_array_equal(sets["kd"][:, 1], s[:, post.labels.index("kd[g]")])
    np.testing.assert_array_equal(sets["f0"], np.tile(TRUTH["f0"], (5, 1)))


@pytest.fixture(scope="module")
def predicted(run):
    """300 posterior draws, the model at each on the samples the likelihood used (angle
    cut 80 degrees), and the same with each draw's noise."""
    data, _, post = run
    keep = metrics.keep_mask(data, 80.0)
    rng = np.random.default_rng(0)
    draws = post.samples()[rng.choice(len(post.samples()), 300, replace=False)]
    f, noisy = predictive_draws(post, draws, data.wi[keep], data.wo[keep], rng)
    return keep, draws, f, noisy


def test_predictive_draws_are_the_model_at_each_draw(run, predicted):
    data, _, post = run
    keep, draws, f, noisy = predicted
    m = models.get("walter", specular_weight=False)
    for k, row in enumerate(draws[:3]):
        params = {
            "kd": [row[post.labels.index(f"kd[{c}]")] for c in "rgb"],
            "f0": TRUTH["f0"],
            "alpha": row[post.labels.index("alpha")],
        }
        want = m.eval(params, data.wi[keep][:50], data.wo[keep][:50])
        np.testing.assert_allclose(f[k, :50], want, rtol=1e-12)
    # multiplicative noise: log(noisy / f) is the draw's sigma times a standard normal
    sig = np.exp(draws[:, post.labels.index("log_sigma")])
    z = np.log(noisy / f) / sig[:, None, None]
    assert abs(np.std(z) - 1.0) < 0.02 and abs(np.mean(z)) < 0.02


def test_the_predictive_band_covers_95_percent_of_data_with_the_likelihoods_noise(run, predicted):
    """The data were made with the noise the likelihood assumes (5% log-normal), so the
    95% predictive band holds about 95% of them (3 x 1,252 values: +/- 0.4% at 1 sigma,
    wider for the correlation of the channels and the posterior's own spread)."""
    data, _, _ = run
    keep, _, _, noisy = predicted
    lo, hi = np.quantile(noisy, [0.025, 0.975], axis=0)
    y = data.values[keep]
    inside = np.mean((y >= lo) & (y <= hi))
    assert 0.92 < inside < 0.98, inside


def test_predictive_figure_draws_data_fit_and_bands_on_in_plane_slices(run):
    data, r, post = run
    fig = predictive_figure(post, data, r)
    assert isinstance(fig, Figure) and len(fig.axes) == 6  # values above, ratios below
    in_plane = np.rad2deg(data.phi_d[data.valid]).min()  # the measured line nearest phi_d = 0
    for k, ax in enumerate(fig.axes):
        assert len(ax.collections) == 2  # the model's band and the predictive band
        labels = [ln.get_label() for ln in ax.get_lines()]
        assert labels == ["posterior median", "LM fit", "data"]
        if k < 3:
            assert f"phi_d = {in_plane:.1f} deg" in ax.get_title()
            share = int(ax.get_title().split("\n")[1].split("%")[0])
            assert 70 <= share <= 100
        else:  # over the posterior median: the median line is 1
            np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), 1.0)


def test_corner_marks_the_lm_value_interval_and_ellipse(run):
    _, r, post = run
    fig = corner_figure(post, fit=r, truths=TRUTH)
    dim = len(post.labels)
    axes = np.asarray(fig.axes).reshape(dim, dim)
    i = post.labels.index("alpha")
    v, se = float(r.params["alpha"]), float(r.stderr["alpha"])
    span = [p for p in axes[i, i].patches if p.get_alpha() == 0.2]
    assert len(span) == 1
    x = _data_x(span[0])
    np.testing.assert_allclose([x.min(), x.max()], [v - Z95 * se, v + Z95 * se], rtol=1e-9)
    assert any(np.allclose(ln.get_xdata(), TRUTH["alpha"]) for ln in axes[i, i].get_lines())
    # the ellipse of (kd[g], alpha): its boundary is where the LM Gaussian's squared
    # Mahalanobis distance is the 95% quantile of chi-square with 2 degrees of freedom
    j = post.labels.index("kd[g]")
    assert j < i
    (ell,) = [p for p in axes[i, j].patches if isinstance(p, Ellipse)]
    t = np.linspace(0, 2 * np.pi, 50)
    pts = ell.get_patch_transform().transform(np.stack([np.cos(t), np.sin(t)], -1))  # unit circle
    a, b = r.labels.index("kd[g]"), r.labels.index("alpha")
    cov = r.covariance[np.ix_([a, b], [a, b])]
    d = pts - [float(r.params["kd"][1]), v]
    m2 = np.einsum("ni,ij,nj->n", d, np.linalg.inv(cov), d)
    np.testing.assert_allclose(m2, CHI2_2_95, rtol=1e-6)
    # the noise scale has no LM value: nothing orange on its row
    k = post.labels.index("log_sigma")
    assert not [p for p in axes[k, k].patches if p.get_alpha() == 0.2]


def test_trace_rows_give_tau_burn_in_and_ess(run):
    _, _, post = run
    fig = trace_figure(post)
    assert len(fig.axes) == len(post.labels) + 1
    for ax, tau, ess in zip(fig.axes, post.autocorr_time, post.ess, strict=False):
        title = ax.get_title(loc="right")
        assert f"tau = {tau:.1f} steps" in title and f"ESS {ess:.0f}" in title
        assert "shorter than 50 tau" in title  # 250 kept steps: short on purpose
        x = _data_x(ax.patches[0])
        assert x.min() == pytest.approx(0) and x.max() == pytest.approx(post.burn)
    assert fig.axes[-1].get_ylabel() == "log post."


def test_interval_rows_put_lm_at_plus_minus_1_96_and_the_posterior_in_lm_units(run):
    _, r, post = run
    fig = interval_figure(post, r, truths=TRUTH)
    (ax,) = fig.axes
    labels = [t.get_text() for t in ax.get_yticklabels()][::-1]
    assert labels == list(r.labels)  # the free parameter scalars, in order; no log_sigma
    q = post.quantiles()
    lines = ax.get_lines()
    for lab in labels:
        name, _, ch = lab.partition("[")
        c = "rgb".index(ch[0]) if ch else 0
        v = float(np.atleast_1d(r.params[name])[c])
        se = float(np.atleast_1d(r.stderr[name])[c])
        want = sorted([(q[lab][0] - v) / se, (q[lab][2] - v) / se])
        assert any(np.allclose(ln.get_xdata(), want) for ln in lines), lab
    assert sum(np.allclose(ln.get_xdata(), [-Z95, Z95]) for ln in lines) == len(labels)
    text = " ".join(t.get_text() for t in ax.texts)
    assert f"LM {float(r.params['alpha']):.4g}" in text
