"""The one rule for every number an export writes, applied by :func:`brdffit.export.export`.

Every target's writer (Mitsuba dict, XML and JSON; glTF JSON; MaterialX) formats the
values that come out of this module, and nothing else, so the rule lives here once:

1. **Non-finite values are refused.** A NaN or infinite fitted parameter, model value or
   target slot raises :class:`~brdffit.errors.ExportValueError` naming it, before any
   file is written (``write_exports`` exports every target before writing any file).
2. **Zero within resolution is zero.** A target slot value within :data:`RESOLUTION`
   times its range of a bound *is* the bound: ``sheen_tint = 6.1e-19`` is written 0,
   ``weight = 1 - 1e-16`` is written 1. :data:`RESOLUTION` is :data:`EXACT_TOL`, the
   tolerance that already defines an exact export, so snapping never turns an exact
   mapping into an inexact one except for a material that is black to that tolerance.
3. **Float32 normal range.** Renderers read float32: Mitsuba parses every number with
   ``std::stof``, which throws on subnormals (``mi.load_dict({'type': 'principled',
   'sheen_tint': 1e-39})`` fails, 6e-19 loads), and glTF/MaterialX viewers store float32.
   So every written number is 0 or has a magnitude in ``[FLOAT32_TINY, FLOAT32_MAX]``;
   :func:`check_material` walks the finished material and refuses any other, naming
   the key, as a guard on values derived from the slots (glTF's ``ior``, Mitsuba's
   ``eta``).

The snapped match's errors are measured again, so the error an export reports is that
of the numbers written.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from brdffit.errors import ExportValueError
from brdffit.export._match import (
    EXACT_TOL,
    Family,
    Match,
    albedo_directions,
    albedo_error,
    log_rms,
    relative_rms,
)

FLOAT32_TINY = float(np.finfo(np.float32).tiny)
"""Smallest normal float32, 1.1754944e-38: below it ``std::stof`` throws (subnormal)."""
FLOAT32_MAX = float(np.finfo(np.float32).max)
"""Largest float32, 3.4028235e38."""
RESOLUTION = EXACT_TOL
"""A slot value within this fraction of its range from a bound is written as the bound."""


def require_finite(what: str, values: Mapping[str, object]) -> None:
    """Raise :class:`ExportValueError` naming the first entry of ``values`` not finite.

    Arguments: ``what`` says whose values they are (``"the fit's parameter"``);
    ``values`` maps names to scalars or arrays.
    """
    for name, v in values.items():
        arr = np.asarray(v, float)
        if not np.all(np.isfinite(arr)):
            raise ExportValueError(
                name, arr.tolist(), f"{what} {name!r} is {arr.tolist()}; only finite values export"
            )


def snap(value: float, lower: float, upper: float) -> float:
    """``value`` as written for a slot with bounds ``[lower, upper]`` (rules 2 and 3).

    Clipped into the bounds; within ``RESOLUTION * (upper - lower)`` of a bound it
    becomes that bound; a magnitude below :data:`FLOAT32_TINY` becomes 0. Unitless:
    the slot's own unit.
    """
    tol = RESOLUTION * (upper - lower)
    v = min(max(float(value), lower), upper)
    if v - lower <= tol:
        v = lower
    elif upper - v <= tol:
        v = upper
    return 0.0 if abs(v) < FLOAT32_TINY else min(max(v, -FLOAT32_MAX), FLOAT32_MAX)


def snap_params(family: Family, params: Mapping[str, object]) -> dict[str, object]:
    """Every slot of ``params`` through :func:`snap`; refuses a non-finite one by name."""
    require_finite(f"{family.name} slot", {s.name: params[s.name] for s in family.slots})
    out = dict(params)
    for s in family.slots:
        arr = np.atleast_1d(np.asarray(params[s.name], float))
        snapped = np.array([snap(x, s.lower, s.upper) for x in arr])
        out[s.name] = float(snapped[0]) if s.size == 1 else snapped
    return out


def writable(
    match: Match,
    f_model: np.ndarray,
    wi: np.ndarray,
    wo: np.ndarray,
    albedo: np.ndarray | None = None,
) -> Match:
    """``match`` with its slot values as they will be written, errors measured again.

    Arguments: ``f_model`` (N, 3) the fitted model at ``wi``, ``wo`` (1/sr), the pairs
    the match was measured at; ``albedo`` the model at
    :func:`~brdffit.export._match.albedo_directions`, or None. Returns ``match`` itself
    when nothing changed.
    """
    params = snap_params(match.family, match.params)
    error, log_error, a_error = match.error, match.log_error, match.albedo_error
    same = all(
        np.array_equal(np.asarray(params[s.name]), np.asarray(match.params[s.name]))
        for s in match.family.slots
    )
    if not same:
        f = match.family.evaluate(params, wi, wo)
        require_finite(f"{match.family.name} value", {"f": f})
        error, log_error = relative_rms(f, f_model, wi[:, 2]), log_rms(f, f_model, wi[:, 2])
        if albedo is not None:
            a_error = albedo_error(match.family.evaluate(params, *albedo_directions()), albedo)
    # the errors are written too (file comments, glTF extras): the same float32 rule
    error, log_error = (0.0 if abs(x) < FLOAT32_TINY else x for x in (error, log_error))
    if same and (error, log_error) == (match.error, match.log_error):
        return match
    fitted = match.fitted
    return Match(match.family, params, error, log_error, match.start_error, fitted, a_error)


def check_material(material: object, path: str = "material") -> None:
    """Refuse any number in ``material`` (nested dicts, lists, arrays) that breaks rule 3.

    Raises :class:`ExportValueError` naming the key path (``material.bsdf_1.alpha``), the
    value and what is accepted. Strings and booleans pass.
    """
    if isinstance(material, Mapping):
        for k, v in material.items():
            check_material(v, f"{path}.{k}")
        return
    if isinstance(material, (list, tuple, np.ndarray)):
        for i, v in enumerate(np.asarray(material, dtype=object).ravel()):
            check_material(v, f"{path}[{i}]")
        return
    if isinstance(material, (str, bool, np.bool_)) or material is None:
        return
    v = float(material)
    if not np.isfinite(v) or (v != 0.0 and not FLOAT32_TINY <= abs(v) <= FLOAT32_MAX):
        raise ExportValueError(
            path,
            v,
            f"{path} = {v!r} cannot be written: a renderer reads float32, so a value must be "
            f"finite and 0 or of magnitude in [{FLOAT32_TINY:.8g}, {FLOAT32_MAX:.8g}]",
        )
