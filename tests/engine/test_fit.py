"""Levenberg-Marquardt fits against synthetic truth: recovery, errors, freezing, failure."""

from __future__ import annotations

import json
import logging
from contextlib import contextmanager

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import (
    FitError,
    FitResult,
    Measurements,
    ParameterError,
    Status,
    fit,
    models,
    synthesize,
)
from brdffit.engine import objective as objective_mod
from brdffit.engine.batch import Engine, _subset, coarse_size, refine_size
from brdffit.engine.fit import require_measurements
from brdffit.engine.metrics import get_metric, prepare, prepare_all, shape_bucket
from brdffit.engine.objective import Objective
from brdffit.engine.settings import COARSE
from tests.cases import CASES

TRUTH = {"kd": [0.1, 0.2, 0.3], "ks": [0.8, 0.7, 0.9], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}
GRID = (5, 5, 5)  # 11,664 MERL bin centres: the MERL grid at a fifth of its resolution


def _digits(got, want) -> float:
    rel = np.max(np.abs(np.asarray(got) - np.asarray(want)) / np.abs(np.asarray(want)))
    return float(-np.log10(max(rel, 1e-17)))


@pytest.fixture(scope="module")
def walter():
    return models.get("walter")


@pytest.mark.parametrize("metric", ["low_e2", pytest.param("ngan", marks=pytest.mark.slow)])
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
    # one start (screen=0): the frozen scalars are the subject, not the start policy. A
    # scalar and an RGB parameter, frozen by value and then by name at their starts: one
    # free set for both fits, so the second reuses the compiled descents (the frozen
    # values are inputs of them; another free set compiled them again, 5 s)
    f0 = [0.9, 0.6, 0.3]
    r = fit(walter, data, "low_e2", freeze={"alpha": 0.15, "f0": f0}, n_restarts=0, screen=0)
    assert r.converged and r.frozen == ("f0", "alpha") and r.n_free == 6
    assert float(r.params["alpha"]) == 0.15 and float(r.stderr["alpha"]) == 0.0
    np.testing.assert_array_equal(r.stderr["f0"], 0.0)
    assert not {"alpha", "f0[r]", "f0[g]", "f0[b]"} & set(r.labels)
    assert "(frozen)" in r.report()
    init = {"alpha": 0.2, "f0": [0.8, 0.5, 0.2]}
    r2 = fit(walter, data, "low_e2", freeze=["alpha", "f0"], init=init, n_restarts=0, screen=0)
    assert float(r2.params["alpha"]) == 0.2 and r2.frozen == ("f0", "alpha")
    np.testing.assert_array_equal(r2.params["f0"], [0.8, 0.5, 0.2])
    assert r2.loss > r.loss  # alpha and f0 held away from the truth's 0.15 and f0
    with pytest.raises(ParameterError, match="cannot freeze unknown parameter"):
        fit(walter, data, freeze={"roughness": 0.1})


def test_a_fit_that_runs_out_of_steps_is_not_converged(walter):
    data = synthesize(walter, TRUTH, stride=GRID)
    # the settings of the max_steps=2 row below: one compiled descent serves both
    r = fit(walter, data, "low_e2", max_steps=2, n_restarts=0, screen=0, throw=False)
    assert r.status is Status.MAX_STEPS and not r.converged
    with pytest.raises(FitError, match="max_steps") as err:
        fit(walter, data, "low_e2", max_steps=2, n_restarts=0, screen=0)
    assert isinstance(err.value.result, FitResult)


@pytest.mark.parametrize("max_steps", [1, 2, 3])
def test_a_fit_never_takes_more_lm_steps_than_max_steps(walter, max_steps):
    # max_steps counts tried LM steps, accepted or not (the old chunked fitter ran a
    # whole 8-step chunk, so max_steps=1 reported 8).
    data = synthesize(walter, TRUTH, stride=GRID)
    r = fit(walter, data, "low_e2", max_steps=max_steps, n_restarts=0, screen=0, throw=False)
    assert r.n_steps <= max_steps and r.status is Status.MAX_STEPS, (r.n_steps, r.status)


@pytest.mark.parametrize("bad", [0, -3, True])
def test_max_steps_must_be_a_positive_integer(walter, bad):
    data = synthesize(walter, TRUTH, stride=GRID)
    with pytest.raises(ParameterError, match="max_steps"):
        fit(walter, data, max_steps=bad)


def test_a_non_finite_fit_is_reported_failed(walter):
    good = synthesize(walter, TRUTH, stride=GRID)
    huge = good.values * 1e305  # (f_model - f_data)^2 overflows: the loss is inf
    data = Measurements.from_directions(good.wi, good.wo, huge, weights=good.weights)
    r = fit(walter, data, "ngan", n_restarts=0, throw=False)
    assert r.status is Status.NONFINITE and not r.converged and r.stderr is None


def test_best_fit_on_a_bound_is_held_there_and_flagged():
    lam = models.get("lambert")
    bright = synthesize(lam, {"kd": 1.0}, grid="random", n=3000, seed=0)
    data = Measurements.from_directions(bright.wi, bright.wo, bright.values * 1.5)
    r = fit(lam, data, "low_e2", n_restarts=0)
    assert r.converged and r.at_bound == ("kd[r]", "kd[g]", "kd[b]")  # per channel
    np.testing.assert_allclose(r.params["kd"], 1.0, rtol=1e-6)
    assert any("bound" in w for w in r.warnings)


def test_json_round_trip_and_required_keys(walter):
    data = synthesize(walter, TRUTH, stride=(9, 9, 9), noise_mult=0.05, seed=1)
    r = fit(walter, data, "low_e2", n_restarts=0)  # the robust test's plain fits compile once
    d = json.loads(r.to_json())
    for key in ("model", "metric", "params", "stderr", "loss", "converged"):
        assert key in d
    assert d["params"]["kd"] == pytest.approx(np.asarray(r.params["kd"]).tolist())
    back = FitResult.from_dict(d)
    assert back.to_dict() == r.to_dict()
    assert set(r.losses) == {"ngan", "low_e1", "low_e2", "log1p_l1"}
    assert r.losses["low_e2"] == r.loss


def _with_outliers(data: Measurements, share: float, factor: float, seed: int) -> Measurements:
    rng = np.random.default_rng(seed)
    values = data.values.copy()
    hit = rng.choice(len(values), int(share * len(values)), replace=False)
    values[hit] *= factor
    return Measurements.from_directions(data.wi, data.wo, values, weights=data.weights)


@pytest.mark.parametrize("robust", ["huber", "cauchy"])
def test_robust_loss_shrugs_off_outliers_the_plain_fit_does_not(walter, robust):
    clean = synthesize(walter, TRUTH, stride=(9, 9, 9), noise_mult=0.02, seed=4)
    data = _with_outliers(clean, 0.01, 100.0, seed=5)
    plain = fit(walter, data, "low_e2", n_restarts=0)
    rob = fit(walter, data, "low_e2", n_restarts=0, robust=robust)
    ref = fit(walter, clean, "low_e2", n_restarts=0)  # what the data say without outliers
    assert rob.converged and rob.robust == robust and rob.robust_scale > 0

    def worst(r):  # largest distance to the clean fit, in the robust fit's standard errors
        return max(np.max(np.abs(r.params[k] - ref.params[k]) / rob.stderr[k]) for k in TRUTH)

    print(robust, "largest |fit - clean fit| / stderr: plain", worst(plain), "robust", worst(rob))
    assert worst(rob) < 2.0 and worst(plain) > 10.0
    assert f"{robust} loss" in rob.report()
    assert FitResult.from_dict(json.loads(rob.to_json())).robust_scale == rob.robust_scale
    with pytest.raises(ParameterError, match="robust"):
        fit(walter, data, robust="l1")


def test_a_robust_fit_under_ngan_ends_below_the_truths_own_robust_objective(walter):
    # ngan is linear in the BRDF: a cell x100 weighs 1e4 more, so the plain optimum is
    # dragged far off. A robust descent judged by the plain loss stayed there (Walter on
    # the stress suite's outliers: 0.162 against the truth's 0.149); judged by its own
    # objective it must reach the truth's basin, so end no higher than the truth.
    clean = synthesize(walter, TRUTH, stride=(9, 9, 9), noise_mult=0.02, seed=4)
    data = _with_outliers(clean, 0.01, 100.0, seed=5)
    r = fit(walter, data, "ngan", init=TRUTH, n_restarts=0, screen=0, robust="huber")
    prep = prepare(data, get_metric("ngan"))
    obj = Objective.build(walter, robust="huber", scale=float(r.robust_scale))
    j_fit, j_truth = (
        float(obj.cost(jnp.asarray(obj.layout.solver_vector(p)), prep)) for p in (r.params, TRUTH)
    )
    assert r.converged
    assert j_fit <= j_truth * (1 + 1e-9), (j_fit, j_truth)


@pytest.mark.parametrize(
    ("stride", "coarse", "winner_on"), [((9, 9, 9), 500, [1_252]), (GRID, 100, [853, 7_288])]
)
def test_coarse_starts_then_all_samples_reach_the_same_optimum(
    walter, stride, coarse, winner_on, monkeypatch
):
    # 1,252 samples, starts on 500: the winner goes straight to all of them; 7,288
    # samples, starts on 100: it is refined on 853 first (refine_size). Coarse to fine
    # ends where the starts on all samples end.
    data = synthesize(walter, TRUTH, stride=stride, noise_mult=0.05, seed=3)
    # n_restarts=0: the screened starts still race; `full` reuses the JSON test's program
    full = fit(walter, data, "low_e2", coarse=None, n_restarts=0)
    single: list[int] = []  # padded sample counts of the one-start descents
    descend = Engine._descend

    def spy(self, obj, z, preps, *rest):
        if np.ndim(z) == 2:
            single.append(preps[0].rows)
        return descend(self, obj, z, preps, *rest)

    monkeypatch.setattr(Engine, "_descend", spy)
    thin = fit(walter, data, "low_e2", coarse=coarse, n_restarts=0)
    assert full.coarse_samples == 0 and thin.coarse_samples == coarse and thin.coarse_steps > 0
    assert single == [shape_bucket(n) for n in winner_on]
    assert thin.n_samples == full.n_samples and thin.converged
    assert thin.loss == pytest.approx(full.loss, rel=1e-9)
    for name in TRUTH:  # both stop at ftol = 1e-10 on the loss: ~1e-5 in parameters
        np.testing.assert_allclose(thin.params[name], full.params[name], rtol=1e-3)
    assert f"starts on {coarse} samples" in thin.report()


def test_an_albedo_whose_optimum_is_zero_lands_on_its_bound_without_a_crawl(walter):
    truth = {**TRUTH, "kd": [0.0, 0.2, 0.3]}
    data = synthesize(walter, truth, stride=GRID)
    for metric in ("low_e2", "ngan"):
        r = fit(walter, data, metric, n_restarts=0, screen=0)  # the one start's descent
        assert r.converged and r.n_steps <= 64, (metric, r.n_steps)
        assert "kd[r]" in r.at_bound and "kd[g]" not in r.at_bound  # only the channel at 0
        np.testing.assert_allclose(r.params["kd"], truth["kd"], atol=1e-9)
        np.testing.assert_allclose(r.params["alpha"], 0.15, rtol=1e-6)


def test_unidentified_parameters_are_named():
    case = next(c for c in CASES if c.model == "disney" and c.not_identifiable)
    model, params = case.build()
    data = synthesize(model, params, stride=(9, 9, 9))
    # the one descent from the truth: the screened starts end anywhere on the family
    r = fit(model, data, "low_e2", init=params, n_restarts=0, screen=0, throw=False)
    named = {label.split("[")[0] for label in r.not_identified}
    assert named & set(case.not_identifiable), (named, case.not_identifiable)
    # F0's scalars, and sheen: base_color s and (1 - metallic) / s keep the diffuse lobe
    # while the sheen lobe, (1 - metallic) sheen, needs sheen s
    family = {"base_color", "metallic", "specular", "specular_tint", "sheen"}
    assert {"metallic", "specular", "specular_tint"} <= named <= family, named
    assert any(n in w for w in r.warnings for n in named)


def test_an_optimum_on_the_upper_bound_is_reached_without_a_crawl():
    # Oren-Nayar with rho = (0, 0.49, 1): in the old logit space the fit from the truth
    # itself crawled towards rho[b] = 1 and stopped unconverged after 512 steps; a box
    # bound is reached by projection.
    on = models.get("oren_nayar")
    truth = {"rho": [0.0, 0.4857, 1.0], "sigma": 0.3917}
    data = synthesize(on, truth, grid="random", n=2000, seed=3)
    r = fit(on, data, "low_e2", init=truth, n_restarts=0, screen=0)
    assert r.converged and r.n_steps <= 128, (r.status, r.n_steps)
    assert set(r.at_bound) == {"rho[r]", "rho[b]"}  # rho[g] = 0.4857 is inside
    np.testing.assert_allclose(r.params["rho"], truth["rho"], atol=1e-9)
    np.testing.assert_allclose(r.params["sigma"], truth["sigma"], rtol=1e-6)


def test_an_albedo_of_3e_6_is_fitted_not_held_at_zero(walter):
    # kd[r] = 3e-6 was u = -12.7 in the old logit space, where the fitter pinned it to 0;
    # in natural units with box bounds it is an interior point like any other.
    truth = {**TRUTH, "kd": [3e-6, 0.2, 0.3]}
    data = synthesize(walter, truth, stride=GRID)
    r = fit(walter, data, "low_e2", n_restarts=0, screen=0)
    assert r.converged and "kd" not in r.at_bound, (r.status, r.at_bound)
    np.testing.assert_allclose(r.params["kd"], truth["kd"], rtol=1e-4)


def test_a_fit_with_every_parameter_frozen_evaluates_and_reports():
    lam = models.get("lambert")
    data = synthesize(lam, {"kd": 0.5}, stride=GRID)
    r = fit(lam, data, "low_e2", freeze={"kd": 0.5})
    assert r.converged and r.n_free == 0 and r.errors_reason == "no free parameter"
    assert r.loss < 1e-25  # the frozen value is the truth: noise-free data, exact fit


def test_fit_refuses_what_is_not_measurements_and_names_the_nbrdf_reader():
    # fit's own check (the test suite's type-check hook would stop the call first)
    class NBRDF:  # stands for the network read_nbrdf returns
        pass

    with pytest.raises(ParameterError, match="read_nbrdf_measurements"):
        require_measurements(NBRDF())
    with pytest.raises(ParameterError, match="got dict"):
        require_measurements({})
    require_measurements(synthesize(models.get("lambert"), {"kd": 0.5}, stride=15))


def test_thinned_starts_keep_each_metrics_own_values():
    """A log metric leaves out a signed value below ln(1 + x)'s domain that a linear
    metric fits; thinning one metric's data like the other's must keep its own values."""
    data = synthesize(models.get("lambert"), {"kd": 0.5}, stride=9)
    values = np.array(data.values)
    values[np.flatnonzero(data.valid)[::7], 1] = -3.0  # f cos far below -1
    signed = Measurements.from_directions(
        data.wi, data.wo, values, valid=data.valid, negative="signed"
    )
    preps = prepare_all(signed)
    lin, log = preps["ngan"], preps["low_e2"]
    assert not np.array_equal(np.asarray(lin.values), np.asarray(log.values))
    small_lin = _subset(lin, 40)
    small_log = _subset(log, 40, like=small_lin)
    idx = np.linspace(0, log.n - 1, 40).round().astype(int)
    np.testing.assert_array_equal(small_log.values, np.asarray(log.values)[idx])
    np.testing.assert_array_equal(small_log.weight, np.asarray(log.weight)[idx])


@pytest.mark.parametrize(
    ("n", "coarse", "want"),
    [
        (1_252, 25_000, None),  # small data: the starts see every sample
        (4_000, 25_000, None),  # the floor would not halve them
        (7_288, 25_000, 2_000),  # the floor
        (20_234, 25_000, 2_000),  # stride 3 3 5: a 32nd would be under the floor
        (100_000, 25_000, 3_125),  # a 32nd
        (909_696, 25_000, 25_000),  # full MERL grid: the cap
        (909_696, COARSE, 8_000),  # and the default's: a stride of 114 keeps every theta_h row
        (20_234, 1_000, 1_000),  # the caller's own cap wins
        (20_234, None, None),  # thinning off
    ],
)
def test_the_starts_thin_mid_sized_data_to_a_32nd(n, coarse, want):
    assert coarse_size(n, coarse) == want


@pytest.mark.parametrize(
    ("n", "n_small", "want"),
    [
        (909_696, 8_000, 85_308),  # full MERL grid: 8,000 -> 85,308 -> all, x 10.7 each
        (20_234, 2_000, None),  # stride 3 3 5: a factor 10 in all, no room for two of 4
        (130_000, 8_000, 32_249),  # just over 16 x 8,000: two factors of 4
        (127_000, 8_000, None),  # just under
        (1_252, 50, 250),
        (1_252, 500, None),
    ],
)
def test_a_stage_between_the_starts_and_all_samples_grows_the_data_evenly(n, n_small, want):
    assert refine_size(n, n_small) == want
    if want is not None:
        assert want**2 <= n * n_small < (want + 1) ** 2


def test_a_fit_on_mid_sized_data_runs_its_starts_on_thinned_samples(walter):
    # 7,288 samples: the starts descend on 2,000 of them, the answer on all, and it is
    # the answer of the starts run on every sample (same cost to 1e-9 relative).
    data = synthesize(walter, TRUTH, stride=GRID, noise_mult=0.02, seed=2)
    thin, full = fit(walter, data), fit(walter, data, coarse=None)
    assert thin.coarse_samples == 2_000 and full.coarse_samples == 0
    assert abs(thin.loss - full.loss) <= 1e-9 * full.loss


@contextmanager
def _compiled():
    """The names of the programs XLA compiles inside the block."""
    names: list[str] = []

    class Names(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            msg = record.getMessage()
            if msg.startswith("Finished XLA compilation of jit("):
                names.append(msg.split("jit(")[1].split(")")[0])

    log, handler = logging.getLogger("jax"), Names()
    log.addHandler(handler)
    try:
        with jax.log_compiles(True):
            yield names
    finally:
        log.removeHandler(handler)


def test_another_metric_on_another_sample_count_reuses_the_compiled_descents(walter):
    # the metric is data (Prepared) and sample counts are padded to a bucket: a fit
    # under ngan on data with 138 samples fewer runs the programs low_e2's fit compiled
    data = synthesize(walter, TRUTH, stride=(9, 9, 9), noise_mult=0.02, seed=1)
    first = fit(walter, data, "low_e2")
    with _compiled() as names:
        second = fit(walter, data, "ngan", cut_deg=78.0)
    assert first.converged and second.converged and second.n_data < first.n_data
    solver = {"race", "select_one", "solve_one", "linear_start_one", "answer"}
    assert not solver & set(names), names


def test_other_tolerances_and_step_budget_reuse_the_compiled_descents(walter):
    # tolerances and max_steps are inputs of the compiled descents, not constants in them
    data = synthesize(walter, TRUTH, stride=(9, 9, 9), noise_mult=0.02, seed=1)
    first = fit(walter, data, "low_e2")
    with _compiled() as names:
        other = dict(max_steps=300, ftol=1e-9, xtol=1e-9, gtol=1e-9)
        second = fit(walter, data, "low_e2", **other)
    assert first.converged and second.converged
    solver = {"race", "select_one", "solve_one", "linear_start_one", "answer"}
    assert not solver & set(names), names


def test_block_errors_from_the_sums_the_descent_kept_match_a_pass_at_the_answer(
    walter, monkeypatch
):
    # the descent on all samples keeps each block's score and Gram matrix at its last
    # linearisation; moved to the answer to first order they give the errors that a
    # Jacobian pass at the answer gives, to the step's size (below the tolerances)
    data = synthesize(walter, TRUTH, stride=GRID, noise_mult=0.05, seed=3)
    calls: list[str] = []
    answer, losses_at = objective_mod.answer, objective_mod.losses_at
    monkeypatch.setattr(objective_mod, "answer", lambda *a: calls.append("answer") or answer(*a))
    monkeypatch.setattr(
        objective_mod, "losses_at", lambda *a: calls.append("losses") or losses_at(*a)
    )
    kept = fit(walter, data, "low_e2", errors="blocks")
    assert calls == ["losses"]
    monkeypatch.setattr(objective_mod, "moved_block_moments", lambda *a: None)
    again = fit(walter, data, "low_e2", errors="blocks")
    assert calls == ["losses", "answer"]
    assert kept.errors_method == again.errors_method == "blocks"
    # the same point; the loss from another program (losses_at, answer): to rounding
    assert kept.n_steps == again.n_steps
    np.testing.assert_array_equal(kept.params["alpha"], again.params["alpha"])
    assert kept.loss == pytest.approx(again.loss, rel=1e-14)
    assert kept.cost == pytest.approx(again.cost, rel=1e-12)
    for name in TRUTH:
        np.testing.assert_allclose(kept.stderr[name], again.stderr[name], rtol=1e-4)
        np.testing.assert_allclose(kept.error_dof[name], again.error_dof[name], rtol=1e-4)
    np.testing.assert_allclose(kept.covariance, again.covariance, rtol=1e-3, atol=1e-12)
