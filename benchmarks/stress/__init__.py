"""Numerical-stability stress suite: fits on synthetic data in hard regimes, from random starts.

A *case* is one model, one metric and one :class:`Regime`. For each case the truth is
drawn from the model's baseline parameters (:data:`ROLES`, jittered with the case's
seed) and changed as the regime says; the data are synthesised from it; then the model
is fitted once from the truth (the *reference*) and from ``n_starts`` seeded random
starts (``init=`` a random natural point, ``n_restarts=0``; the fit's own screen of
spread candidates still adds its starts, as it does in use, seeded with the start's
number so that the screen too differs from start to start).

**Recovery.** A start is recovered when its fit is finite, converged (``Status.CONVERGED``)
and its final objective ``J`` (``0.5 sum rho(r)^2``, what LM minimises: the metric's
residuals, robust ones when the regime fits with a robust loss, all at one robust scale)
lies within ``REL_TOL J_best + ABS_TOL J_0`` of the best ``J_best`` over the reference,
every start and the truth itself (``truth_objective``: a fit that ends above the truth's
own objective has missed the truth's basin, whatever the other fits did); ``J_0`` is the
objective of the zero BRDF (the data's own energy), so the floor only matters for
noise-free data, where ``J_best`` is ~0. Every other end is a
failure with its reason: the solver status (``MAX_STEPS``, with whether ``J`` was already
within the tolerance, ``SOLVER_FAILED``, ``NONFINITE``), ``wrong minimum`` (converged, but
``J`` above the tolerance), ``stalled next to the minimum`` (the same, within
``STALL_DISTANCE`` of the best point in the optimiser space: the descent stopped early),
``silent non-finite`` (a NaN or Inf in the loss or parameters of a fit that did not say
so: a bug), or the exception raised. A failure's *excess* is
``(J - J_best) / max(J_best, ABS_TOL J_0)``.

**Identifiable.** The recovery target applies to cases identifiable in principle. A case
is not when :data:`NOT_IDENTIFIABLE` says so, or when its data are corrupted (noise,
outliers) and the minimum of the truth's basin is not the lowest: such a case also gets
a ``local`` fit, a plain descent from the truth (``screen=0``), and when that converges
to a distinct minimum above the best, the corruption decides which of several minima is
lowest, and none of them is the material's (:func:`_optimum_moved`). The reference is
no test of that: its screen's starts can leave the basin. On noise-free data the truth
is an exact minimum, so a failed reference there stays a failure.

**Data.** Every regime gives exactly ``n_samples`` fitted samples (valid and inside the
cut), so one compiled fit serves every regime of a model and metric. Directions are
random in Rusinkiewicz coordinates with MERL's density (``theta_h = (pi/2) u^2``, ``u``,
``theta_d``, ``phi_d`` and ``phi_h`` uniform: 2.5% of the samples have ``theta_h < 1e-3``,
so a near-mirror peak is sampled) or, for the grazing regimes, each direction with
probability 0.8 in ``theta > 60`` degrees. Weights are the Monte Carlo solid-angle measure
``dwi dwo`` of each sample (the Ngan metric uses them).

**Roughness.** :data:`ROLES` names per model the parameter that sets the lobe width and
how it maps a roughness ``r`` (GGX/Beckmann ``alpha`` units): ``width`` (the parameter is
``r``), ``squared`` (``alpha = x^2``: ``x = sqrt(r)``; Brady's ``tan theta_h`` scale is
``beta^2`` too), ``exponent`` (Phong-type ``cos^n``: ``n = 2 / r^2``; near-mirror draws
``n`` log-uniformly in ``EXPONENT_RANGE``), ``sigma`` (Oren-Nayar's facet slope; no
specular lobe). A regime that has no meaning for a model (near-mirror Lambert) is
*not applicable*: it is listed, never run.

Results are one JSON file per case, ``<out>/<model>__<metric>__<regime>.json``, written
atomically: an interrupted run resumes and skips finished cases.
"""

from .cases import (
    CaseSpec,
    case_seed,
    case_spec,
    case_start,
    fitter_version,
    inject_outliers,
    make_data,
    not_applicable,
    random_start,
    sample_directions,
)
from .files import case_path, is_finished, load_results, write_case
from .regimes import (
    ABS_TOL,
    DEFAULT_METRICS,
    MAX_STEPS,
    N_SAMPLES,
    N_STARTS,
    NOT_IDENTIFIABLE,
    RECOVERY_TARGET,
    REGIMES,
    REL_TOL,
    ROLES,
    Regime,
    Roles,
)
from .scoring import case_fit, corrupts, objective, rescore, run_case, score, zero_objective
from .suite import format_matrix, format_table, run_suite, summary

__all__ = [
    "ABS_TOL", "DEFAULT_METRICS", "MAX_STEPS", "N_SAMPLES", "N_STARTS", "NOT_IDENTIFIABLE",
    "RECOVERY_TARGET", "REGIMES", "REL_TOL", "ROLES", "CaseSpec", "Regime", "Roles",
    "case_fit", "case_path", "case_seed", "case_spec", "case_start", "corrupts",
    "fitter_version", "format_matrix", "format_table", "inject_outliers", "is_finished",
    "load_results", "make_data", "not_applicable", "objective", "random_start", "rescore",
    "run_case", "run_suite", "sample_directions", "score", "summary", "write_case",
    "zero_objective",
]  # fmt: skip
