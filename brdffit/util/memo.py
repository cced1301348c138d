"""Values computed once per live object: :func:`per_object`.

A fit derives the same arrays from the same data again and again (a sweep fits 36
models and metrics to one material; :func:`brdffit.fit` pads the data for every metric
at the end of each fit). :func:`per_object` keeps what was derived beside the object it
was derived from, for as long as that object lives, keyed by identity: it is for
objects that do not change (:class:`brdffit.core.measurements.Measurements` holds
read-only arrays; :class:`brdffit.engine.metrics.Prepared` is a frozen module).
"""

from __future__ import annotations

import threading
import weakref
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

T = TypeVar("T")

_SLOTS: dict[int, dict[Hashable, Any]] = {}
_LOCK = threading.Lock()


def per_object(owner: object, key: Hashable, compute: Callable[[], T]) -> T:
    """``compute()`` the first time ``(owner, key)`` is asked for while ``owner`` lives;
    the same value afterwards. ``owner`` must support weak references; the values go
    when it is collected."""
    with _LOCK:
        slot = _SLOTS.get(id(owner))
        if slot is None:
            slot = _SLOTS[id(owner)] = {}
            weakref.finalize(owner, _SLOTS.pop, id(owner), None)
        if key in slot:
            return slot[key]
    value = compute()
    with _LOCK:
        return slot.setdefault(key, value)
