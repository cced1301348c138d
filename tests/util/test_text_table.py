"""Tables as text, Markdown, CSV and HTML (brdffit.util.text_table.render): the HTML form
is one escaped table whose cells read back unchanged, numbers right-aligned."""

from __future__ import annotations

import csv
import io

import pytest

from brdffit.errors import ParameterError
from brdffit.util.text_table import FORMATS, is_numeric, render
from tests.html_tables import parse, tables

HEAD = ["model", "loss", "rel. error", "note"]
BODY = [
    ["walter <ggx>", "1.25e-03", "2.00%", "a & b \"quoted\" 'single'"],
    ["lambert", "-0.5", "nan", ""],
    ["<script>alert(1)</script>", "12", "inf", "x < y > z"],
]


def test_html_is_one_table_with_head_and_body_and_cells_read_back_unchanged():
    out = render(HEAD, BODY, "html")
    assert out.startswith("<table>\n<thead>\n") and out.endswith("</tbody>\n</table>\n")
    p = parse(out)
    assert [t for t in p.tags if t in ("table", "thead", "tbody")] == ["table", "thead", "tbody"]
    (t,) = p.tables
    assert t.head == HEAD and t.body == BODY  # html.escape'd, unescaped by the parser


def test_html_escapes_every_cell():
    out = render(HEAD, BODY, "html")
    assert "<script>" not in out and "&lt;script&gt;alert(1)&lt;/script&gt;" in out
    assert "walter &lt;ggx&gt;" in out and "a &amp; b &quot;quoted&quot; &#x27;single&#x27;" in out
    assert "x &lt; y &gt; z" in out
    assert "<style" not in out and "<link" not in out and "class=" not in out  # no CSS


def test_html_right_aligns_numeric_cells_and_the_headers_of_numeric_columns():
    (t,) = tables(render(HEAD, BODY, "html"))
    assert t.right == [[False, True, True, False]] * 3
    # loss and rel. error hold numbers only; "note" holds text (its empty cell is no number)
    assert t.head_right == [False, True, True, False]
    (only_empty,) = tables(render(["a"], [[""]], "html"))
    assert only_empty.head_right == [False] and only_empty.right == [[False]]


@pytest.mark.parametrize(
    ("cell", "numeric"),
    [
        ("3", True), ("-1.5e-03", True), ("+0.9976", True), ("2.00%", True), (".5", True),
        ("nan", True), ("-inf", True), ("1.2e+03", True), (" 7 ", True),
        ("", False), ("yes", False), ("NO (MAX_STEPS)", False), ("0.3 +/- 0.01", False),
        ("kd[r]", False), ("1.5 s", False), ("(frozen)", False), ("e5", False),
    ],
)  # fmt: skip
def test_is_numeric(cell, numeric):
    assert is_numeric(cell) is numeric


def test_every_format_is_listed_and_others_are_refused():
    assert FORMATS == ("text", "markdown", "csv", "html")
    for fmt in FORMATS:
        assert render(HEAD, BODY, fmt).endswith("\n")
    with pytest.raises(ParameterError, match="html"):
        render(HEAD, BODY, "latex")


def test_the_other_formats_are_unchanged():
    assert list(csv.reader(io.StringIO(render(HEAD, BODY, "csv")))) == [HEAD, *BODY]
    md = render(["a", "b"], [["1", "x"]], "markdown")
    assert md == "| a | b |\n|---|---|\n| 1 | x |\n"
    assert render(["a", "bb"], [["123", "x"]], "text") == "a    bb\n123  x\n"
