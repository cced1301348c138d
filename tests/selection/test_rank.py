"""Ranking of fits on one data set."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from brdffit import ParameterError, Status, fit, models, rank, synthesize
from brdffit.selection.rank import LOSS_RTOL, ranks

TRUTH = {"kd": [0.1, 0.2, 0.3], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}


@pytest.fixture(scope="module")
def results():
    data = synthesize(models.get("walter"), TRUTH, stride=(9, 9, 9), noise_mult=0.05, seed=4)
    return [
        # one start each: the ranking is the subject (three screened races cost 29 s)
        fit(models.get(n), data, "low_e2", n_restarts=0, screen=0, throw=False)
        for n in ("lambert", "blinn_phong", "walter")
    ]


def test_the_generating_model_ranks_first_by_every_criterion(results):
    for by in ("loss", "aic", "bic"):
        r = rank(results, by=by)
        assert r.rows[0].model == "walter", r.table()
        assert [getattr(x, f"rank_{by}") for x in r.rows] == [1, 2, 3]
    table = rank(results).table()
    assert "low_e2" in table and "n = residuals" in table
    md = rank(results).table("markdown")
    assert md.count("\n|") >= 4
    assert rank(results).table("csv").splitlines()[0].startswith("rank,model")


def test_mixing_metrics_or_data_is_refused(results):
    other = fit(
        models.get("lambert"),
        synthesize(models.get("lambert"), {}, stride=(9, 9, 9)),
        "ngan",
        n_restarts=0,
    )
    with pytest.raises(ParameterError, match="one data set under one metric"):
        rank([results[0], other])
    with pytest.raises(ParameterError, match="at least one"):
        rank([])


NAN = float("nan")


@pytest.mark.parametrize(
    ("values", "rtol", "expected"),
    [
        ([3.0, 1.0, 2.0], LOSS_RTOL, [3, 1, 2]),
        ([2.0, 1.0, 2.0 * (1 + 5e-6)], LOSS_RTOL, [2.5, 1, 2.5]),  # inside 1e-5: a tie
        ([2.0, 1.0, 2.0 * (1 + 5e-6)], 0.0, [2, 1, 3]),  # exact ties only
        ([1.0, 1.0 + 2e-5], LOSS_RTOL, [1, 2]),  # outside 1e-5
        ([1.0, 1.0 + 8e-6, 1.0 + 1.6e-5], LOSS_RTOL, [1.5, 1.5, 3]),  # no chaining past 1e-5
        ([5.0, 5.0, 5.0, 1.0], 0.0, [3, 3, 3, 1]),  # ranks 2, 3, 4 -> 3
        ([NAN, 1.0, NAN, 2.0], LOSS_RTOL, [3.5, 1, 3.5, 2]),  # NaN last, tied with each other
        ([0.0, 0.0], LOSS_RTOL, [1.5, 1.5]),
        ([-10.0, -10.0 + 5e-5], LOSS_RTOL, [1.5, 1.5]),  # |difference| / |value| = 5e-6
        ([], LOSS_RTOL, []),
    ],
)
def test_ranks_share_the_average_of_tied_places(values, rtol, expected):
    assert ranks(np.array(values), rtol).tolist() == expected


def test_a_nested_model_at_its_boundary_ties_with_the_smaller_one(results):
    lambert, walter = results[0], results[2]
    # Oren-Nayar converged to its Lambert special case: loss 2e-6 relative above Lambert
    nested = replace(lambert, model="oren_nayar", options={}, loss=lambert.loss * (1 + 2e-6))
    worse = replace(lambert, model="phong", options={}, loss=lambert.loss * (1 + 1e-3))
    # stopped at max_steps 1e-3 above walter: ranked by the loss it reached, and marked
    stuck = replace(walter, model="ward", status=Status.MAX_STEPS, loss=walter.loss * 1.001)
    nan = float("nan")
    failed = replace(walter, model="kurt", status=Status.NONFINITE, loss=nan, aic=nan, bic=nan)
    r = rank([worse, failed, nested, lambert, walter, stuck])
    by = {row.model: row.rank_loss for row in r.rows}
    assert by == {
        "walter": 1,
        "ward": 2,  # not converged, finite loss
        "oren_nayar": 3.5,
        "lambert": 3.5,
        "phong": 5,
        "kurt": 6,  # no finite loss: last
    }
    assert [row.model for row in r.rows[2:4]] == ["oren_nayar", "lambert"]  # given order
    text = r.table()
    assert "\n3.5 " in text and "share their average rank" in text
    assert "NO (MAX_STEPS)" in text and "NO (NONFINITE)" in text


def test_options_column_shows_the_changed_options_of_the_label(results):
    walter = results[2]
    beckmann = replace(walter, options={**walter.options, "distribution": "beckmann"})
    gone = replace(walter, model="no_longer_registered", options={"lobes": 3})
    rows = {row.model: row.options for row in rank([walter, beckmann, gone]).rows if row.options}
    assert rows == {"walter": "distribution=beckmann", "no_longer_registered": "lobes=3"}
