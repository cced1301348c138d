"""Ranking of fits on one data set."""

from __future__ import annotations

import pytest

from brdffit import fit, models, rank, synthesize
from brdffit.errors import ParameterError

TRUTH = {"kd": [0.1, 0.2, 0.3], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}


@pytest.fixture(scope="module")
def results():
    data = synthesize(models.get("walter"), TRUTH, stride=(9, 9, 9), noise_mult=0.05, seed=4)
    return [
        fit(models.get(n), data, "low_e2", n_restarts=1, throw=False)
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
