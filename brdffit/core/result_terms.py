"""The terms a fit result is read in: what a loss value is, what its errors assume,
how a value and its error print, and when a value counts as at its bound.

Shared by :mod:`brdffit.core.result` (the fields), :mod:`brdffit.core.result_text` (the
report and its HTML) and the modules that rank and tabulate losses.
"""

from __future__ import annotations

import math

import numpy as np

AT_BOUND_RTOL = 1e-6
"""A free scalar within this relative distance of a bound is flagged ``at bound``."""

AT_BOUND_ATOL = 1e-9
"""... or within this absolute distance (bounds at 0); such a value is printed as 0."""

SUMMED_METRICS = ("low_e1", "low_e2")
"""Metrics whose loss is a sum over samples (:mod:`brdffit.engine.metrics`: unnormalised
``sin theta_i`` weights); the others are a weighted RMS (``ngan``) or a mean
(``log1p_l1``)."""


#: The side, in degrees of (theta_h, theta_d), of the blocks that ``errors="blocks"``
#: treats as independent (:mod:`brdffit.engine.block_errors`).
BLOCK_DEG = 10.0


def errors_assumed(method: str, n_blocks: int = 0, dof: dict | None = None) -> str:
    """What the standard errors of ``method`` (``sandwich``, ``classic``, ``blocks``) assume,
    in the words reports print beside them (``dof``: :attr:`FitResult.error_dof
    <brdffit.core.result.FitResult.error_dof>`, its range is printed)."""
    if method == "classic":
        return "residuals independent, one variance; errors by classic (s^2 (J^T J)^-1)"
    if method == "blocks":
        nu = np.concatenate([np.ravel(v) for v in (dof or {}).values()] or [np.empty(0)])
        nu = nu[np.isfinite(nu)]
        t = f", {nu.min():.3g} to {nu.max():.3g} degrees of freedom" if nu.size else ""
        return (
            f"model error: residuals correlated within {BLOCK_DEG:g}-degree (theta_h, theta_d) "
            f"blocks, independent between them; errors by cluster sandwich (CR2) over "
            f"{n_blocks} blocks, widened so that +/- 1.96 stderr is the Student-t 95% "
            f"interval{t}"
        )
    return "residuals independent, any variance; errors by sandwich"


def per_sample(metric: str, loss: float, n_samples: int) -> float:
    """The loss of ``metric`` per sample (module docstring): ``loss / n_samples`` for the
    summed metrics, ``loss`` itself for the normalised ones; NaN without samples."""
    if metric not in SUMMED_METRICS:
        return float(loss)
    return float(loss) / n_samples if n_samples > 0 else float("nan")


def loss_kind(metric: str) -> str:
    """What a loss value of ``metric`` is: ``"sum"``, ``"RMS"`` or ``"mean"`` over samples."""
    if metric in SUMMED_METRICS:
        return "sum"
    return "RMS" if metric == "ngan" else "mean"


def value_cells(
    v: float, err: float | None, *, frozen: bool = False, at_bound: bool = False
) -> tuple[str, str, str]:
    """A scalar, its error and its relative error in %, as the three texts of
    :func:`value_text` (the relative error is ``""`` where that prints none; the error is
    ``(frozen)``, ``(none)`` or ``(at bound; no error)`` / ``(no error)`` where it is not a
    number)."""
    if at_bound and abs(v) <= AT_BOUND_ATOL:
        v = 0.0
    if frozen:
        return f"{v:.6g}", "(frozen)", ""
    if err is None:
        return f"{v:.6g}", "(none)", ""
    if not math.isfinite(err):
        return f"{v:.6g}", f"({'at bound; ' if at_bound else ''}no error)", ""
    return f"{v:.6g}", f"{err:.3g}", f"{abs(err / v) * 100:.2f}" if v != 0 else ""


def value_text(v: float, err: float | None, *, frozen: bool = False, at_bound: bool = False) -> str:
    """A scalar and its standard error as the report prints them.

    ``value +/- error (relative %)``; ``(frozen)``; ``+/- (none)`` when the fit has no
    errors at all; ``(at bound; no error)`` or ``(no error)`` when this scalar's error
    is not finite (held on a bound, or singular). A value at a bound within
    :data:`AT_BOUND_ATOL` of 0 prints as 0 (the solver's round-off, e.g. 4e-18, is not a
    value), and the relative error is left out when the value is 0: never ``nan%``.
    The texts are those of :func:`value_cells`.
    """
    value, error, rel = value_cells(v, err, frozen=frozen, at_bound=at_bound)
    if frozen or (err is not None and not math.isfinite(err)):
        return f"{value} {error}"
    return f"{value} +/- {error}" + (f" ({rel}%)" if rel else "")
