"""Rows of group j for the generic model tests: OpenPBR Surface as MaterialX evaluates it
(``brdffit/models/openpbr.py``), one row per option and one with every option on.

Identifiability (``tests/models/test_identifiability.py``, noise-free data): the core
row is a partly metallic base (``base_metalness`` 0.3) with a coloured ``base_color``
and ``specular_color``, where the metal lobe (``specular_weight F82(base_color,
specular_color)``), the dielectric lobe (``F(eta)`` of the modulated index) and the
diffuse (EON of ``base_color``, darkened by the dielectric's throughput) separate every
input. The dielectric row (``base_metalness`` 0) sees ``specular_weight`` only through
the modulated index ``e = sqrt(specular_weight) (eta_s - 1)/(eta_s + 1)``, which
``specular_ior`` also sets, so ``specular_weight`` is frozen there. In the row with every
option the film's thickness is frozen: not a degenerate direction but a start (see
:data:`FILM_START`). Every other parameter of every row came back to 1e-3 (the slow check).
"""

from __future__ import annotations

from tests.cases import Case

CORE = {
    "base_color": [0.8, 0.5, 0.2],
    "base_metalness": 0.3,
    "base_diffuse_roughness": 0.6,
    "specular_weight": 0.7,
    "specular_color": [0.9, 0.7, 0.8],
    "specular_roughness": 0.35,
    "specular_ior": 1.7,
}
COAT = {"coat_weight": 0.6, "coat_roughness": 0.2, "coat_ior": 1.45}
FUZZ = {"fuzz_weight": 0.7, "fuzz_color": [0.3, 0.5, 0.9], "fuzz_roughness": 0.4}
FILM = {"thin_film_weight": 0.6, "thin_film_thickness": 0.4, "thin_film_ior": 1.3}
DIELECTRIC_ONLY = (
    "a dielectric (base_metalness 0) sees specular_weight only through the modulated index "
    "sqrt(specular_weight) (eta - 1)/(eta + 1), which specular_ior also sets"
)

FILM_START = (
    "not a degenerate direction but a start: the Airy sum oscillates in the thickness, and "
    "with every other feature on, LM from the default 0.5 um stopped in a neighbouring "
    "interference minimum (0.59 um, loss 2e-3); the thin_film row recovers it alone"
)

ROWS: list[Case] = [
    Case("openpbr", params=CORE),
    Case(
        "openpbr",
        params=CORE | {"base_metalness": 0.0, "specular_ior": 1.6, "specular_weight": 1.0},
        not_identifiable={"specular_weight": DIELECTRIC_ONLY},
    ),
    Case("openpbr", {"anisotropic": True}, CORE | {"specular_roughness_anisotropy": 0.6}),
    Case("openpbr", {"coat": True}, CORE | COAT),
    Case("openpbr", {"fuzz": True}, CORE | FUZZ),
    Case("openpbr", {"thin_film": True}, CORE | FILM),
    Case(
        "openpbr",
        {"anisotropic": True, "coat": True, "fuzz": True, "thin_film": True},
        CORE | COAT | FUZZ | FILM | {"specular_roughness_anisotropy": 0.4},
        not_identifiable={"thin_film_thickness": FILM_START},
    ),
]
