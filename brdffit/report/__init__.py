"""Reports: what people read and look at, made from fits and sweep folders.

Modules: ``figures`` (lit spheres, in-plane curves, theta_h x theta_d images, slices of
data against fits), ``lookup`` (the fit and the data at any directions: model evaluation,
nearest-bin lookup, slices, in-plane directions), ``render`` (sphere set-up, lightings,
tone map),
``posterior_figures`` (a posterior's corner plot, walker traces, intervals beside the LM
ones, predictive band), ``selection_figures`` (a sweep's rank matrix and Pareto plot),
``sweep_sections`` (a sweep report's tables and figures per metric, for both writers),
``markdown`` (the Markdown sweep report, :func:`write_report`), ``html`` (the one-file
HTML report of a fit, :func:`write_fit_html`, and the blocks it shares) and
``sweep_html`` (that of a sweep, :func:`write_sweep_html`).
"""

from brdffit.report.figures import halfdiff_figure, plot_slices, polar_figure, sphere_figure
from brdffit.report.html import write_fit_html
from brdffit.report.markdown import write_report
from brdffit.report.posterior_figures import (
    corner_figure,
    interval_figure,
    predictive_figure,
    trace_figure,
)
from brdffit.report.selection_figures import pareto_figure, rank_matrix_figure
from brdffit.report.sweep_html import write_sweep_html

__all__ = [
    "corner_figure",
    "halfdiff_figure",
    "interval_figure",
    "pareto_figure",
    "plot_slices",
    "polar_figure",
    "predictive_figure",
    "rank_matrix_figure",
    "sphere_figure",
    "trace_figure",
    "write_fit_html",
    "write_report",
    "write_sweep_html",
]
