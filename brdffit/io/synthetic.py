"""Synthetic measurements from any model and parameters, with seeded noise and gaps.

Noise, applied in this order to the noise-free values ``f``:

* multiplicative log-normal: ``f exp(sigma_mult z)``, ``z ~ N(0, 1)`` per sample and
  channel (median-preserving: the log of the data is unbiased);
* additive Gaussian: ``+ sigma_add z'`` in 1/sr (values may turn negative; a negative
  value means "not measured" in the MERL format, so such cells become invalid);
* a fraction ``missing`` of the valid samples marked invalid (drawn without
  replacement).

Everything is drawn from ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

from collections.abc import Mapping

import jax.numpy as jnp
import numpy as np

from brdffit.core.abstract_model import AbstractModel, eval_compiled
from brdffit.core.geometry import uniform_hemisphere
from brdffit.core.measurements import Measurements
from brdffit.errors import ParameterError
from brdffit.io.merl_grid import merl_grid, merl_grid_measurements


def _params(model: AbstractModel, params: Mapping[str, object]) -> dict:
    full = model.defaults()
    for name, value in params.items():
        full[name] = model.parameter(name).check_value(value)
    return full


def synthesize(
    model: AbstractModel,
    params: Mapping[str, object],
    *,
    grid: str = "merl",
    stride: tuple[int, int, int] | int = (1, 1, 1),
    n: int = 100_000,
    directions: tuple[np.ndarray, np.ndarray] | None = None,
    noise_mult: float = 0.0,
    noise_add: float = 0.0,
    missing: float = 0.0,
    seed: int = 0,
    source: str | None = None,
) -> Measurements:
    """Measurements of ``model`` at ``params`` (missing names take defaults).

    Arguments:
    - ``grid``: ``"merl"`` (the MERL bin centres, file order, see ``stride``),
      ``"random"`` (``n`` pairs uniform on the upper hemisphere, equal weights) or
      ``"directions"`` (the given ``directions = (wi, wo)``).
    - ``stride``: sub-grid of the MERL grid (odd divisors of 90, 90, 180); 1 = full.
    - ``noise_mult``, ``noise_add``, ``missing``, ``seed``: see the module docstring.
    - ``source``: provenance text; a description of the generator by default.

    Returns :class:`Measurements` marked
    :attr:`~brdffit.core.measurements.Measurements.synthetic`; on the full MERL grid it
    can be written with :func:`brdffit.write_merl` (read back, it counts as measured).
    """
    if noise_mult < 0 or noise_add < 0 or not 0 <= missing < 1:
        raise ParameterError(
            f"noise_mult={noise_mult}, noise_add={noise_add} must be >= 0 and "
            f"missing={missing} in [0, 1)"
        )
    full = _params(model, params)
    rng = np.random.default_rng(seed)
    if source is None:
        source = f"synthetic {model.name} ({grid}, seed {seed})"
    if grid == "merl":
        g = merl_grid(stride)
        wi, wo = g.wi, g.wo
    elif grid == "random":
        wi, wo = uniform_hemisphere(rng, n), uniform_hemisphere(rng, n)
    elif grid == "directions" and directions is not None:
        wi, wo = (np.asarray(a, float) for a in directions)
    else:
        raise ParameterError(
            f"grid={grid!r}: use 'merl', 'random' or 'directions' (with directions=(wi, wo))"
        )
    f = np.asarray(eval_compiled(model, full, jnp.asarray(wi), jnp.asarray(wo)), dtype=float)
    if noise_mult:
        f = f * np.exp(noise_mult * rng.standard_normal(f.shape))
    if noise_add:
        f = f + noise_add * rng.standard_normal(f.shape)
    keep = np.ones(len(f), bool)
    if missing:
        idx = rng.choice(len(f), size=int(round(missing * len(f))), replace=False)
        keep[idx] = False
    if grid == "merl":
        cube = f.T.reshape(3, *g.shape)
        valid = keep.reshape(g.shape)
        out = merl_grid_measurements(cube, source=source, stride=stride, valid=valid)
    else:
        out = Measurements.from_directions(wi, wo, f, valid=keep, source=source)
    return out.replace(synthetic=True)
