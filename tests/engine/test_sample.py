"""emcee posteriors: coverage of the truth over seeds, diagnostics, warnings, plots."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from brdffit import ChainTooShortError, ParameterError, fit, models, sample, synthesize
from brdffit.engine.posterior import ChainTooShortWarning, PosteriorAtBoundWarning

TRUTH = {"kd": [0.1, 0.2, 0.3], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}


def _flat_truth(labels):
    flat = {}
    for k, v in TRUTH.items():
        v = np.atleast_1d(v)
        flat.update(
            {k: v[0]} if v.size == 1 else {f"{k}[{c}]": x for c, x in zip("rgb", v, strict=True)}
        )
    return np.array([flat[lab] for lab in labels if lab != "log_sigma"])


def _run(seed: int, n_steps: int = 900):
    # Walter's paper form (no specular weight): the 28 scalars the binomial bound counts
    m = models.get("walter", specular_weight=False)
    # The same MERL sub-grid for every seed (only the noise changes): one compile.
    data = synthesize(m, TRUTH, stride=(9, 9, 9), noise_mult=0.05, seed=seed)
    r = fit(m, data, "low_e2", n_restarts=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ChainTooShortWarning)
        return sample(
            m,
            data,
            init=r,
            noise="multiplicative",
            n_steps=n_steps,
            burn=300,
            seed=seed,
            progress=False,
        )


@pytest.mark.slow  # 27-30 s: many seeded chains; test_mixed_noise_* keep the sampler fast
def test_95_percent_intervals_cover_the_truth_in_most_seeds():
    hits, total = 0, 0
    for seed in range(4):
        post = _run(seed)
        q = post.quantiles()
        lo = np.array([q[lab][0] for lab in post.labels[:-1]])
        hi = np.array([q[lab][2] for lab in post.labels[:-1]])
        t = _flat_truth(post.labels)
        covered = (lo <= t) & (t <= hi)
        print(
            f"seed {seed}: {covered.sum()}/{covered.size} covered; "
            f"sigma {np.exp(q['log_sigma'][1]):.4f} (true 0.05)"
        )
        hits += int(covered.sum())
        total += covered.size
        # The noise scale itself is recovered: 5% log-normal noise.
        assert abs(np.exp(q["log_sigma"][1]) - 0.05) < 0.005
    # Nominal 95%: 26.6 of 28 expected; fewer than 22 has probability < 1e-3 for
    # independent intervals (binomial), even allowing for short-chain quantile noise.
    assert hits >= 22, (hits, total)


def test_diagnostics_shapes_and_short_chain_warning():
    m = models.get("lambert")
    data = synthesize(m, {"kd": [0.2, 0.4, 0.6]}, grid="random", n=500, noise_mult=0.05)
    with pytest.warns(ChainTooShortWarning, match="autocorrelation"):
        post = sample(
            m,
            data,
            n_steps=60,
            n_walkers=16,
            progress=False,
            init={"kd": [0.2, 0.4, 0.6]},
            noise="multiplicative",
        )
    assert post.chain.shape == (60, 16, 4) and post.log_prob.shape == (60, 16)
    assert post.labels == ("kd[r]", "kd[g]", "kd[b]", "log_sigma")
    assert post.acceptance_fraction.shape == (16,) and np.all(post.ess > 0)
    assert post.split_rhat().shape == (4,)
    assert post.warnings and "Posterior" in post.summary()
    with pytest.raises(ChainTooShortError) as err:
        post.require_converged()
    assert err.value.estimate.shape == (4,)
    # Natural units inside the bounds, whatever the walkers did in unconstrained space.
    assert np.all((post.chain[..., :3] > 0) & (post.chain[..., :3] < 1))


def _lambert_posterior(kd: list[float], init: list[float], seed: int = 0):
    """Short lambert posterior on 500 random directions with 5% log-normal noise."""
    m = models.get("lambert")
    data = synthesize(m, {"kd": kd}, grid="random", n=500, noise_mult=0.05, seed=seed)
    return sample(
        m,
        data,
        n_steps=600,
        n_walkers=16,
        progress=False,
        init={"kd": init},
        noise="multiplicative",
        seed=seed,
    )


@pytest.mark.parametrize(
    ("red", "start", "bound"),
    [(1.0, 0.99, 1.0), (0.0, 1e-4, 0.0)],
    ids=["upper", "lower"],
)
def test_at_bound_warning_names_the_scalar_and_bound(red, start, bound):
    # The red albedo's truth sits on a bound: its posterior is truncated there.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ChainTooShortWarning)
        with pytest.warns(PosteriorAtBoundWarning, match=rf"kd\[r\] at {bound:g}\b"):
            post = _lambert_posterior([red, 0.4, 0.6], [start, 0.4, 0.6])
    assert post.at_bound == (("kd[r]", bound),)
    assert post.to_dict()["at_bound"] == [["kd[r]", bound]]
    assert f"at bound {bound:g}" in post.summary()
    assert any("piled against a bound" in w for w in post.warnings)


def test_no_at_bound_warning_for_a_resolved_value_just_inside_a_bound():
    # kd[r] = 0.003 is within 1% of the span of 0, but resolved to +-0.5%: not piled.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ChainTooShortWarning)  # any other warning: error
        post = _lambert_posterior([0.003, 0.4, 0.6], [0.003, 0.4, 0.6])
    assert post.at_bound == () and post.to_dict()["at_bound"] == []
    assert "at bound" not in post.summary()


def test_mixed_noise_labels_and_bad_arguments():
    m = models.get("lambert")
    data = synthesize(m, {"kd": 0.3}, grid="random", n=300, noise_mult=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ChainTooShortWarning)
        post = sample(m, data, n_steps=40, n_walkers=12, progress=False)
    # The default noise model is "mixed": two sampled scales after the three albedos.
    assert post.noise == "mixed" and post.labels[-2:] == ("log_sigma_add", "log_sigma_mult")
    with pytest.raises(ParameterError, match="noise='weird'"):
        sample(m, data, noise="weird")
    with pytest.raises(ParameterError, match="not free parameters"):
        sample(m, data, priors={"alpha": lambda x: 0.0})


def test_sample_library_names_the_argument():
    data = synthesize(models.get("lambert"), {"kd": [0.2, 0.2, 0.2]}, stride=(15, 15, 15))
    with pytest.raises(ParameterError, match="n_steps"):
        sample(models.get("lambert"), data, n_steps=0, progress=False)
    with pytest.raises(ParameterError, match="n_walkers"):
        sample(models.get("lambert"), data, n_walkers=1, progress=False)


@pytest.mark.parametrize(
    ("noise_add", "noise_mult", "metric"),
    [
        (0.003, 0.03, "low_e2"),
        pytest.param(0.006, 0.0, "ngan", marks=pytest.mark.slow),  # 10 s; "both" covers it
        (0.0, 0.05, "low_e2"),
    ],
    ids=["both", "additive", "multiplicative"],
)
def test_mixed_noise_recovers_both_scales(noise_add, noise_mult, metric):
    # Data with an absolute (1/sr) and a relative noise scale: the default likelihood's
    # two scales bracket the generator's, and a scale the data lack comes out near 0.
    m = models.get("walter", specular_weight=False)
    data = synthesize(
        m, TRUTH, stride=(9, 9, 9), noise_add=noise_add, noise_mult=noise_mult, seed=7
    )
    r = fit(m, data, metric, n_restarts=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ChainTooShortWarning)
        post = sample(m, data, init=r, n_steps=900, burn=300, seed=1, progress=False)
    q = post.quantiles()
    for lab, true in (("log_sigma_add", noise_add), ("log_sigma_mult", noise_mult)):
        lo, med, hi = np.exp(q[lab])
        if true > 0:
            assert lo <= true <= hi and abs(med / true - 1) < 0.1, (lab, lo, med, hi)
        else:
            # Absent: at the median value it adds under a tenth of the noise present.
            f_med = float(np.median(data.values[data.valid]))
            abs_hi = hi if lab.endswith("add") else hi * f_med  # 1/sr
            present = noise_mult * f_med if lab.endswith("add") else noise_add
            assert abs_hi < 0.1 * present, (lab, abs_hi, present)
    lo = np.array([q[lab][0] for lab in post.labels[:-2]])
    hi = np.array([q[lab][2] for lab in post.labels[:-2]])
    t = _flat_truth(post.labels[:-2])
    assert np.sum((lo <= t) & (t <= hi)) >= 5, (lo, hi, t)  # 7 scalars at nominal 95%
