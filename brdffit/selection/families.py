"""Material families for grouping rankings: a user's CSV file, else a guess from the name.

A families file (``--families FILE`` of ``brdffit sweep`` and ``brdffit report``) is a
CSV of ``material,family`` rows (an optional header row ``material,family``; blank
lines and lines starting with ``#`` are skipped); :func:`read_families` reads it and its
families replace the guesses below for the materials it names.

The guess (:func:`family_of`) reads the name as words: lower case, split at anything
that is not a letter or digit, a word's trailing digits ignored (``paint2`` is
``paint``). A word is a keyword of the table below when it equals one (``wood`` also
ends a compound: ``fruitwood``); ``metallic paint`` counts as two words in a row. A name
usually ends in its head noun (``acrylic felt`` is a felt, ``gold metallic paint`` a
paint, ``black oxidized steel`` a steel), so when several keywords occur the **last**
one decides. Words that name a colour or a look as often as a material (``gold``,
``silver``, ``metallic``) are no keyword: ``silver sticker`` is a vinyl film and
``satin gold`` a paint finish, so a name with only such hints is ``"other"`` rather
than a wrong guess.

========================  ==================================================================
family                    keywords
========================  ==================================================================
metallic paint            metallic paint (two words)
paint                     paint
plastic/phenolic          plastic, phenolic, delrin, acrylic, polyethylene, pvc, teflon,
                          nylon, polyurethane
fabric                    fabric, felt, velvet
wood                      wood, maple, cherry, oak, walnut, pine, natural 209 (two words)
stone                     marble, obsidian, granite, aventurnine, alumina, jasper, hematite,
                          silicon nitrade (two words)
rubber                    rubber, latex
metal                     aluminium, aluminum, alum bronze (two words), brass, chrome,
                          nickel, steel, bronze, tungsten, ss440, metal
other                     everything else (white-diffuse-bball; gold or silver alone)
========================  ==================================================================
"""

from __future__ import annotations

import csv
import os
import re
from pathlib import Path

from brdffit.errors import SweepError


def _keywords(text: str) -> tuple[str, ...]:
    return tuple(k.strip() for k in text.split(","))


FAMILY_KEYWORDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("metallic paint", ("metallic paint",)),
    ("paint", ("paint",)),
    (
        "plastic/phenolic",
        _keywords(
            "plastic, phenolic, delrin, acrylic, polyethylene, pvc, teflon, nylon, polyurethane"
        ),
    ),
    ("fabric", _keywords("fabric, felt, velvet")),
    ("wood", _keywords("wood, maple, cherry, oak, walnut, pine, natural 209")),
    (
        "stone",
        _keywords(
            "marble, obsidian, granite, aventurnine, alumina, jasper, hematite, silicon nitrade"
        ),
    ),
    ("rubber", _keywords("rubber, latex")),
    (
        "metal",
        _keywords(
            "aluminium, aluminum, alum bronze, brass, chrome, nickel, steel, bronze, tungsten, "
            "ss440, metal"
        ),
    ),
)
"""Family -> keywords (one word, or two words in a row written with a space)."""

FAMILIES: tuple[str, ...] = tuple(f for f, _ in FAMILY_KEYWORDS) + ("other",)

SUFFIX_KEYWORDS: frozenset[str] = frozenset({"wood"})
"""Keywords that also count at the end of a compound word (fruitwood, hardwood)."""


def _words(name: str) -> list[tuple[str, str]]:
    """Lower-case words of ``name``, each as (word, word without trailing digits)."""
    return [(w, w.rstrip("0123456789")) for w in re.split(r"[^a-z0-9]+", name.lower()) if w]


def _is(word: tuple[str, str], keyword: str, *, suffix: bool) -> bool:
    """``word`` (either form) is ``keyword``, or ends with it when ``suffix`` allows."""
    if keyword in word:
        return True
    return suffix and keyword in SUFFIX_KEYWORDS and word[1].endswith(keyword)


def _matches(words: list[tuple[str, str]], i: int, keyword: str) -> int:
    """Number of words matched by ``keyword`` starting at word ``i`` (0: no match)."""
    parts = keyword.split()
    if len(parts) == 1:
        return int(_is(words[i], keyword, suffix=True))
    got = words[i : i + len(parts)]
    ok = len(got) == len(parts) and all(
        _is(w, k, suffix=False) for w, k in zip(got, parts, strict=True)
    )
    return len(parts) if ok else 0


def family_of(name: str) -> str:
    """The guessed family of material ``name`` (module docstring), ``"other"`` if unsure."""
    words = _words(name)
    family, i = "other", 0
    while i < len(words):
        step = 1
        for fam, keywords in FAMILY_KEYWORDS:
            n = max(_matches(words, i, k) for k in keywords)
            if n:
                family, step = fam, n
                break
        i += step
    return family


def read_families(path: str | os.PathLike[str]) -> dict[str, str]:
    """Material -> family from a CSV file of ``material,family`` rows (module docstring).

    Raises :class:`SweepError` naming the file and line when the file cannot be read, a
    row has not exactly two non-empty cells, or a material is given two families.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except OSError as e:
        raise SweepError(f"--families {p}: cannot be read ({e.strerror or e})") from None
    except UnicodeDecodeError:
        raise SweepError(f"--families {p}: not a UTF-8 text file") from None
    out: dict[str, str] = {}
    for line, row in enumerate(csv.reader(text.splitlines()), 1):
        cells = [c.strip() for c in row]
        if not any(cells) or cells[0].startswith("#"):
            continue
        if line == 1 and [c.lower() for c in cells] == ["material", "family"]:
            continue
        if len(cells) != 2 or not all(cells):
            raise SweepError(
                f"--families {p}: line {line} is {','.join(row)!r}; expected two non-empty "
                "cells, material,family"
            )
        material, family = cells
        if out.get(material, family) != family:
            raise SweepError(
                f"--families {p}: line {line} gives {material} the family {family!r}, an "
                f"earlier line {out[material]!r}"
            )
        out[material] = family
    if not out:
        raise SweepError(f"--families {p}: no material,family row")
    return out
