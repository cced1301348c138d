"""Model-level numerical checks: values and gradients at extreme directions and bounds.

For each parameter set (the defaults, every parameter at its lower bound, every one
at its upper bound; an infinite bound is replaced by 1e6) and each dtype (float32,
float64), :func:`check_model` evaluates ``model.eval`` on :func:`extreme_pairs`
(normal incidence, grazing at cos 1e-6, wi = wo, mirror pairs) and counts NaN and
negative values, non-finite gradients of ``sum(f)`` over the pairs with finite values
with respect to every parameter scalar, and non-zero values below the horizon. A value
of ``+inf`` is an overflow, counted apart and allowed: the true value exceeds the
dtype's range (``tests/models/test_precision.py`` holds every model to that in float64
against a higher-precision reference), and a wrong small finite number would be worse.
``brdffit check`` prints the rows as a table (:func:`format_table`).

Values and gradients are compiled together (:func:`_values_and_gradients`), as the
fitter runs them: one program per model, dtype and pair count serves every parameter
set and the below-horizon pairs (a separate program for the values alone was a second
compile per model and dtype: three heavy rows of the property tests took 20.1 s with it,
16.6 s without).
Evaluated op by op, SGD's first check took 12.6 s (each operation of its quadrature
compiled on its own), compiled 3.9 s; walter 3.4 s and 1.2 s.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from brdffit import models
from brdffit.core.abstract_model import AbstractModel
from brdffit.errors import ParameterError
from brdffit.util.text_table import render

DTYPES: dict[str, jnp.dtype] = {"float32": jnp.dtype("float32"), "float64": jnp.dtype("float64")}
PARAMETER_SETS: tuple[str, ...] = ("defaults", "low", "high")
GRAZING_COS = 1e-6
"""cos(theta) of the grazing directions in :func:`extreme_pairs`."""


def _extreme_table() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(name, wi, wo) of every extreme pair, unit vectors in the shading frame."""
    g = GRAZING_COS
    s = np.sqrt(1 - g * g)
    n = np.array([0.0, 0.0, 1.0])
    graze_x = np.array([s, 0.0, g])
    graze_y = np.array([0.0, s, g])
    graze_mx = np.array([-s, 0.0, g])
    t = np.array([np.sin(1.2), 0.0, np.cos(1.2)])
    t_mirror = np.array([-np.sin(1.2), 0.0, np.cos(1.2)])
    t_oblique = np.array([0.3, -0.4, np.sqrt(1 - 0.25)])
    return [
        ("normal/normal", n, n),
        ("normal/grazing", n, graze_x),
        ("grazing/normal", graze_x, n),
        ("grazing=grazing", graze_x, graze_x),
        ("grazing/mirror", graze_x, graze_mx),
        ("grazing/90deg", graze_x, graze_y),
        ("69deg=69deg", t, t),
        ("69deg/mirror", t, t_mirror),
        ("oblique=oblique", t_oblique, t_oblique),
        ("oblique/opposite", t_oblique, t_oblique * np.array([-1, -1, 1])),
        ("normal/69deg", n, t),
    ]


def extreme_pairs() -> tuple[np.ndarray, np.ndarray]:
    """Hard (wi, wo) pairs, each (11, 3): normal, grazing (cos 1e-6), wi = wo, mirror, mixes."""
    table = _extreme_table()
    return np.array([w for _, w, _ in table]), np.array([w for _, _, w in table])


def extreme_pair_names() -> tuple[str, ...]:
    """Short names of the rows of :func:`extreme_pairs`, in the same order."""
    return tuple(name for name, _, _ in _extreme_table())


def params_at_bounds(model: AbstractModel, which: str) -> dict[str, jax.Array]:
    """Every parameter at its lower (``"low"``) or upper (``"high"``) bound, natural units.

    An infinite bound is replaced by 1e6 (a finite stand-in for "very large").
    """
    if which not in ("low", "high"):
        raise ParameterError(f"which={which!r}: use 'low' or 'high'")
    out = {}
    for p in model.parameters:
        v = p.bounds[0] if which == "low" else p.bounds[1]
        out[p.name] = jnp.full(p.shape, min(v, 1e6), dtype=float)
    return out


@dataclass(frozen=True)
class CheckRow:
    """One model x parameter set x dtype check.

    Counts are of direction pairs (samples) with any RGB channel affected, except
    ``nonfinite_grad``, which counts parameter scalars whose gradient of ``sum(f)`` over
    the pairs with finite values is not finite. ``overflow_f`` counts pairs with a
    ``+inf`` value (allowed, module docstring); ``nonfinite_f`` those with NaN or
    ``-inf``. ``max_f`` is the largest finite value in 1/sr (NaN if none).
    ``bad_grad`` names the parameters with a non-finite gradient; ``bad_pairs`` the
    extreme pairs with a NaN, ``-inf`` or negative value, ``overflow_pairs`` those with
    ``+inf``.
    """

    model: str
    params: str
    dtype: str
    n: int
    nonfinite_f: int
    overflow_f: int
    negative_f: int
    nonfinite_grad: int
    below_horizon_nonzero: int
    dtype_kept: bool
    max_f: float
    bad_grad: tuple[str, ...]
    bad_pairs: tuple[str, ...]
    overflow_pairs: tuple[str, ...]

    @property
    def passed(self) -> bool:
        """No NaN, non-negative, finite gradients, zero below the horizon, kept ``dtype``."""
        counts = (self.nonfinite_f, self.negative_f, self.nonfinite_grad)
        return not any(counts) and not self.below_horizon_nonzero and self.dtype_kept

    @property
    def note(self) -> str:
        """What failed, naming parameters and direction pairs; empty when passed."""
        parts = []
        if self.bad_grad:
            parts.append("nonfinite grad: " + ", ".join(self.bad_grad))
        if self.bad_pairs:
            parts.append("bad f at: " + ", ".join(self.bad_pairs))
        if self.overflow_pairs:
            parts.append("overflow (+inf, allowed) at: " + ", ".join(self.overflow_pairs))
        if self.below_horizon_nonzero:
            parts.append(f"{self.below_horizon_nonzero} nonzero below horizon")
        if not self.dtype_kept:
            parts.append(f"output is not {self.dtype}")
        return "; ".join(parts)


def _rows_with(mask: np.ndarray) -> np.ndarray:
    """Samples (rows of an (N, 3) mask) with any channel set."""
    return np.any(mask, axis=-1)


def _below_horizon_nonzero(model: AbstractModel, params: Mapping, wi, wo) -> int:
    """Samples with a non-zero (or NaN) value when wo, or wi, is mirrored below the horizon."""
    flip = jnp.asarray([[1.0, 1.0, -1.0]], wi.dtype)
    count = 0
    for a, b in ((wi, wo * flip), (wi * flip, wo)):
        f = np.asarray(_values_and_gradients(model, params, a, b)[0])
        count += int(np.sum(_rows_with(f != 0)))
    return count


@eqx.filter_jit
def _values_and_gradients(
    model: AbstractModel, params: Mapping, wi, wo
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """``model.eval`` and the gradient of ``sum(f)`` over the pairs with respect to every
    parameter, as one compiled program (the forward pass is the gradient's own)."""
    f, pullback = jax.vjp(lambda p: model.eval(p, wi, wo), params)
    return f, pullback(jnp.ones_like(f))[0]


def _nonfinite_grads(grads: Mapping[str, jax.Array]) -> dict[str, int]:
    """Parameter name -> number of its scalars whose gradient is not finite."""
    return {k: int(np.sum(~np.isfinite(np.asarray(g)))) for k, g in grads.items()}


def check_params(
    model: AbstractModel, params: Mapping[str, object], dtype: str, label: str = "custom"
) -> CheckRow:
    """Check one natural parameter dict in ``dtype`` (``"float32"``/``"float64"``).

    ``label`` names the parameter set in the row.
    """
    if dtype not in DTYPES:
        raise ParameterError(f"dtype={dtype!r}: use 'float32' or 'float64'")
    jdtype = DTYPES[dtype]
    wi, wo = (jnp.asarray(w, jdtype) for w in extreme_pairs())
    p = model.cast(params, jdtype)
    f_arr, grads = _values_and_gradients(model, p, wi, wo)
    f = np.asarray(f_arr)
    finite = np.isfinite(f)
    overflow = _rows_with(f == np.inf)
    nonfinite, negative = _rows_with(~finite & (f != np.inf)), _rows_with(f < 0)
    keep = ~_rows_with(~finite)
    if not keep.all():  # the gradient over the pairs with finite values only
        grads = _values_and_gradients(model, p, wi[keep], wo[keep])[1]
    grad_bad = _nonfinite_grads(grads)
    names = extreme_pair_names()
    return CheckRow(
        model=models.label(model),
        params=label,
        dtype=dtype,
        n=int(f.shape[0]),
        nonfinite_f=int(np.sum(nonfinite)),
        overflow_f=int(np.sum(overflow)),
        negative_f=int(np.sum(negative)),
        nonfinite_grad=sum(grad_bad.values()),
        below_horizon_nonzero=_below_horizon_nonzero(model, p, wi, wo),
        dtype_kept=bool(f_arr.dtype == jdtype),
        max_f=float(np.max(f[finite])) if finite.any() else float("nan"),
        bad_grad=tuple(k for k, v in grad_bad.items() if v),
        bad_pairs=tuple(k for k, b in zip(names, nonfinite | negative, strict=True) if b),
        overflow_pairs=tuple(k for k, b in zip(names, overflow, strict=True) if b),
    )


def _dtypes(dtype: str) -> tuple[str, ...]:
    """``"both"`` -> every dtype name; one name -> itself (validated by :func:`check_params`)."""
    return tuple(DTYPES) if dtype == "both" else (dtype,)


def check_model(model: AbstractModel, dtype: str = "both") -> list[CheckRow]:
    """Rows for every parameter set (defaults, low, high) x dtype (``"both"`` or one name)."""
    sets = {
        "defaults": model.defaults(),
        "low": params_at_bounds(model, "low"),
        "high": params_at_bounds(model, "high"),
    }
    return [
        check_params(model, sets[name], dt, name)
        for name in PARAMETER_SETS
        for dt in _dtypes(dtype)
    ]


TABLE_HEAD = [
    "model",
    "params",
    "dtype",
    "n",
    "nonfinite f",
    "overflow f",
    "negative f",
    "nonfinite grad",
    "below horizon != 0",
    "max f",
    "verdict",
    "note",
]


def _cells(r: CheckRow) -> list[str]:
    return [
        r.model,
        r.params,
        r.dtype,
        str(r.n),
        str(r.nonfinite_f),
        str(r.overflow_f),
        str(r.negative_f),
        str(r.nonfinite_grad),
        str(r.below_horizon_nonzero),
        f"{r.max_f:.4g}",
        "pass" if r.passed else "FAIL",
        r.note or "-",
    ]


def format_table(rows: Sequence[CheckRow], fmt: str = "text") -> str:
    """The rows as a plain-text (aligned), Markdown or CSV table."""
    return render(TABLE_HEAD, [_cells(r) for r in rows], fmt)
