"""A fit's result shown in Jupyter and at a prompt: ``_repr_html_`` tables built from the
fields of ``report()`` (the same texts, one row per scalar, escaped), ``str`` the report,
``repr`` one line, IPython's text form the report."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from brdffit import FitResult, fit, models, synthesize
from brdffit.core.result_terms import value_cells, value_text
from brdffit.core.result_text import PARAMETER_HEAD, scalar_rows, statistics
from tests.html_tables import parse, tables, text


@pytest.fixture(scope="module")
def lambert_fit() -> FitResult:
    data = synthesize(
        models.get("lambert"), {"kd": [0.2, 0.3, 0.4]}, stride=(15, 15, 15), noise_mult=0.03, seed=0
    )
    return fit(models.get("lambert"), data, "low_e2", n_restarts=0, screen=0)


def _report_lines(r: FitResult) -> dict[str, str]:
    """Report lines of the parameters, by label."""
    lines = r.report().split("[[Parameters]]\n")[1].splitlines()
    return {x.split()[0]: x for x in lines if x.startswith("    ") and not x.startswith("    (")}


def _flagged(r: FitResult) -> FitResult:
    """``r`` with every flag: kd[r] at bound, kd[b] not identified and not moved, a warning
    and a source that must be escaped, an error reason, a correlation above 0.3."""
    kd = r.params["kd"]
    corr = np.eye(3)
    corr[0, 1] = corr[1, 0] = 0.5
    corr[0, 2] = corr[2, 0] = -0.1
    return dataclasses.replace(
        r,
        source="<b>& data",
        at_bound=("kd[r]",),
        not_identified=("kd[b]",),
        init_params={"kd": np.array([0.9, 0.9, kd[2]])},
        warnings=("one <warning> & more",),
        errors_reason="Jacobian <singular>",
        correlation=corr,
    )


def test_every_scalar_is_a_row_with_the_texts_of_the_report(lambert_fit):
    r = lambert_fit
    stats, params = tables(r._repr_html_())
    assert params.head == list(PARAMETER_HEAD)
    assert [row[0] for row in params.body] == ["kd[r]", "kd[g]", "kd[b]"] == list(r.labels)
    lines = _report_lines(r)
    for row in scalar_rows(r):
        value, err, rel, start, flags = params.row(row.label)[1:]
        # the cells are the pieces of the report's "value +/- error (relative %)"
        assert f"{value} +/- {err} ({rel}%)" == row.text == value_text(row.value, row.stderr)
        assert row.text in lines[row.label] and f"start {start}" in lines[row.label]
        assert float(value) == pytest.approx(r.params["kd"]["rgb".index(row.label[3])], rel=1e-5)
        assert flags == "" and "[" not in lines[row.label][20:]
    assert all(params.right[i][1:5] == [True] * 4 for i in range(3))  # numbers right-aligned
    # the statistics table holds the report's header lines, name and text alike
    assert [name for name, _ in stats.body] == [name for name, _ in statistics(r)]
    report = r.report().splitlines()
    for name, value in stats.body:
        assert f"    {name:<17}{value}" in report
    assert stats.row("metric")[1].startswith(f"low_e2 = {r.loss:.6g} (sum over {r.n_samples}")
    assert "per sample" in stats.row("metric")[1] and "Warning" not in text(r._repr_html_())


def test_flags_reason_correlations_and_warnings_match_the_report(lambert_fit):
    r = _flagged(lambert_fit)
    markup = r._repr_html_()
    stats, params, corr = tables(markup)
    lines = _report_lines(r)
    assert params.row("kd[r]")[5] == "at bound" and "[at bound]" in lines["kd[r]"]
    assert params.row("kd[g]")[5] == "" and "[" not in lines["kd[g]"][20:]
    assert params.row("kd[b]")[5] == "not identified, did not move"
    assert lines["kd[b]"].endswith("[not identified, did not move]")
    assert corr.head == ["parameter 1", "parameter 2", "C"]
    assert corr.body == [["kd[r]", "kd[g]", "+0.5000"]]  # |C| >= 0.3 only
    assert "C(kd[r], kd[g]) = +0.5000" in r.report() and "C(kd[r], kd[b])" not in r.report()
    shown = text(markup)
    assert "Fit: lambert() on <b>& data" in shown
    assert "(no uncertainties: Jacobian <singular>)" in shown
    assert "Warning: one <warning> & more" in shown
    # escaped: no tag from the data reaches the markup
    assert "&lt;b&gt;&amp; data" in markup and "<b>& data" not in markup
    assert "&lt;warning&gt; &amp; more" in markup and "&lt;singular&gt;" in markup
    assert [t for t in parse(markup).tags if t == "b"] == ["b", "b", "b"]  # title, 2 headings


def test_frozen_and_errorless_scalars_read_as_in_the_report(lambert_fit):
    frozen = dataclasses.replace(lambert_fit, frozen=("kd",))
    _, params = tables(frozen._repr_html_())
    for label, line in _report_lines(frozen).items():
        value, err, rel = params.row(label)[1:4]
        assert (err, rel) == ("(frozen)", "") and f"{value} (frozen)" in line
    none = dataclasses.replace(lambert_fit, stderr=None, errors_reason="no Jacobian")
    _, params = tables(none._repr_html_())
    assert params.column("± stderr") == ["(none)"] * 3 and params.column("relative %") == [""] * 3
    assert not any(params.right[i][2] for i in range(3))  # words are not numbers


@pytest.mark.parametrize(
    ("value", "err", "frozen", "at_bound", "cells"),
    [
        (0.5, 0.01, False, False, ("0.5", "0.01", "2.00")),
        (0.0, 0.01, False, False, ("0", "0.01", "")),
        (4.2e-18, float("nan"), False, True, ("0", "(at bound; no error)", "")),
        (0.3, float("nan"), False, False, ("0.3", "(no error)", "")),
        (0.5, None, False, False, ("0.5", "(none)", "")),
        (0.5, 0.01, True, False, ("0.5", "(frozen)", "")),
    ],
)
def test_value_cells_are_the_pieces_of_value_text(value, err, frozen, at_bound, cells):
    assert value_cells(value, err, frozen=frozen, at_bound=at_bound) == cells
    whole = value_text(value, err, frozen=frozen, at_bound=at_bound)
    assert whole.startswith(cells[0]) and cells[1] in whole and cells[2] in whole


def test_str_is_the_report_repr_one_line_and_ipython_shows_the_report(lambert_fit):
    r = lambert_fit
    assert str(r) == r.report() and str(_flagged(r)) == _flagged(r).report()
    line = repr(r)
    assert "\n" not in line and len(line) < 120
    assert line == (
        f"<FitResult lambert low_e2={r.loss:.4g} (per sample {r.loss_per_sample:.4g}), "
        f"3 free, CONVERGED>"
    )
    ngan = dataclasses.replace(r, metric="ngan", loss=0.05)
    assert repr(ngan) == "<FitResult lambert ngan=0.05, 3 free, CONVERGED>"  # RMS: per sample
    pretty = pytest.importorskip("IPython.lib.pretty")
    assert pretty.pretty(r) == r.report()
    # a result read back from JSON shows the same
    again = FitResult.from_dict(r.to_dict())
    assert again._repr_html_() == r._repr_html_() and repr(again) == repr(r)
