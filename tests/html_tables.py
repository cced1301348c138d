"""Reading back the HTML that results show in Jupyter (``_repr_html_``): the tables as
cell texts, with their alignment, and the whole text, through :mod:`html.parser`."""

from __future__ import annotations

from dataclasses import dataclass, field
from html.parser import HTMLParser


@dataclass
class Table:
    """One ``<table>``: the header cells, the body rows (cell texts, unescaped) and, per
    body cell, whether it is right-aligned."""

    head: list[str] = field(default_factory=list)
    body: list[list[str]] = field(default_factory=list)
    right: list[list[bool]] = field(default_factory=list)
    head_right: list[bool] = field(default_factory=list)

    def column(self, name: str) -> list[str]:
        """The body cells under header ``name``."""
        j = self.head.index(name)
        return [row[j] for row in self.body]

    def row(self, first: str) -> list[str]:
        """The one body row whose first cell is ``first``."""
        (hit,) = [r for r in self.body if r[0] == first]
        return hit


class _Parser(HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tables: list[Table] = []
        self.text: list[str] = []
        self.tags: list[str] = []
        self._section = ""
        self._cell: list[str] | None = None
        self._right = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        if tag == "table":
            self.tables.append(Table())
        elif tag in ("thead", "tbody"):
            self._section = tag
        elif tag == "tr" and self._section == "tbody":
            self.tables[-1].body.append([])
            self.tables[-1].right.append([])
        elif tag in ("td", "th"):
            self._cell = []
            self._right = "text-align:right" in (dict(attrs).get("style") or "")

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._cell is not None:
            text, t = "".join(self._cell), self.tables[-1]
            if self._section == "thead":
                t.head.append(text)
                t.head_right.append(self._right)
            else:
                t.body[-1].append(text)
                t.right[-1].append(self._right)
            self._cell = None

    def handle_data(self, data: str) -> None:
        self.text.append(data)
        if self._cell is not None:
            self._cell.append(data)


def parse(markup: str) -> _Parser:
    """The parsed markup: ``.tables`` (:class:`Table`), ``.text`` (data pieces, unescaped),
    ``.tags`` (every start tag, in order)."""
    p = _Parser()
    p.feed(markup)
    p.close()
    return p


def tables(markup: str) -> list[Table]:
    """The tables of ``markup``, in order."""
    return parse(markup).tables


def text(markup: str) -> str:
    """All the text of ``markup``, unescaped, tags dropped."""
    return "".join(parse(markup).text)
