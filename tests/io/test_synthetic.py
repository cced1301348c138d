"""Synthetic measurements: exact noise-free values, seeded noise with the asked statistics."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit import ParameterError, models, synthesize

TRUTH = {"kd": [0.1, 0.2, 0.3], "ks": [0.8, 0.7, 0.9], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}


def test_noise_free_values_equal_model_on_the_grid():
    m = models.get("walter")
    data = synthesize(m, TRUTH, stride=(9, 9, 9))
    f = np.asarray(m.eval({k: np.asarray(v, float) for k, v in TRUTH.items()}, data.wi, data.wo))
    # synthesize evaluates the model compiled, this is op by op: XLA's fusion may round
    # differently in the last bit
    np.testing.assert_allclose(data.values[data.valid], f[data.valid], rtol=1e-13, atol=0)
    # Every above-horizon cell is valid when nothing is missing.
    assert data.n_valid == int(np.sum((data.wi[:, 2] > 0) & (data.wo[:, 2] > 0)))


def test_seeded_noise_statistics_and_missing_fraction():
    m = models.get("lambert")
    a = synthesize(m, {"kd": 0.5}, grid="random", n=20000, noise_mult=0.1, missing=0.25, seed=3)
    b = synthesize(m, {"kd": 0.5}, grid="random", n=20000, noise_mult=0.1, missing=0.25, seed=3)
    assert np.array_equal(a.values, b.values) and np.array_equal(a.valid, b.valid)
    logr = np.log(a.values[a.valid] / (0.5 / np.pi))
    # 15000 x 3 draws: the sample std of N(0, 0.1) is within 2% of 0.1 (about 6 sigma).
    assert abs(np.std(logr) - 0.1) < 2e-3 and abs(np.mean(logr)) < 2e-3
    assert a.n_valid == 15000


def test_additive_noise_negative_values_are_masked():
    m = models.get("lambert")
    d = synthesize(m, {"kd": 0.01}, grid="random", n=5000, noise_add=0.01, seed=0)
    assert 0 < d.n_valid < d.n  # some went negative and are therefore "not measured"
    assert np.all(d.values[d.channel_valid] >= 0)  # masked per channel
    assert (d.valid & ~d.channel_valid.all(axis=1)).any()  # the other channels stay


def test_bad_arguments_name_the_problem():
    m = models.get("lambert")
    with pytest.raises(ParameterError, match="grid='hex'"):
        synthesize(m, {}, grid="hex")
    with pytest.raises(ParameterError, match="missing=1.5"):
        synthesize(m, {}, missing=1.5)
    with pytest.raises(ParameterError, match="'kd'.*outside bounds"):
        synthesize(m, {"kd": 2.0})
