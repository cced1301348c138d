"""A model reduction shown in Jupyter and at a prompt: ``table("html")`` / ``_repr_html_``
is one escaped table row per path row with its decision, the choice in small text;
``str`` is the text table, ``repr`` one line. Built from path rows and JSON fits: no
search runs."""

from __future__ import annotations

import math

import pytest

from brdffit import FitResult, Reduction
from brdffit.selection.reduction import PathRow
from tests.html_tables import parse, tables, text

NAN = math.nan
PATH = (
    PathRow(0, "walter", "-", 10, 1.0, 2.0, NAN, NAN, "start"),
    PathRow(1, "walter[grey=ks]", "grey ks", 8, 1.01, 2.1, 1.05, 3.2, "kept"),
    PathRow(1, "walter[diffuse=false]", "diffuse=false", 7, 1.02, 2.01, 1.001, 0.4, "removed"),
    PathRow(1, "walter[grey=kd]", "grey kd", 8, 1.03, 2.05, 1.01, 1.1, "deferred"),
    PathRow(2, "walter[diffuse=false,grey=kd]", "grey kd", 5, 1.04, 2.02, 1.002, 0.2, "chosen"),
)


def _fit(model: str, loss: float, n_free: int, **options) -> FitResult:
    return FitResult.from_dict(
        {
            "model": model, "options": options, "metric": "low_e2",
            "params": {"ks": 0.6, "alpha": 0.15}, "loss": loss, "status": "CONVERGED",
            "source": "<b>& data", "n_free": n_free,
        }
    )  # fmt: skip


@pytest.fixture(scope="module")
def reduction() -> Reduction:
    return Reduction(
        path=PATH,
        chosen="walter[diffuse=false,grey=kd]",
        result=_fit("walter", 1.04, 5, diffuse=False),
        full=_fit("walter", 1.0, 10),
        cost_ratio=0.5,
        criterion="cv",
        folds=5,
        n_se=2.13,
        min_gain=0.01,
        metric="low_e2",
        source="<b>& data",
    )


def test_one_html_row_per_path_row_with_its_decision(reduction):
    markup = reduction._repr_html_()
    assert markup == reduction.table("html")
    (t,) = tables(markup)
    assert t.head == ["step", "variant", "change", "k", "low_e2", "held-out", "x best", "t",
                      "decision"]  # fmt: skip
    assert len(t.body) == len(PATH)
    for row, p in zip(t.body, PATH, strict=True):
        assert row[:4] == [str(p.step), p.label, p.change, str(p.n_free)]
        assert row[-1] == p.decision
    assert t.column("x best")[0] == "-" and t.column("t")[1:] == ["3.20", "0.40", "1.10", "0.20"]
    # the text table holds the same rows
    lines = reduction.table().splitlines()
    for row in t.body:
        assert any(line.split() == " ".join(row).split() for line in lines), row


def test_html_title_is_bold_and_escaped_and_the_choice_small(reduction):
    markup = reduction.table("html")
    shown = text(markup)
    assert "Simplify walter on <b>& data (metric low_e2; 5-fold CV" in shown
    assert "&lt;b&gt;&amp; data" in markup and "<b>& data" not in markup
    p = parse(markup)
    assert p.tags.count("b") == 1 and p.tags.count("small") == 1
    small = text(markup.split("<small>")[1].split("</small>")[0])
    assert small == reduction.table().splitlines()[-1]
    assert small.startswith("chosen: walter[diffuse=false,grey=kd] (5 of 10 parameters")


def test_str_is_the_text_table_repr_one_line_and_ipython_shows_the_table(reduction):
    assert str(reduction) == reduction.table()
    assert repr(reduction) == (
        "<Reduction walter -> walter[diffuse=false,grey=kd] by cv (5 variants fitted)>"
    )
    pretty = pytest.importorskip("IPython.lib.pretty")
    assert pretty.pretty(reduction) == reduction.table()
