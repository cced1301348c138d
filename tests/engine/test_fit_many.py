"""``fit_many``: many data sets, each result equal to one ``fit`` of its data."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit import ParameterError, fit, fit_many, models, synthesize
from brdffit.engine import fit as fit_mod

GRID = (9, 9, 9)  # 2,000 MERL bin centres: small enough for several fits per test


def _materials(n: int) -> list:
    rng = np.random.default_rng(7)
    walter = models.get("walter")
    out = []
    for i in range(n):
        truth = {
            "kd": rng.uniform(0.05, 0.6, 3),
            "f0": rng.uniform(0.02, 0.9, 3),
            "alpha": float(np.exp(rng.uniform(np.log(0.03), np.log(0.6)))),
        }
        out.append(synthesize(walter, truth, stride=GRID, noise_mult=0.03, seed=i))
    return out


# the robust row (10 s) is slow; robust single fits are in the default suite (test_fit.py)
@pytest.mark.parametrize("robust", [None, pytest.param("huber", marks=pytest.mark.slow)])
@pytest.mark.parametrize("path", ["concurrent", "batched"])
def test_fit_many_equals_one_fit_per_material(robust, path, monkeypatch):
    """Both ways of solving many problems: one per core in threads (the CPU's) and one
    batched solve (an accelerator's, here on the CPU's ``lax.map``)."""
    if path == "batched":
        monkeypatch.setattr(fit_mod, "cores", lambda: 0)
    walter = models.get("walter")
    data = _materials(3)
    many = fit_many(walter, data, "low_e2", robust=robust)
    for d, r in zip(data, many, strict=True):
        one = fit(walter, d, "low_e2", robust=robust)
        assert r.converged and r.source == d.source
        # the same start policy and the same loop: only the summation order of a
        # batched reduction differs, so the losses agree to rounding
        assert r.loss == pytest.approx(one.loss, rel=1e-9), (r.loss, one.loss)
        for name in one.params:
            np.testing.assert_allclose(r.params[name], one.params[name], rtol=1e-6)


def test_fit_many_refuses_data_sets_of_different_sizes():
    walter = models.get("walter")
    a = synthesize(walter, walter.defaults(), stride=GRID)
    b = synthesize(walter, walter.defaults(), stride=(5, 5, 5))
    with pytest.raises(ParameterError, match="different sample counts"):
        fit_many(walter, [a, b])
    with pytest.raises(ParameterError, match="no data set"):
        fit_many(walter, [])
