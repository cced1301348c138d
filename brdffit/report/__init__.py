"""Reports: what people read and look at, made from fits and sweep folders.

Modules: ``figures`` (lit spheres, in-plane curves, theta_h x theta_d images, slices of
data against fits), ``render`` (sphere set-up, lightings, nearest-bin lookup, tone map),
``selection_figures`` (a sweep's rank matrix and Pareto plot),
``sweep_sections`` (a sweep report's tables and figures per metric, for both writers),
``markdown`` (the Markdown sweep report, :func:`write_report`) and ``html`` (one-file
HTML reports of a fit and of a sweep, :func:`write_fit_html`, :func:`write_sweep_html`).
"""

from brdffit.report.html import write_fit_html, write_sweep_html
from brdffit.report.markdown import write_report

__all__ = ["write_fit_html", "write_report", "write_sweep_html"]
