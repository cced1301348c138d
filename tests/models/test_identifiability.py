"""Each model row recovers its own parameters from noise-free synthetic data.

Parameters a row declares ``not_identifiable`` (with the reason) are frozen at the
truth; every other parameter must come back from the defaults (plus two seeded
restarts) to 1e-3 relative. The directions are the same for every row (one geometry).

A row costs 8-40 s on 2 cores, nearly all of it compiling the model's fit (walter: 13 s
the first time, 0.2 s the second), so the default suite runs two rows, :data:`FAST_MODELS`:
Lambert (the smallest fit) and Lafortune's two lobes (the label switching this test
allows for). Every other row is marked ``slow`` and runs with
``bash benchmarks/slow_checks.sh``; the default suite fits walter to its truth in
``tests/engine/test_fit.py``, and ``benchmarks/stress`` recovers every model from noisy data.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from brdffit import Measurements, fit
from tests.cases import CASES
from tests.helpers import random_pairs

WI, WO = random_pairs(7, 1500)

_FIRST: set[str] = set()
FAST_MODELS = frozenset({"lambert", "lafortune"})
"""Models whose first row runs in the default suite (module docstring)."""


def _param(case):
    """The first row of each model in :data:`FAST_MODELS` runs in the default suite; every
    other row is slow."""
    first = case.model not in _FIRST and case.model in FAST_MODELS
    _FIRST.add(case.model)
    return pytest.param(case, id=case.id, marks=() if first else pytest.mark.slow)


@pytest.mark.parametrize("case", [_param(c) for c in CASES])
def test_model_recovers_its_own_parameters(case):
    model, truth = case.build()
    f = np.asarray(model.eval(truth, WI, WO))
    data = Measurements.from_directions(WI, WO, f, source=f"synthetic {case.id}")
    freeze = {k: np.asarray(truth[k]) for k in case.not_identifiable}
    r = fit(model, data, "low_e2", freeze=freeze or None, n_restarts=2, cut_deg=None, throw=False)
    assert r.converged, r.report()
    # A multi-lobe model is the same function with its lobes in any order (label
    # switching), so the answer is compared with every ordering of the truth's lobes.
    errors = [_mismatch(model, r.params, t, freeze) for t in _lobe_orders(case, truth)]
    assert min(errors) == "", errors[0] + "\n" + r.report()


def _lobe_orders(case, truth: dict) -> list[dict]:
    n = int(case.options.get("n_lobes", 1))
    out = []
    for order in itertools.permutations(range(1, n + 1)):
        moved = {}
        for name, value in truth.items():
            stem, _, lobe = name.rpartition("_")
            if stem and lobe.isdigit():
                name = f"{stem}_{order[int(lobe) - 1]}"
            moved[name] = value
        out.append(moved)
    return out


def _mismatch(model, params: dict, truth: dict, freeze: dict) -> str:
    """'' when every free parameter matches ``truth``, else the assertion's message."""
    for p in model.parameters:
        if p.name in freeze:
            continue
        got, want = np.asarray(params[p.name]), np.asarray(truth[p.name])
        # Noise-free data and float64: 1e-3 relative leaves room for flat valleys
        # (e.g. exponents of 1e3) that LM's tolerances stop on early.
        try:
            np.testing.assert_allclose(got, want, rtol=1e-3, atol=1e-6, err_msg=p.name)
        except AssertionError as e:
            return str(e)
    return ""
