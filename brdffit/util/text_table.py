"""Rendering a table (a header row and rows of text cells) as aligned text, Markdown, CSV
or HTML."""

from __future__ import annotations

import csv
import html
import io
import re
from collections.abc import Sequence

from brdffit.errors import ParameterError

FORMATS = ("text", "markdown", "csv", "html")

_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?%?|[+-]?(nan|inf)", re.IGNORECASE)
_RIGHT = ' style="text-align:right"'


def render(head: Sequence[str], body: Sequence[Sequence[str]], fmt: str = "markdown") -> str:
    """``head`` and ``body`` as ``"text"`` (left-aligned columns), ``"markdown"``, ``"csv"``
    or ``"html"``.

    Every format ends with a newline; CSV lines end with ``\\n``. HTML is one ``<table>``
    with a ``<thead>`` and a ``<tbody>``, every cell escaped (:func:`html.escape`), no
    style sheet: numeric-looking cells (:func:`is_numeric`: ``-1.5e-3``, ``2.00%``,
    ``nan``) are right-aligned by an inline style, and so is a header cell whose column
    holds only such cells.
    """
    rows = [list(head), *(list(b) for b in body)]
    if fmt == "csv":
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerows(rows)
        return buf.getvalue()
    if fmt == "markdown":
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        return "\n".join(lines + ["| " + " | ".join(b) + " |" for b in rows[1:]]) + "\n"
    if fmt == "html":
        return _html(rows[0], rows[1:])
    if fmt != "text":
        raise ParameterError(f"fmt={fmt!r}: use one of {', '.join(FORMATS)}")
    widths = [max(len(x) for x in col) for col in zip(*rows, strict=True)]
    line = "  ".join(f"{{:<{w}}}" for w in widths)
    return "\n".join(line.format(*r).rstrip() for r in rows) + "\n"


def is_numeric(cell: str) -> bool:
    """True for a cell that reads as one number: ``3``, ``-1.5e-03``, ``2.00%``, ``nan``."""
    return _NUMBER.fullmatch(cell.strip()) is not None


def _html(head: list[str], body: list[list[str]]) -> str:
    def cell(tag: str, text: str, right: bool) -> str:
        return f"<{tag}{_RIGHT if right else ''}>{html.escape(text)}</{tag}>"

    def numeric_column(j: int) -> bool:
        cells = [r[j] for r in body if j < len(r) and r[j].strip()]
        return bool(cells) and all(is_numeric(c) for c in cells)

    right = [numeric_column(j) for j in range(len(head))]
    lines = ["<table>", "<thead>"]
    lines.append(
        "<tr>" + "".join(cell("th", h, n) for h, n in zip(head, right, strict=True)) + "</tr>"
    )
    lines += ["</thead>", "<tbody>"]
    lines += ["<tr>" + "".join(cell("td", c, is_numeric(c)) for c in r) + "</tr>" for r in body]
    return "\n".join([*lines, "</tbody>", "</table>"]) + "\n"
