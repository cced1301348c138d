"""A fit's result as people read it: ``at bound`` flags per channel, values without an
error printed cleanly, per-scalar labels through JSON, and losses per sample beside the
sums (in the report, the JSON and the ranking table)."""

from __future__ import annotations

import dataclasses
import json

import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import FitResult, Measurements, fit, models, rank, synthesize
from brdffit.core.result_terms import per_sample, value_text
from brdffit.engine import metrics as metrics_mod
from brdffit.engine import misfit


@pytest.fixture(scope="module")
def oren_nayar_fit():
    # rho[r] and rho[b] on their bounds, rho[g] inside (as in test_fit.py)
    on = models.get("oren_nayar")
    truth = {"rho": [0.0, 0.4857, 1.0], "sigma": 0.3917}
    data = synthesize(on, truth, grid="random", n=2000, seed=3)
    return fit(on, data, "low_e2", init=truth, n_restarts=0, screen=0)


# --------------------------------------------------------------------------- at bound


def test_at_bound_names_only_the_channels_on_a_bound(oren_nayar_fit):
    r = oren_nayar_fit
    assert r.at_bound == ("rho[r]", "rho[b]")
    lines = {x.split()[0]: x for x in r.report().splitlines() if x.startswith("    rho")}
    assert "[at bound" not in lines["rho[g]"] and "%" in lines["rho[g]"]
    assert "[at bound" in lines["rho[r]"] and "[at bound" in lines["rho[b]"]
    assert "nan" not in r.report()
    # held on its bound by the active set: the solver's 4e-18 and a NaN error (the issue)
    pinned = dataclasses.replace(
        r,
        params={**r.params, "rho": np.array([4.24835e-18, *r.params["rho"][1:]])},
        stderr={**r.stderr, "rho": np.array([np.nan, *r.stderr["rho"][1:]])},
    )
    line = next(x for x in pinned.report().splitlines() if x.startswith("    rho[r]"))
    assert line.split()[1:6] == ["0", "(at", "bound;", "no", "error)"], line


@pytest.mark.parametrize(
    ("value", "err", "at_bound", "text"),
    [
        (4.24835e-18, float("nan"), True, "0 (at bound; no error)"),  # the line
        (1.0, float("nan"), True, "1 (at bound; no error)"),
        (0.3, float("nan"), False, "0.3 (no error)"),
        (0.0, 0.01, False, "0 +/- 0.01"),  # no relative error of a zero
        (0.5, 0.01, False, "0.5 +/- 0.01 (2.00%)"),
        (0.5, None, False, "0.5 +/- (none)"),
    ],
)
def test_values_without_an_error_print_cleanly(value, err, at_bound, text):
    assert value_text(value, err, at_bound=at_bound) == text


def test_results_written_with_names_read_back_with_per_scalar_labels(oren_nayar_fit):
    d = json.loads(oren_nayar_fit.to_json())
    assert d["at_bound"] == ["rho[r]", "rho[b]"]
    assert FitResult.from_dict(d).at_bound == ("rho[r]", "rho[b]")
    d["at_bound"] = ["rho", "sigma"]  # a result file from before the labels
    assert FitResult.from_dict(d).at_bound == ("rho[r]", "rho[g]", "rho[b]", "sigma")


# --------------------------------------------------------------------------- losses per sample


def test_losses_per_sample_do_not_depend_on_the_sample_count():
    walter = models.get("walter")
    truth = {"kd": [0.1, 0.2, 0.3], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}
    params = {**walter.defaults(), **{k: jnp.asarray(v) for k, v in truth.items()}}
    data = synthesize(walter, truth, stride=(9, 9, 9), noise_mult=0.05, seed=2)
    twice = Measurements.from_directions(
        *(np.vstack([a] * 2) for a in (data.wi, data.wo, data.values)),
        weights=np.concatenate([data.weights] * 2),
    )  # the same samples twice: a sum doubles, a per-sample value must not move

    def per(d):
        preps = metrics_mod.prepare_all(d, cut_deg=80.0)
        n = next(iter(preps.values())).n
        some = next(iter(preps.values()))
        losses = misfit.losses(walter.evaluate(params, some.g), some.cos_i, preps)
        return {k: (float(v), per_sample(k, float(v), n)) for k, v in losses.items()}

    one, two = per(data), per(twice)
    for name in ("low_e1", "low_e2"):
        assert two[name][0] == pytest.approx(2 * one[name][0], rel=1e-12)
    for name in metrics_mod.METRICS:
        assert two[name][1] == pytest.approx(one[name][1], rel=1e-12), name
    # two sub-grids of one noisy material: sums 27x apart, per sample within 10% (the
    # noise, 5% multiplicative, is what is left at the truth)
    fine = synthesize(walter, truth, stride=(3, 3, 3), noise_mult=0.05, seed=3)
    f = per(fine)
    assert f["low_e2"][0] / one["low_e2"][0] > 20
    assert f["low_e2"][1] == pytest.approx(one["low_e2"][1], rel=0.1)


def test_reports_tables_and_json_give_the_loss_per_sample(oren_nayar_fit):
    r = oren_nayar_fit
    d = json.loads(r.to_json())
    assert d["loss_kind"] == "sum" and d["loss_per_sample"] == pytest.approx(r.loss / r.n_samples)
    assert d["losses_per_sample"]["ngan"] == d["losses"]["ngan"]  # an RMS already
    assert f"sum over {r.n_samples} samples; {r.loss / r.n_samples:.6g} per sample" in r.report()
    table = rank([r]).table("csv").splitlines()
    assert table[0].startswith("rank,model,options,low_e2 (sum),low_e2 per sample,")
    assert float(table[1].split(",")[4]) == pytest.approx(r.loss / r.n_samples, rel=1e-5)
