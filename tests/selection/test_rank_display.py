"""A ranking shown in Jupyter and at a prompt: ``table("html")`` / ``_repr_html_`` is one
escaped table row per model in rank order with the cells of the other formats, the notes
in small text; ``str`` is the text table, ``repr`` one line. Results are built from JSON
dicts: no fit runs."""

from __future__ import annotations

import csv
import io

import pytest

from brdffit import FitResult, rank
from brdffit.selection.rank import NOTE, PER_SAMPLE, TIES
from tests.html_tables import parse, tables, text


def _result(model: str, loss: float, aic: float, status: str = "CONVERGED", **options):
    return FitResult.from_dict(
        {
            "model": model, "options": options, "metric": "low_e2",
            "params": {"kd": [0.1, 0.2, 0.3]}, "loss": loss, "aic": aic, "bic": aic + 5.0,
            "status": status, "source": "<b>& data", "n_data": 300, "n_samples": 100,
            "n_free": 3, "wall_time": 1.5,
        }
    )  # fmt: skip


@pytest.fixture(scope="module")
def results() -> list[FitResult]:
    return [
        _result("lambert", 3.0, -10.0),
        _result("walter", 1.0, -30.0, distribution="beckmann"),
        _result("oren_nayar", 2.0, -5.0, "MAX_STEPS"),
        _result("blinn_phong", float("nan"), float("nan"), "NONFINITE"),
    ]


@pytest.mark.parametrize(
    ("by", "order"),
    [
        ("loss", ["walter", "oren_nayar", "lambert", "blinn_phong"]),
        ("aic", ["walter", "lambert", "oren_nayar", "blinn_phong"]),
    ],
)
def test_one_html_row_per_model_in_rank_order(results, by, order):
    ranking = rank(results, by=by)
    markup = ranking._repr_html_()
    assert markup == ranking.table("html")
    (t,) = tables(markup)
    assert t.column("model") == order == [r.model for r in ranking.rows]
    assert t.column("rank") == ["1", "2", "3", "4"]
    # the same head and cells as the CSV form
    assert [t.head, *t.body] == list(csv.reader(io.StringIO(ranking.table("csv"))))
    assert t.row("1")[1:3] == ["walter", "distribution=beckmann"]
    converged = dict(zip(t.column("model"), t.column("converged"), strict=True))
    assert converged["oren_nayar"] == "NO (MAX_STEPS)" and converged["lambert"] == "yes"
    assert t.head_right[t.head.index("AIC")] and not t.head_right[t.head.index("model")]


def test_html_title_is_bold_and_escaped_and_the_notes_small(results):
    markup = rank(results).table("html")
    p = parse(markup)
    assert "Ranking by loss on <b>& data (metric low_e2, n = 300)" in text(markup)
    assert "&lt;b&gt;&amp; data" in markup and "<b>& data" not in markup
    assert p.tags.count("b") == 1 and p.tags.count("small") == 1
    small = markup.split("<small>")[1].split("</small>")[0]
    assert text(small) == f"{TIES}{PER_SAMPLE}{NOTE}"  # the three notes, one per line
    assert small.count("<br>") == 2


def test_str_is_the_text_table_repr_one_line_and_ipython_shows_the_table(results):
    ranking = rank(results)
    assert str(ranking) == ranking.table()
    assert repr(ranking) == "<Ranking by loss on <b>& data (low_e2): 4 models, best walter>"
    pretty = pytest.importorskip("IPython.lib.pretty")
    assert pretty.pretty(ranking) == ranking.table()
