"""How long a model takes to evaluate: the one timer behind a sweep's cost column and the
cost ratio that :func:`brdffit.simplify` reports.

What is timed is the model alone, ``model.evaluate(params, g)`` jitted, on shading
geometry computed beforehand (the geometry depends on the data only and is computed
once per data set, so it is not part of a model's cost). Calls are repeated until one
measurement lasts about 2 ms, so that the clock's resolution and the dispatch of a
single call do not decide the figure, and the best of ``repeats`` measurements is kept
(the least disturbed by other work on the machine).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry, shading_geometry
from brdffit.core.measurements import Measurements

#: Seconds one measurement should last at least (many calls per measurement when one is
#: quicker): well above ``time.perf_counter``'s resolution and a call's dispatch.
MIN_MEASUREMENT_S = 2e-3


@functools.cache
def _compiled(model: AbstractModel) -> Callable:
    """``jax.jit(model.evaluate)``, one per model options (models are frozen and compare
    by their options), so that it is traced and compiled once per process and sample
    count. Made anew for every model object, it was traced and compiled again in every
    task of a sweep: 0.45-0.6 s for SGD and STD on 65,536 samples, more than the timing."""
    return jax.jit(model.evaluate)


def eval_seconds(
    model: AbstractModel, params: dict, g: ShadingGeometry, *, repeats: int = 5
) -> float:
    """Best-of-``repeats`` warm seconds of one jitted ``model.evaluate(params, g)``.

    The first call (compilation) is not timed."""
    p = {k: jnp.asarray(v) for k, v in params.items()}
    # the model closed over (its options are static), so a call is one compiled dispatch
    _evaluate = _compiled(model)
    jax.block_until_ready(_evaluate(p, g))
    t0 = time.perf_counter()
    jax.block_until_ready(_evaluate(p, g))
    reps = max(1, int(MIN_MEASUREMENT_S / max(time.perf_counter() - t0, 1e-7)))
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(reps):
            out = _evaluate(p, g)
        jax.block_until_ready(out)
        best = min(best, (time.perf_counter() - t0) / reps)
    return best


def eval_ns_per_sample(
    model: AbstractModel, params: dict, data: Measurements, *, n: int = 65536, repeats: int = 3
) -> float:
    """:func:`eval_seconds` on ``n`` samples, in ns per sample: the valid directions of
    ``data`` tiled (or cut) to ``n``."""
    idx = np.resize(np.flatnonzero(data.valid), n)
    g = shading_geometry(jnp.asarray(data.wi[idx]), jnp.asarray(data.wo[idx]))
    return eval_seconds(model, params, g, repeats=repeats) / n * 1e9
