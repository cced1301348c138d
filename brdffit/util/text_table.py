"""Rendering a table (a header row and rows of text cells) as aligned text, Markdown or CSV."""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence

from brdffit.errors import ParameterError

FORMATS = ("text", "markdown", "csv")


def render(head: Sequence[str], body: Sequence[Sequence[str]], fmt: str = "markdown") -> str:
    """``head`` and ``body`` as ``"text"`` (left-aligned columns), ``"markdown"`` or ``"csv"``.

    Every format ends with a newline; CSV lines end with ``\\n``.
    """
    rows = [list(head), *(list(b) for b in body)]
    if fmt == "csv":
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerows(rows)
        return buf.getvalue()
    if fmt == "markdown":
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        return "\n".join(lines + ["| " + " | ".join(b) + " |" for b in rows[1:]]) + "\n"
    if fmt != "text":
        raise ParameterError(f"fmt={fmt!r}: use one of {', '.join(FORMATS)}")
    widths = [max(len(x) for x in col) for col in zip(*rows, strict=True)]
    line = "  ".join(f"{{:<{w}}}" for w in widths)
    return "\n".join(line.format(*r).rstrip() for r in rows) + "\n"
