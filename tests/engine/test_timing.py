"""The evaluation-cost timer: traced once per model options, not once per model object."""

from __future__ import annotations

import math

import numpy as np

from brdffit import models
from brdffit.core.geometry import shading_geometry
from brdffit.engine import timing
from brdffit.engine.timing import eval_seconds


def test_a_model_is_traced_once_for_every_equal_model_object(monkeypatch):
    rng = np.random.default_rng(0)
    v = rng.normal(size=(2, 256, 3))
    v[..., 2] = np.abs(v[..., 2]) + 0.1
    wi, wo = v / np.linalg.norm(v, axis=-1, keepdims=True)
    g = shading_geometry(wi, wo)
    model = models.from_spec("walter")
    params = {p.name: np.full(p.shape, p.default) for p in model.parameters}
    traced = []
    evaluate = type(model).evaluate

    def counting(self, p, geometry):
        traced.append(1)  # runs only while jax traces: a compiled call does not enter it
        return evaluate(self, p, geometry)

    monkeypatch.setattr(type(model), "evaluate", counting)
    timing._compiled.cache_clear()  # no program compiled before the patch
    try:
        times = [eval_seconds(models.from_spec("walter"), params, g, repeats=2) for _ in range(3)]
    finally:
        timing._compiled.cache_clear()  # none that calls the patch after it
    assert all(math.isfinite(t) and t > 0 for t in times)
    assert len(traced) == 1  # one trace for three sweep tasks of the same model
