"""Robust losses: residuals whose squares are a robust loss, and their IRLS weights.

Least squares minimises ``0.5 sum r^2``; a robust fit minimises ``0.5 sum rho(r)`` with
``rho`` Huber's or Cauchy's loss at a scale in residual units. :func:`robust_residuals`
gives residuals whose squares are ``rho(r)``, so Levenberg-Marquardt stays a
least-squares solver; :func:`robust_weights` the weights of its iteratively reweighted
Gauss-Newton model (:meth:`brdffit.engine.objective.Objective.linearize`).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from brdffit.engine.metrics import Prepared
from brdffit.engine.misfit import residuals
from brdffit.errors import ParameterError

ROBUST_TUNING = {"huber": 1.345, "cauchy": 2.385}
"""Tuning constants (in units of the residuals' robust sigma) for 95% efficiency."""

MAD_SIGMA = 1.4826
"""``1 / Phi^-1(3/4)``: the median absolute deviation of normal residuals times this is
their sigma (Hampel 1974)."""


def default_scale(kind: str, r: np.ndarray) -> float:
    """The scale of ``kind``'s loss for the plain residuals ``r`` (host): its tuning
    constant times their robust sigma, :data:`MAD_SIGMA` x MAD (the RMS where the MAD is
    0, i.e. where more than half the residuals are equal)."""
    mad = MAD_SIGMA * float(np.median(np.abs(r - np.median(r))))
    spread = mad if mad > 0 else float(np.sqrt(np.mean(r * r)))
    return ROBUST_TUNING[kind] * max(spread, 1e-300)


def check_kind(kind: str | None) -> None:
    """Raise :class:`~brdffit.errors.ParameterError` unless ``kind`` is None or a key of
    :data:`ROBUST_TUNING`."""
    if kind is not None and kind not in ROBUST_TUNING:
        raise ParameterError(f"robust={kind!r}: use None, 'huber' or 'cauchy'")


def robust_residuals(r: Array, kind: str | None, scale: Array | np.ndarray | float) -> Array:
    """Residuals whose squares are a robust loss of ``r`` with ``scale`` (residual units).

    ``None`` returns ``r``. ``"huber"``: ``rho(r) = r^2`` for ``|r| <= c`` and
    ``2 c |r| - c^2`` beyond; ``"cauchy"``: ``rho(r) = c^2 ln(1 + (r / c)^2)``. The
    returned ``sign(r) sqrt(rho(r))`` keeps LM a least-squares solver; both forms are
    smooth at 0 and equal ``r`` to first order there.
    """
    if kind is None:
        return r
    x = r / scale
    if kind == "huber":
        a = jnp.abs(x)
        big = a > 1.0
        root = jnp.sqrt(jnp.where(big, 2.0 * a - 1.0, 1.0))
        return jnp.where(big, jnp.sign(r) * scale * root, r)
    if kind == "cauchy":
        # x * sqrt(ln(1 + x^2) / x^2), written with log1p and safe at x = 0
        x2 = x * x
        safe = jnp.where(x2 > 1e-12, x2, 1.0)
        factor = jnp.where(x2 > 1e-12, jnp.sqrt(jnp.log1p(safe) / safe), 1.0 - 0.25 * x2)
        return r * factor
    raise ParameterError(f"robust={kind!r}: use None, 'huber' or 'cauchy'")


def robust_weights(r: Array, kind: str | None, scale: Array | np.ndarray | float) -> Array:
    """IRLS weights ``rho'(r^2)`` of the robust loss of :func:`robust_residuals`.

    The gradient of ``0.5 sum rho(r^2)`` is ``J^T (w r)`` with these ``w``; the
    Gauss-Newton model of the reweighted problem is ``J^T diag(w) J``. ``None``: ones;
    ``"huber"``: ``min(1, scale / |r|)``; ``"cauchy"``: ``1 / (1 + (r / scale)^2)``.
    """
    if kind is None:
        return jnp.ones_like(r)
    x = jnp.abs(r) / scale
    if kind == "huber":
        return 1.0 / jnp.maximum(x, 1.0)
    if kind == "cauchy":
        return 1.0 / (1.0 + x * x)
    raise ParameterError(f"robust={kind!r}: use None, 'huber' or 'cauchy'")


def objective(
    f_model: Array,
    prep: Prepared,
    robust: str | None = None,
    scale: Array | np.ndarray | float = 1.0,
) -> Array:
    """``0.5 sum rho(r)^2``: what Levenberg-Marquardt minimises (``rho`` the robust loss)."""
    r = robust_residuals(residuals(f_model, prep), robust, scale)
    return 0.5 * jnp.sum(r * r)
