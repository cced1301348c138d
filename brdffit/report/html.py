"""One self-contained HTML file per fit: tables and figures, nothing external; and the
building blocks the sweep page (:mod:`brdffit.report.sweep_html`) shares.

Every figure is embedded as a base64 PNG (``data:`` URI) and the style sheet is inline,
so the file opens anywhere, offline, and can be mailed as it is. Files are written
atomically (:mod:`brdffit.util.atomic`).

* :func:`write_fit_html`: the fit's statistics (metric and its value, every other
  metric, noise model, status, steps, samples), its parameters as value +/- standard
  error with start values and flags, its warnings, and the three figures of
  :mod:`brdffit.report.figures` (lit spheres, in-plane curves, theta_h x theta_d images).
* :func:`brdffit.report.sweep_html.write_sweep_html`: the sweep's page, from the same
  blocks (:func:`html_table`, :func:`png_data_uri`, the page and its style).
"""

from __future__ import annotations

import base64
import csv
import html
import io
import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from brdffit.core.measurements import Measurements
from brdffit.core.result import FitResult
from brdffit.core.result_terms import errors_assumed
from brdffit.errors import MeasurementsError
from brdffit.export import ERROR_DEFINITION, Export
from brdffit.report import figures
from brdffit.util.atomic import write_text

STYLE = """
body { font: 14px/1.45 system-ui, sans-serif; margin: 1.5em auto; max-width: 1250px;
       padding: 0 1em; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.25em; border-bottom: 1px solid #ccc; }
h3 { font-size: 1.05em; }
table { border-collapse: collapse; margin: 0.6em 0 1.2em; font-size: 13px; max-width: 100%; }
th, td { border: 1px solid #ccc; padding: 2px 8px; text-align: left; overflow-wrap: anywhere; }
th { background: #eef1f5; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
tr:nth-child(even) td { background: #fafafa; }
img { max-width: 100%; height: auto; display: block; margin: 0.3em 0; }
figure { margin: 0.8em 0 1.6em; } figcaption { font-size: 12px; color: #555; }
pre { background: #f6f6f6; padding: 0.6em; font-size: 12px; white-space: pre-wrap;
      overflow-wrap: anywhere; }
.warn { color: #a33; } .note { color: #555; font-size: 13px; }
"""


# --------------------------------------------------------------------------- building blocks


def png_data_uri(fig: object, dpi: int = 90) -> str:
    """A matplotlib figure as a ``data:image/png;base64,...`` URI. The report's figures are
    not registered with pyplot (:mod:`brdffit.report.figures`): nothing to close."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight", pad_inches=0.1)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _figure(fig: object, alt: str, caption: str) -> str:
    return (
        f'<figure><img alt="{html.escape(alt)}" src="{png_data_uri(fig)}">'
        f"<figcaption>{html.escape(caption)}</figcaption></figure>"
    )


def figure_or_note(fig: object | None, note: str, alt: str, caption: str) -> str:
    """The figure, or where there is none (:class:`~brdffit.report.sweep_sections.MetricSection`)
    the note saying why."""
    if fig is None:
        return f'<p class="note">{html.escape(note)}</p>'
    return _figure(fig, alt, caption)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def html_table(head: Sequence[str] | None, rows: Sequence[Sequence[str]]) -> str:
    """An HTML table of text cells (escaped); numeric cells are right-aligned.

    With ``head=None``: a key/value table, no header row, the first column as ``th``.
    """

    def row(r: Sequence[str]) -> str:
        if head is None:
            return (
                f"<tr><th>{html.escape(str(r[0]))}</th>"
                + "".join(f"<td>{html.escape(str(c))}</td>" for c in r[1:])
                + "</tr>"
            )
        num = ' class="num"'
        cells = (f"<td{num if _is_number(str(c)) else ''}>{html.escape(str(c))}</td>" for c in r)
        return "<tr>" + "".join(cells) + "</tr>"

    th = "" if head is None else "".join(f"<th>{html.escape(h)}</th>" for h in head)
    thead = f"<thead><tr>{th}</tr></thead>" if head is not None else ""
    return f"<table>{thead}<tbody>{''.join(row(r) for r in rows)}</tbody></table>"


def table_from_csv(text: str) -> str:
    rows = list(csv.reader(io.StringIO(text)))
    return html_table(rows[0], rows[1:]) if rows else ""


def table_from_markdown(text: str) -> str:
    """A table of :func:`brdffit.util.text_table.render` in Markdown (cells hold no ``|``)
    as HTML."""
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    rows = [[c.strip() for c in ln.strip("|").split("|")] for ln in lines]
    return html_table(rows[0], rows[2:]) if rows else ""


def page(title: str, body: list[str]) -> str:
    return (
        "<!DOCTYPE html>\n"
        f'<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
        f"<style>{STYLE}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n"
    )


def write_page(path: str | os.PathLike[str], text: str) -> Path:
    try:
        write_text(path, text)
    except OSError as e:
        raise OSError(f"{path}: cannot be written: {e.strerror or e}") from e
    return Path(path)


# --------------------------------------------------------------------------- one fit


def _fmt(x: float, spec: str = ".6g") -> str:
    return format(x, spec) if math.isfinite(x) else "n/a"


def _parameter_rows(result: FitResult) -> list[list[str]]:
    """One row per scalar: value, standard error, relative error, start, flags."""
    rows = []
    for name, value in result.params.items():
        flat = np.atleast_1d(np.asarray(value, float))
        init = np.atleast_1d(np.asarray(result.init_params.get(name, np.nan), float))
        init = np.broadcast_to(init, flat.shape)
        err = None if result.stderr is None else np.atleast_1d(result.stderr[name])
        for c, v in enumerate(flat):
            label = name if flat.size == 1 else f"{name}[{'rgb'[c]}]"
            flags = []
            if name in result.frozen:
                flags.append("frozen")
                e_txt, rel = "", ""
            else:
                e = float(err[c]) if err is not None else math.nan
                e_txt = _fmt(e, ".3g") if err is not None else "none"
                rel = f"{abs(e / v) * 100:.3g}%" if v != 0 and math.isfinite(e) else "n/a"
                if label in result.at_bound:
                    flags.append("at bound")
                if label in result.not_identified:
                    flags.append("not identified")
                if np.isclose(v, init[c], rtol=1e-9, atol=0):
                    flags.append("did not move")
            rows.append([label, _fmt(float(v)), e_txt, rel, _fmt(float(init[c]), ".4g")])
            rows[-1].append(", ".join(flags))
    return rows


def _fit_statistics(result: FitResult) -> list[list[str]]:

    opts = ", ".join(f"{k}={v!r}" for k, v in result.options.items()) or "defaults"
    cut = "none" if result.cut_deg is None else f"theta_i, theta_o < {result.cut_deg:g} deg"
    others = ", ".join(f"{k} {_fmt(v)}" for k, v in result.losses.items() if k != result.metric)
    return [
        ["model", f"{result.model} ({opts})"],
        ["data", result.source],
        [f"metric {result.metric}", _fmt(result.loss)],
        ["other metrics (same samples)", others or "none"],
        ["fit's angle cut", cut],
        [
            "noise model",
            errors_assumed(result.errors_method, result.error_blocks, result.error_dof),
        ],
        ["status", result.status.value],
        ["steps", f"{result.n_steps} (best of {result.n_starts} starts)"],
        ["samples", f"{result.n_samples} ({result.n_data} residuals), {result.n_free} free"],
        ["AIC / BIC", f"{_fmt(result.aic)} / {_fmt(result.bic)} (n = residuals)"],
        ["wall time", f"{result.wall_time:.3g} s"],
    ]


def fit_html(
    result: FitResult,
    data: Measurements,
    *,
    title: str | None = None,
    sphere_size: int = 128,
    exports: Sequence[tuple[Export, Sequence[Path]]] = (),
) -> str:
    """The HTML text of :func:`write_fit_html` (arguments there)."""
    source = result.source.split(" (", 1)[0]  # readers describe a path as "NAME (PATH)"
    title = title or f"brdffit: {result.model} fitted to {Path(source).name or source}"
    body = [f"<h1>{html.escape(title)}</h1>", "<h2>Fit</h2>"]
    body.append(html_table(None, _fit_statistics(result)))
    body.append("<h2>Parameters</h2>")
    head = ["parameter", "value", "std. error", "rel. error", "start", "flags"]
    body.append(html_table(head, _parameter_rows(result)))
    if result.errors_reason:
        body.append(f'<p class="note">No uncertainties: {html.escape(result.errors_reason)}</p>')
    body += [f'<p class="warn">Warning: {html.escape(w)}</p>' for w in result.warnings]
    body.append("<h2>Figures</h2>")
    try:
        body += [
            _figure(
                figures.sphere_figure(result, data, size=sphere_size),
                "lit spheres",
                "Spheres from the data (nearest MERL bin; bins not measured filled from the "
                "nearest measured one) and from the fit, and their colour difference "
                "(CIEDE2000 as displayed; grey where the data were not measured; below it "
                "the mean colour ratio data / fit per channel), under a distant point "
                "light (top) and a sky/ground environment (bottom: bright sky above, dark "
                "ground below, so the band across each sphere's middle is the horizon the "
                "normals there face, not a seam). Tone map: exposure as printed, clipped, "
                "sRGB transfer curve.",
            ),
            _figure(
                figures.polar_figure(result, data),
                "in-plane BRDF",
                "In-plane BRDF f (1/sr, no cosine) against the viewing angle at several "
                "incidence angles: lines the fit, dots the data (nearest bin); data "
                "measured at or below 0, which a log axis cannot place, are orange "
                "triangles on the axis floor.",
            ),
            _figure(
                figures.halfdiff_figure(result, data),
                "theta_h x theta_d images",
                "log10 f of data and fit over theta_h (square-root axis) and theta_d at "
                "phi_d near 90 deg, and ln(data / fit), for the channel the fit misses "
                "most (the title gives all three). Grey: not measured; orange: measured at "
                "or below 0 (no logarithm; the title counts them).",
            ),
        ]
    except MeasurementsError as e:
        body.append(f'<p class="note">No figures: {html.escape(str(e))}</p>')
    if exports:
        body += _export_section(exports)
    body += ["<h2>Data</h2>", f"<pre>{html.escape(data.summary())}</pre>"]
    body += ["<h2>Text report</h2>", f"<pre>{html.escape(result.report())}</pre>"]
    return page(title, body)


def _export_section(exports: Sequence[tuple[Export, Sequence[Path]]]) -> list[str]:
    """The exports written beside the report: per target what was written, whether it is
    exact, its measured errors (:data:`brdffit.export.ERROR_DEFINITION`), the files,
    and each export's notes (what the target could not hold)."""
    head = ["target", "written as", "mapping", "rel. RMS error", "log error", "albedo error",
            "files"]  # fmt: skip
    rows = [
        [
            e.target,
            e.target_model,
            "exact" if e.exact else "approximate" + (" (fitted)" if e.fitted else ""),
            _fmt(e.error, ".3g"),
            _fmt(e.log_error, ".3g"),
            _fmt(e.albedo_error, ".3g"),
            ", ".join(Path(p).name for p in paths),
        ]
        for e, paths in exports
    ]
    out = ["<h2>Exports</h2>", html_table(head, rows)]
    out.append(f'<p class="note">{html.escape(ERROR_DEFINITION)}</p>')
    for e, _ in exports:
        out += [f'<p class="note">{html.escape(e.target)}: {html.escape(n)}</p>' for n in e.notes]
    return out


def write_fit_html(
    path: str | os.PathLike[str],
    result: FitResult,
    data: Measurements,
    *,
    title: str | None = None,
    sphere_size: int = 128,
    exports: Sequence[tuple[Export, Sequence[Path]]] = (),
) -> Path:
    """Write the one-file HTML report of a fit, atomically; returns its path.

    Arguments:
    - ``path``: the ``.html`` file (replaced if it exists).
    - ``result``: the fit; ``data``: the measurements it was fitted to (figures need them
      on the MERL grid or a strided sub-grid, else the report says why they are missing).
    - ``title``: page heading (default: model and data file).
    - ``sphere_size``: pixels per sphere side (:func:`brdffit.report.figures.sphere_figure`).
    - ``exports``: what :func:`brdffit.export.write_exports` returned for this fit, shown
      in an "Exports" section (target, form written, exact or not, errors, file names,
      notes).

    Raises ``OSError`` naming ``path`` when it cannot be written.
    """
    folder = Path(path).parent
    if not folder.is_dir():  # say so before the figures are drawn
        raise OSError(f"{path}: cannot be written: no folder {folder}")
    page = fit_html(result, data, title=title, sphere_size=sphere_size, exports=exports)
    return write_page(path, page)
