"""Material families from material names (MERL naming), for grouping rankings.

The family is the first rule below whose keywords occur in the lower-case name; the
order matters ("gold-metallic-paint" is a metallic paint, "gold-paint" a paint,
"black-oxidized-steel" a metal). Names that match nothing are ``"other"``.

========================  ==================================================================
family                    keywords
========================  ==================================================================
metallic paint            metallic-paint
paint                     paint
plastic/phenolic          plastic, phenolic, delrin, acrylic, polyethylene, pvc, teflon,
                          nylon, polyurethane
fabric                    fabric, felt, velvet
wood                      wood, maple, cherry, oak, walnut, pine, natural-209
stone                     marble, obsidian, granite, aventurnine, alumina, jasper, hematite,
                          silicon-nitrade
rubber                    rubber, latex
metal                     aluminium, alum-bronze, brass, chrome, nickel, steel, bronze, gold,
                          silver, tungsten, ss440, metal
other                     everything else (e.g. white-diffuse-bball, color-changing-paint
                          goes to paint)
========================  ==================================================================
"""

from __future__ import annotations

FAMILY_KEYWORDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("metallic paint", ("metallic-paint",)),
    ("paint", ("paint",)),
    (
        "plastic/phenolic",
        (
            "plastic",
            "phenolic",
            "delrin",
            "acrylic",
            "polyethylene",
            "pvc",
            "teflon",
            "nylon",
            "polyurethane",
        ),
    ),
    ("fabric", ("fabric", "felt", "velvet")),
    ("wood", ("wood", "maple", "cherry", "oak", "walnut", "pine", "natural-209")),
    (
        "stone",
        (
            "marble",
            "obsidian",
            "granite",
            "aventurnine",
            "alumina",
            "jasper",
            "hematite",
            "silicon-nitrade",
        ),
    ),
    ("rubber", ("rubber", "latex")),
    (
        "metal",
        (
            "aluminium",
            "alum-bronze",
            "brass",
            "chrome",
            "nickel",
            "steel",
            "bronze",
            "gold",
            "silver",
            "tungsten",
            "ss440",
            "metal",
        ),
    ),
)

FAMILIES: tuple[str, ...] = tuple(f for f, _ in FAMILY_KEYWORDS) + ("other",)


def family_of(name: str) -> str:
    """The family of material ``name`` (module docstring), ``"other"`` if none matches."""
    low = name.lower()
    for family, words in FAMILY_KEYWORDS:
        if any(w in low for w in words):
            return family
    return "other"
