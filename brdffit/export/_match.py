"""Matching a renderer's material to a fitted model: the directions, the error, the fit.

Every export is judged the same way, by measurement:

* :func:`error_directions` is one fixed set of direction pairs (Halton points in
  Rusinkiewicz angles, dense near the specular peak like the MERL grid, both
  directions within :data:`CUT_DEG` of the normal);
* :func:`relative_rms` is the error of a target material against the model there, on
  ``f cos(theta_i)`` (the quantity a renderer integrates against the light), and
  :func:`log_rms` the same comparison in ``ln(1 + f cos(theta_i))`` (the form of the
  ``low_e2`` fit metric), which weighs a sharp highlight and the diffuse colour alike;
* :func:`match` starts from a closed-form mapping and keeps it when its relative error
  is at float64 round-off (:data:`EXACT_TOL`): the export is then exact. Otherwise it
  fits the target's parameters to the model by bounded least squares on the log
  residuals (scipy's ``least_squares``) and keeps whichever has the smaller log error.
  Fitting the linear residuals instead let a highlight of alpha 0.008 (10% of the pairs
  lie in it) decide everything: the diffuse colour of a red plastic came out grey.

A :class:`Family` is a renderer's parametrised material: named slots with bounds and a
numpy evaluation in brdffit's convention (``wi`` toward the light, ``wo`` toward the
viewer, f in 1/sr without the cosine). :func:`generic_alpha` is the microfacet alpha
every target starts a model without a closed-form mapping from.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import qmc

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import halfdiff_to_io

N_DIRECTIONS = 4096
"""Halton points drawn; those with a direction beyond :data:`CUT_DEG` are dropped."""
CUT_DEG = 80.0
"""Both directions of every pair lie within this angle of the normal (degrees)."""
EXACT_TOL = 1e-9
"""An export whose error is at most this (float64 evaluation) is exact."""
BLACK = 1e-10
"""RMS of ``f cos(theta_i)`` (1/sr) below which a model counts as black: the relative
error's denominator is floored at it, so a model fitted to ~0 (parameters at 1e-40)
has a finite, meaningful error instead of a ratio of two round-offs."""

ERROR_DEFINITION = (
    "error = relative RMS of f cos(theta_i) over R, G, B: sqrt(sum ((f_export - f_model) "
    f"cos_i)^2 / max(sum (f_model cos_i)^2, n {BLACK:g}^2)) (n values; a model darker than "
    f"{BLACK:g} 1/sr RMS is black); log error = RMS of ln(1 + f_export cos_i) - "
    "ln(1 + f_model cos_i); both at the direction pairs of "
    f"brdffit.export.error_directions() ({N_DIRECTIONS} Halton points in Rusinkiewicz "
    "angles, theta_h = (pi/2) u^2 as on the MERL grid, theta_d, phi_d, phi_h uniform; pairs "
    f"with a direction beyond {CUT_DEG:g} degrees dropped); approximate exports are fitted "
    "on the log error; albedo error = RMS over views at 0, 30, 60, 75 degrees and R, G, B "
    "of the relative difference of the directional albedo (integral of f cos_i over "
    f"theta_i < {CUT_DEG:g} degrees); candidates are ranked by log error + albedo error"
)

Evaluate = Callable[[Mapping[str, np.ndarray], np.ndarray, np.ndarray], np.ndarray]


@functools.lru_cache(maxsize=1)
def _directions() -> tuple[np.ndarray, np.ndarray]:
    u = qmc.Halton(d=4, scramble=False).random(N_DIRECTIONS + 1)[1:]  # the first is all 0
    theta_h = 0.5 * np.pi * u[:, 0] ** 2
    wi, wo = halfdiff_to_io(
        theta_h, 0.5 * np.pi * u[:, 1], 2 * np.pi * u[:, 2], 2 * np.pi * u[:, 3]
    )
    keep = np.minimum(wi[:, 2], wo[:, 2]) > np.cos(np.radians(CUT_DEG))
    return wi[keep], wo[keep]


def error_directions() -> tuple[np.ndarray, np.ndarray]:
    """The fixed direction pairs every export error is measured at: ``(wi, wo)``, (N, 3) each.

    Unit vectors in the shading frame, ``wi`` toward the light, ``wo`` toward the viewer
    (see :data:`ERROR_DEFINITION`). Deterministic: unscrambled Halton points.
    """
    wi, wo = _directions()
    return wi.copy(), wo.copy()


ALBEDO_VIEWS_DEG = (0.0, 30.0, 60.0, 75.0)
"""View angles (degrees from the normal) at which :func:`albedo_error` compares albedos."""


@functools.lru_cache(maxsize=1)
def _albedo_grid() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n_theta, n_phi = 24, 48
    cut = np.cos(np.radians(CUT_DEG))
    mu = 1.0 - (np.arange(n_theta) + 0.5) / n_theta * (1.0 - cut)  # cos theta_i, midpoints
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    m, p = (a.ravel() for a in np.meshgrid(mu, phi, indexing="ij"))
    s = np.sqrt(1.0 - m**2)
    wi1 = np.stack([s * np.cos(p), s * np.sin(p), m], axis=1)
    views = np.radians(np.asarray(ALBEDO_VIEWS_DEG))
    wo1 = np.stack([np.sin(views), np.zeros_like(views), np.cos(views)], axis=1)
    wi = np.tile(wi1, (len(views), 1))
    wo = np.repeat(wo1, len(wi1), axis=0)
    weight = np.full(len(wi1), 2 * np.pi * (1.0 - cut) / len(wi1))  # solid angle per cell
    return wi, wo, weight


def albedo_directions() -> tuple[np.ndarray, np.ndarray]:
    """Direction pairs of :func:`albedo_error`: ``(wi, wo)``, (4 x 1152, 3) each.

    For each view of :data:`ALBEDO_VIEWS_DEG`, ``wi`` on a midpoint grid uniform in
    ``cos theta_i`` (24 rows down to :data:`CUT_DEG`) and ``phi`` (48 columns).
    """
    wi, wo, _ = _albedo_grid()
    return wi.copy(), wo.copy()


def albedo_error(f_target: np.ndarray, f_model: np.ndarray) -> float:
    """RMS over views and channels of the relative difference of directional albedos.

    ``a(wo) = integral of f cos_i dwi`` over ``theta_i < CUT_DEG`` (midpoint rule), at
    :func:`albedo_directions`; f (N, 3) in 1/sr. A model albedo below 1e-6 counts as
    1e-6 (black). This is what a render under an environment shows (the satin fit's
    principled export matched f cos to 1% yet its albedo was off by +13/-9/-8%).
    """
    wi, _, weight = _albedo_grid()
    n_views = len(ALBEDO_VIEWS_DEG)
    c = (wi[:, 2] * np.tile(weight, n_views))[:, None]
    a_t = (f_target * c).reshape(n_views, -1, 3).sum(axis=1)
    a_m = (f_model * c).reshape(n_views, -1, 3).sum(axis=1)
    return float(np.sqrt(np.mean(((a_t - a_m) / np.maximum(np.abs(a_m), 1e-6)) ** 2)))


def relative_rms(f_target: np.ndarray, f_model: np.ndarray, cos_i: np.ndarray) -> float:
    """Relative RMS of ``f cos_i``: ``sqrt(sum ((ft - fm) cos_i)^2 / sum (fm cos_i)^2)``.

    Arguments: ``f_target`` and ``f_model`` (N, 3) in 1/sr; ``cos_i`` (N,) the cosine of
    the light direction. The denominator is at least ``n BLACK^2`` (``n`` values,
    :data:`BLACK`): for a black model the error is the RMS difference over ``BLACK``.
    """
    num = np.sum(((f_target - f_model) * cos_i[:, None]) ** 2)
    den = np.sum((f_model * cos_i[:, None]) ** 2)
    return float(np.sqrt(num / max(den, f_model.size * BLACK**2)))


def log_rms(f_target: np.ndarray, f_model: np.ndarray, cos_i: np.ndarray) -> float:
    """RMS over samples and channels of ``ln(1 + f_target cos_i) - ln(1 + f_model cos_i)``.

    Arguments as :func:`relative_rms`; f in 1/sr, so the log compresses values above ~1.
    """
    c = cos_i[:, None]
    return float(np.sqrt(np.mean((np.log1p(f_target * c) - np.log1p(f_model * c)) ** 2)))


@dataclass(frozen=True)
class Slot:
    """One parameter of a family: name, size (1 scalar, 3 RGB) and box bounds."""

    name: str
    size: int
    lower: float
    upper: float


@dataclass(frozen=True, eq=False)
class Family:
    """A renderer's material with free parameters (``slots``) and its evaluation.

    ``evaluate(params, wi, wo)`` returns f (N, 3) in 1/sr, brdffit's convention;
    ``params`` maps each slot name to a float (size 1) or an array (3,). ``build(params)``
    returns the target's material (a Mitsuba dict, a glTF material, OpenPBR inputs).
    """

    name: str
    slots: tuple[Slot, ...]
    evaluate: Evaluate
    build: Callable[[Mapping[str, object]], dict]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of the flat vector :meth:`pack` makes."""
        lo = np.concatenate([np.full(s.size, s.lower) for s in self.slots])
        hi = np.concatenate([np.full(s.size, s.upper) for s in self.slots])
        return lo, hi

    def pack(self, params: Mapping[str, object]) -> np.ndarray:
        """Slot values -> one flat vector, clipped into the bounds."""
        x = np.concatenate([np.broadcast_to(params[s.name], (s.size,)) for s in self.slots])
        return np.clip(x.astype(float), *self.bounds())

    def unpack(self, x: np.ndarray) -> dict[str, object]:
        """Flat vector -> slot values (floats for scalars, arrays (3,) for colours)."""
        out: dict[str, object] = {}
        i = 0
        for s in self.slots:
            out[s.name] = float(x[i]) if s.size == 1 else np.array(x[i : i + s.size])
            i += s.size
        return out


@dataclass(frozen=True, eq=False)
class Match:
    """A family's parameters chosen for a model and their measured errors.

    ``error`` (:func:`relative_rms`) and ``log_error`` (:func:`log_rms`) at
    :func:`error_directions`; ``fitted``: least squares moved the closed-form start;
    ``start_error``: the relative error of that start; ``albedo_error``
    (:func:`albedo_error`, 0 when not measured).
    """

    family: Family
    params: dict[str, object]
    error: float
    log_error: float
    start_error: float
    fitted: bool
    albedo_error: float = 0.0

    @property
    def score(self) -> float:
        """What candidates are ranked by: ``log_error + albedo_error``."""
        return self.log_error + self.albedo_error

    @property
    def exact(self) -> bool:
        """Measured error at float64 round-off: the target reproduces the model."""
        return self.error <= EXACT_TOL


def match(
    family: Family,
    start: Mapping[str, object],
    f_model: np.ndarray,
    wi: np.ndarray,
    wo: np.ndarray,
    *,
    fit: bool = True,
    max_nfev: int = 20,
    stride: int = 3,
    albedo: np.ndarray | None = None,
) -> Match:
    """Closed-form ``start``, kept if exact, else refined by bounded least squares.

    Arguments: ``family``; ``start`` its slot values (clipped into the bounds);
    ``f_model`` (N, 3) the model at ``wi``, ``wo`` (:func:`error_directions`); ``fit``
    False returns the start as it is; ``max_nfev`` the least-squares evaluation budget
    per free scalar; ``stride``: least squares sees every ``stride``-th pair (for speed),
    the errors are measured at all of them. The residuals are those of :func:`log_rms`.
    ``albedo``: the model at :func:`albedo_directions` (N, 3), to measure
    :attr:`Match.albedo_error`.
    """
    cos_i = wi[:, 2]
    a_wi, a_wo = albedo_directions() if albedo is not None else (None, None)

    def albedo_of(params: dict[str, object]) -> float:
        if albedo is None:
            return 0.0
        return albedo_error(family.evaluate(params, a_wi, a_wo), albedo)

    def measured(params: dict[str, object]) -> tuple[float, float]:
        f = family.evaluate(params, wi, wo)
        return relative_rms(f, f_model, cos_i), log_rms(f, f_model, cos_i)

    x0 = family.pack(start)
    p0 = family.unpack(x0)
    e0, l0 = measured(p0)
    if e0 <= EXACT_TOL or not fit:
        return Match(family, p0, e0, l0, e0, False, albedo_of(p0))
    wi_s, wo_s = wi[::stride], wo[::stride]
    c_s = wi_s[:, 2:3]
    target = np.log1p(f_model[::stride] * c_s)

    def residuals(x: np.ndarray) -> np.ndarray:
        f = family.evaluate(family.unpack(x), wi_s, wo_s)
        return np.ravel(np.log1p(f * c_s) - target)

    lo, hi = family.bounds()
    with np.errstate(all="ignore"):  # finite differences may step onto a bound's edge
        sol = least_squares(
            residuals,
            x0,
            bounds=(lo, hi),
            x_scale="jac",
            max_nfev=max_nfev * x0.size,
            # lsmr, not the default dense SVD: LAPACK's threaded SVD of this tall J ran
            # 300x slower on a loaded 2-core machine; the fits are unchanged
            tr_solver="lsmr",
        )
    p1 = family.unpack(np.clip(sol.x, lo, hi))
    e1, l1 = measured(p1)
    if np.isfinite(l1) and l1 < l0:
        return Match(family, p1, e1, l1, e0, True, albedo_of(p1))
    return Match(family, p0, e0, l0, e0, False, albedo_of(p0))


def best(matches: list[Match]) -> Match:
    """The match with the least :attr:`Match.score`: the log error least squares
    minimised, which weighs the peak's shape, plus the albedo error a render under an
    environment shows (on the satin walter fit the form with the least log error,
    principled, rendered with env rel RMSE 0.188 against the measurement, the one
    with the least score 0.131)."""
    return min(matches, key=lambda m: m.score)


def first_of(p: Mapping[str, np.ndarray], names: tuple[str, ...], default: object) -> object:
    """The value in ``p`` of the first of ``names`` it holds, else ``default``."""
    return next((p[n] for n in names if n in p), default)


def generic_alpha(p: Mapping[str, np.ndarray]) -> float:
    """A microfacet alpha to start from: the model's own ``alpha`` or ``m``, else the
    Beckmann-equivalent ``sqrt(2 / (n + 2))`` of a Phong-type exponent ``n``, else 0.2."""
    found = first_of(p, ("alpha", "alpha_1", "m", "m_1", "sigma"), None)
    if found is not None:
        return float(np.mean(found))
    n = first_of(p, ("n", "n_1"), None)
    return float(np.sqrt(2.0 / (float(n) + 2.0))) if n is not None else 0.2


def walter_lobes(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[tuple]:
    """Each specular lobe of a walter fit as ``(alpha_x, alpha_y, ks, f0)`` (``ks`` RGB, ones
    without the specular weight), in the model's order; ``p`` has RGB parameters."""
    out = []
    for k in range(1, model.n_lobes + 1):
        s = model.suffix(k)
        ax, ay = (
            (p[f"alpha_x{s}"], p[f"alpha_y{s}"]) if model.anisotropic else (p[f"alpha{s}"],) * 2
        )
        out.append((float(ax), float(ay), np.asarray(p.get(f"ks{s}", np.ones(3))), p[f"f0{s}"]))
    return out
