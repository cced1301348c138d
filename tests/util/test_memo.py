"""Values computed once per live object (:mod:`brdffit.util.memo`)."""

import gc

import numpy as np

from brdffit import models, synthesize
from brdffit.engine import metrics
from brdffit.util import memo
from brdffit.util.memo import per_object


class _Owner:
    pass


def test_a_value_is_computed_once_per_owner_and_key_and_goes_with_its_owner():
    calls = []
    a, b = _Owner(), _Owner()
    for owner in (a, a, b):
        per_object(owner, "k", lambda: calls.append(1) or len(calls))
    del owner
    assert per_object(a, "k", lambda: -1) == 1 and per_object(b, "k", lambda: -1) == 2
    assert per_object(a, "other", lambda: 3) == 3
    key_a, key_b = id(a), id(b)
    assert key_a in memo._SLOTS and key_b in memo._SLOTS
    del a
    gc.collect()  # other tests' owners may go too: look at these two only
    assert key_a not in memo._SLOTS and key_b in memo._SLOTS


def test_a_data_set_is_prepared_and_padded_once():
    walter = models.get("walter")
    data = synthesize(walter, walter.defaults(), stride=(9, 9, 9))
    first = metrics.prepare_all(data)
    assert metrics.prepare_all(data) is first
    assert metrics.prepare_all(data, cut_deg=70.0) is not first
    p = first["low_e2"]
    assert p.padded() is p and p.rows == metrics.shape_bucket(p.n)
    thin = p.take(np.arange(p.n // 2))
    assert thin.padded() is thin.padded() and thin.padded().rows == metrics.shape_bucket(thin.n)
    before = len(memo._SLOTS)
    del data, first, p
    gc.collect()
    assert len(memo._SLOTS) < before  # nothing holds the data's arrays once it is gone
