"""Model selection: which model, and which of its features, the data support.

Modules: ``rank`` (models fitted to one data set, ranked by the metric, AIC and BIC),
``sweep_results`` (a sweep folder's results read back), ``crossrank`` (ranking over many
materials, with bootstrap intervals), ``pareto`` (fit error against run time, the Pareto
front), ``families`` (material families), ``variants`` (the variants one move simpler
than a model), ``variant_fit`` (one variant fitted on all data and every fold, scored),
``folds`` (cross-validation folds and the held-out test), ``simplify`` (the greedy
backward search, :func:`brdffit.simplify`), ``reduction`` (what it found), ``survival``
(which features survive reduction over a sweep).
"""

from brdffit.selection.crossrank import aggregate, aggregate_table, matrices
from brdffit.selection.pareto import error_vs_time, pareto_table
from brdffit.selection.rank import Ranking, rank
from brdffit.selection.reduction import Reduction
from brdffit.selection.simplify import simplify
from brdffit.selection.sweep_results import load_sweep

__all__ = [
    "Ranking",
    "Reduction",
    "aggregate",
    "aggregate_table",
    "error_vs_time",
    "load_sweep",
    "matrices",
    "pareto_table",
    "rank",
    "simplify",
]
