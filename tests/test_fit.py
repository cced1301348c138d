"""Levenberg-Marquardt fits against synthetic truth: recovery, errors, freezing, failure."""

from __future__ import annotations

import json

import numpy as np
import pytest

from brdffit import FitError, FitResult, Status, fit, models, synthesize
from brdffit.errors import ParameterError
from brdffit.measurements import Measurements

TRUTH = {"kd": [0.1, 0.2, 0.3], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}
GRID = (5, 5, 5)  # 11,664 MERL bin centres: the MERL grid at a fifth of its resolution


def _digits(got, want) -> float:
    rel = np.max(np.abs(np.asarray(got) - np.asarray(want)) / np.abs(np.asarray(want)))
    return float(-np.log10(max(rel, 1e-17)))


@pytest.fixture(scope="module")
def walter():
    return models.get("walter")


@pytest.mark.parametrize("metric", ["low_e2", "ngan"])
def test_noise_free_ggx_lambert_recovered_to_1e6(walter, metric):
    data = synthesize(walter, TRUTH, stride=GRID)
    r = fit(walter, data, metric)
    assert r.converged
    for name, want in TRUTH.items():
        print(f"{metric} {name}: {_digits(r.params[name], want):.1f} matching digits")
        np.testing.assert_allclose(r.params[name], want, rtol=1e-6)


def test_noisy_fit_within_three_standard_errors(walter):
    data = synthesize(walter, TRUTH, stride=GRID, noise_mult=0.05, seed=11)
    r = fit(walter, data, "low_e2")
    assert r.converged and r.stderr is not None
    for name, want in TRUTH.items():
        z = (r.params[name] - np.asarray(want)) / r.stderr[name]
        print(name, np.round(z, 2))
        assert np.all(np.abs(z) < 3), (name, z)
        assert np.all(r.stderr[name] > 0)


def test_frozen_parameters_leave_the_fit(walter):
    data = synthesize(walter, TRUTH, stride=GRID, noise_mult=0.02, seed=2)
    r = fit(walter, data, "low_e2", freeze={"alpha": 0.15}, n_restarts=0)
    assert r.converged and r.frozen == ("alpha",) and r.n_free == 6
    assert float(r.params["alpha"]) == 0.15 and float(r.stderr["alpha"]) == 0.0
    assert "alpha" not in r.labels and "(frozen)" in r.report()
    r2 = fit(walter, data, "low_e2", freeze=["f0"], init={"f0": [0.9, 0.6, 0.3]}, n_restarts=0)
    np.testing.assert_array_equal(r2.params["f0"], [0.9, 0.6, 0.3])
    with pytest.raises(ParameterError, match="cannot freeze unknown parameter"):
        fit(walter, data, freeze={"roughness": 0.1})


def test_a_fit_that_runs_out_of_steps_is_not_converged(walter):
    data = synthesize(walter, TRUTH, stride=GRID)
    r = fit(walter, data, "low_e2", max_steps=2, n_restarts=0, throw=False)
    assert r.status is Status.MAX_STEPS and not r.converged
    with pytest.raises(FitError, match="max_steps") as err:
        fit(walter, data, "low_e2", max_steps=2, n_restarts=0)
    assert isinstance(err.value.result, FitResult)


def test_a_non_finite_fit_is_reported_failed(walter):
    good = synthesize(walter, TRUTH, stride=GRID)
    huge = good.values * 1e305  # (f_model - f_data)^2 overflows: the loss is inf
    data = Measurements.from_directions(good.wi, good.wo, huge, weights=good.weights)
    r = fit(walter, data, "ngan", n_restarts=0, throw=False)
    assert r.status is Status.NONFINITE and not r.converged and r.stderr is None


def test_best_fit_on_a_bound_is_pinned_and_flagged():
    lam = models.get("lambert")
    bright = synthesize(lam, {"kd": 1.0}, grid="random", n=3000, seed=0)
    data = Measurements.from_directions(bright.wi, bright.wo, bright.values * 1.5)
    r = fit(lam, data, "low_e2", n_restarts=0)
    assert r.converged and r.at_bound == ("kd",)
    np.testing.assert_allclose(r.params["kd"], 1.0, rtol=1e-6)
    assert any("bound" in w for w in r.warnings)


def test_json_round_trip_and_required_keys(walter):
    data = synthesize(walter, TRUTH, stride=(9, 9, 9), noise_mult=0.05, seed=1)
    r = fit(walter, data, "low_e2", n_restarts=1)
    d = json.loads(r.to_json())
    for key in ("model", "metric", "params", "stderr", "loss", "converged"):
        assert key in d
    assert d["params"]["kd"] == pytest.approx(np.asarray(r.params["kd"]).tolist())
    back = FitResult.from_dict(d)
    assert back.to_dict() == r.to_dict()
    assert set(r.losses) == {"ngan", "low_e1", "low_e2", "log1p_l1"}
    assert r.losses["low_e2"] == r.loss
