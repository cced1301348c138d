"""Metrics against a direct numpy transcription of DESIGN.md's formulas."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from brdffit import Measurements
from brdffit.engine import metrics, misfit
from tests.helpers import random_pairs


def _data(seed: int = 0, n: int = 400) -> tuple[Measurements, np.ndarray]:
    wi, wo = random_pairs(seed, n)
    rng = np.random.default_rng(seed)
    fd = rng.uniform(0.01, 5.0, (n, 3))
    fm = fd * rng.uniform(0.5, 1.5, (n, 3))
    w = rng.uniform(0.5, 2.0, n)
    return Measurements.from_directions(wi, wo, fd, weights=w), fm


def _reference(name: str, data: Measurements, fm: np.ndarray, cut_deg: float) -> float:
    c = np.cos(np.deg2rad(cut_deg))
    k = data.valid & (data.wi[:, 2] > c) & (data.wo[:, 2] > c)
    ci = data.wi[k, 2][:, None]
    si = np.sqrt(1 - data.wi[k, 2] ** 2)[:, None]
    fd, fm = data.values[k], fm[k]
    if name == "ngan":
        w = data.weights[k][:, None]
        return float(np.sqrt(np.sum(w * (fm * ci - fd * ci) ** 2) / np.sum(w[:, 0])))
    if name == "low_e1":
        return float(np.sum(((fm - fd) * ci) ** 2 * si))
    if name == "low_e2":
        return float(np.sum((np.log1p(fm * ci) - np.log1p(fd * ci)) ** 2 * si))
    return float(np.mean(np.abs(np.log1p(fm * ci) - np.log1p(fd * ci))))


@pytest.mark.parametrize("name", sorted(metrics.METRICS))
@pytest.mark.parametrize("cut", [80.0, 60.0])
def test_loss_matches_design_formula(name, cut):
    data, fm = _data()
    m = metrics.get_metric(name)
    prep = metrics.prepare(data, m, cut_deg=cut)
    keep = metrics.keep_mask(data, cut)
    got = float(misfit.loss(jnp.asarray(fm[keep]), prep))
    # Same float64 sums in another order: 1e-12 relative.
    np.testing.assert_allclose(got, _reference(name, data, fm, cut), rtol=1e-12)


@pytest.mark.parametrize("name", ["ngan", "low_e1", "low_e2"])
def test_quadratic_metrics_loss_is_sum_of_squared_residuals(name):
    data, fm = _data(1)
    m = metrics.get_metric(name)
    prep = metrics.prepare(data, m)
    keep = metrics.keep_mask(data, 80.0)
    r = misfit.residuals(jnp.asarray(fm[keep]), prep)
    total = float(jnp.sum(r * r))
    expect = total**0.5 if name == "ngan" else total
    np.testing.assert_allclose(float(misfit.loss(jnp.asarray(fm[keep]), prep)), expect, rtol=1e-12)


def test_l1_surrogate_is_quadratic_near_zero_and_linear_far():
    data, _ = _data(2, 50)
    m = metrics.get_metric("log1p_l1")
    prep = metrics.prepare(data, m, cut_deg=None)
    w = float(prep.weight[0, 0])
    for e, expect in [(1e-6, 1e-12), (1.0, 2 * metrics.L1_DELTA * 1.0)]:
        # f such that log1p(f cos) - target = e exactly for every sample and channel.
        f = (jnp.expm1(prep.target + e)) / prep.cos_i[:, None]
        r = misfit.residuals(f, prep)
        # r^2 / w is 2 delta^2 (sqrt(1 + (e/delta)^2) - 1): e^2 for small e, ~2 delta |e| for large.
        np.testing.assert_allclose(float(r[0] ** 2 / w), expect, rtol=2e-3)


def test_unknown_metric_and_empty_selection_raise():
    data, _ = _data()
    with pytest.raises(metrics.ParameterError, match="unknown metric 'nope'"):
        metrics.get_metric("nope")
    with pytest.raises(metrics.ParameterError, match="no valid sample"):
        metrics.prepare(data, metrics.get_metric("ngan"), cut_deg=0.0)


@given(st.integers(1, 10**8))
def test_shape_bucket_rounds_up_by_less_than_an_eighth_to_a_fixed_point(n):
    b = metrics.shape_bucket(n)
    assert n <= b and 8 * (b - n) < n
    assert metrics.shape_bucket(b) == b


def test_shape_bucket_has_eight_sizes_per_octave():
    assert len({metrics.shape_bucket(n) for n in range(2**14 + 1, 2**15 + 1)}) == 8


@pytest.mark.parametrize("name", sorted(metrics.METRICS))
def test_padded_rows_add_nothing_to_residuals_or_loss(name):
    data, fm = _data(3)
    prep = metrics.prepare(data, metrics.get_metric(name))
    f = jnp.asarray(fm[metrics.keep_mask(data, 80.0)])
    big = prep.pad(prep.n + 37)
    # the padding repeats the first sample's directions: a model is evaluated there
    f_big = jnp.concatenate([f, jnp.repeat(f[:1], 37, axis=0)])
    r, r_big = misfit.residuals(f, prep), misfit.residuals(f_big, big)
    np.testing.assert_array_equal(r_big[: r.size], r)
    assert np.all(np.asarray(r_big[r.size :]) == 0.0)
    np.testing.assert_allclose(misfit.loss(f_big, big), misfit.loss(f, prep), rtol=1e-14)
    assert big.rows == prep.rows + 37 and big.n == prep.n
    assert prep.padded().rows == metrics.shape_bucket(prep.n) and prep.padded().n == prep.n


@pytest.mark.parametrize("name", sorted(metrics.METRICS))
def test_prepare_all_pads_once_and_its_samples_are_prepare_s(name):
    # 289 samples: padded to 304 (shape_bucket); the rows before the padding are what
    # prepare gives, and the padding changes neither residuals nor loss
    data, fm = _data(3)
    prep = metrics.prepare(data, metrics.get_metric(name))
    every = metrics.prepare_all(data)
    padded = every[name]
    assert padded.n == prep.n and padded.rows == metrics.shape_bucket(prep.n) > prep.n
    assert padded.padded() is padded
    for field in ("cos_i", "target", "weight", "values"):
        np.testing.assert_array_equal(np.asarray(getattr(padded, field))[: prep.n],
                                      np.asarray(getattr(prep, field)))  # fmt: skip
    assert not np.any(np.asarray(padded.weight)[prep.n :])
    f = fm[metrics.keep_mask(data, 80.0)]
    f_big = jnp.asarray(np.concatenate([f, np.repeat(f[:1], padded.rows - prep.n, 0)]))
    np.testing.assert_allclose(misfit.loss(f_big, padded), misfit.loss(jnp.asarray(f), prep),
                               rtol=1e-14)  # fmt: skip
    np.testing.assert_allclose(misfit.losses(f_big, padded.cos_i, every)[name],
                               misfit.loss(jnp.asarray(f), prep), rtol=1e-14)  # fmt: skip
