"""The Measurements container: per-channel validity, the negative-value policy, counts.

Expected masks are computed here from the definitions (horizon by the directions'
z components, the policy's rule on the values), not from brdffit's own helpers.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from brdffit import Measurements, MeasurementsError
from brdffit.engine import metrics, misfit


def _dirs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2, n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return v[0], v[1]


@settings(max_examples=40, deadline=None)
@given(
    values=arrays(np.float64, (12, 3), elements=st.floats(-2.0, 2.0)),
    seed=st.integers(0, 2**16),
    policy=st.sampled_from(["not_measured", "signed"]),
)
def test_channel_masks_follow_the_policy_channel_by_channel(values, seed, policy):
    wi, wo = _dirs(12, seed)
    data = Measurements.from_directions(wi, wo, values, negative=policy)
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    measured = values >= 0 if policy == "not_measured" else np.ones_like(values, bool)
    np.testing.assert_array_equal(data.channel_valid, above[:, None] & measured)
    np.testing.assert_array_equal(data.valid, above & measured.any(axis=1))
    np.testing.assert_array_equal(data.values, values)  # kept as given, never clamped
    counts = data.mask_counts()
    assert counts.below_horizon == int((~above).sum())
    assert counts.n_masked == data.n - data.n_valid
    lost = above[:, None] & ~measured
    assert counts.channels_masked == tuple(int(k) for k in lost.sum(axis=0))


def test_non_finite_values_are_an_error_unless_marked_invalid():
    wi, wo = _dirs(20, 1)
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]) + 0.1, np.abs(wo[:, 2]) + 0.1
    values = np.full((20, 3), 0.2)
    values[7, 1] = np.nan
    with pytest.raises(MeasurementsError, match=r"1 non-finite .* sample 7"):
        Measurements.from_directions(wi, wo, values, source="gonio run 3")
    valid = np.ones((20, 3), bool)
    valid[7, 1] = False
    data = Measurements.from_directions(wi, wo, values, valid=valid)
    assert data.valid[7] and not data.channel_valid[7, 1] and data.values[7, 1] == -1.0
    with pytest.raises(MeasurementsError, match="negative="):
        Measurements.from_directions(wi, wo, np.abs(values), negative="clamp")


def test_a_masked_channel_has_no_weight_and_the_normalisation_counts_channels():
    wi, wo = _dirs(400, 2)
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]) + 0.2, np.abs(wo[:, 2]) + 0.2
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    values = np.random.default_rng(0).uniform(0.1, 1.0, (400, 3))
    full = Measurements.from_directions(wi, wo, values)
    holes = values.copy()
    holes[::3, 2] = -1.0  # blue not measured in a third of the samples
    part = Measurements.from_directions(wi, wo, holes)
    assert part.n_valid == full.n_valid
    for name in metrics.METRICS:
        m = metrics.get_metric(name)
        p_full = metrics.prepare(full, m, cut_deg=None)
        p_part = metrics.prepare(part, m, cut_deg=None)
        w = np.asarray(p_part.weight)
        assert (w[::3, 2] == 0).all() and (w[1::3] > 0).all()
        # a model equal to the data everywhere has loss 0 with or without the holes
        assert float(misfit.loss(p_full.values, p_part)) == pytest.approx(0.0, abs=1e-15)
        # a uniform relative error gives the same mean loss with the holes (ngan, l1)
        f = 1.1 * p_full.values
        if m.weighting == "uniform":
            lf = float(misfit.loss(f, p_full))
            assert float(misfit.loss(f, p_part)) == pytest.approx(lf, rel=0.15)


def test_log_metrics_leave_out_values_outside_the_log_domain():
    wi = np.tile([0.5, 0.0, np.sqrt(0.75)], (3, 1))  # low_e2 weighs by sin theta_i
    wo = np.tile([0.0, 0.0, 1.0], (3, 1))
    values = np.array([[0.5, -0.2, 0.5], [0.5, -1.5, 0.5], [0.4, 0.4, 0.4]])
    data = Measurements.from_directions(wi, wo, values, negative="signed")
    assert data.channel_valid.all()
    w = np.asarray(metrics.prepare(data, metrics.get_metric("low_e2"), cut_deg=None).weight)
    assert w[1, 1] == 0 and (np.delete(w.ravel(), 4) > 0).all()  # -1.5: ln(1 + x) undefined
    w = np.asarray(metrics.prepare(data, metrics.get_metric("ngan"), cut_deg=None).weight)
    assert (w > 0).all()  # a linear metric fits the signed value as it is


def test_replace_valid_applies_to_every_channel_and_layout_is_named():
    wi, wo = _dirs(10, 3)
    data = Measurements.from_directions(wi, wo, np.full((10, 3), -1.0))
    assert data.n_valid == 0
    opened = data.replace(valid=np.ones(10, bool))
    assert opened.channel_valid.all() and opened.n_valid == 10
    assert data.layout() == "scattered directions"
