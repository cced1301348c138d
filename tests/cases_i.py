"""Rows of group i for the generic model tests: Mitsuba 3's ``principled`` BSDF as a model
(the defaults, every feature on, a dielectric with flatness and clear coat, an anisotropic
metal with an untinted sheen)."""

from __future__ import annotations

from tests.cases import Case

_ALL = dict.fromkeys(
    ("metallic", "spec_tint", "anisotropic", "sheen", "sheen_tint", "flatness", "clearcoat"), True
)

ROWS: list[Case] = [
    Case(
        "principled",
        params={"base_color": [0.8, 0.5, 0.2], "metallic": 0.3, "roughness": 0.4, "specular": 0.6},
    ),
    Case(
        "principled",
        _ALL,
        {
            "base_color": [0.8, 0.5, 0.2],
            "metallic": 0.3,
            "roughness": 0.4,
            "specular": 0.6,
            "spec_tint": 0.3,
            "anisotropic": 0.5,
            "sheen": 0.4,
            "sheen_tint": 0.6,
            "flatness": 0.4,
            "clearcoat": 0.5,
            "clearcoat_gloss": 0.7,
        },
    ),
    Case(
        "principled",
        {"metallic": False, "flatness": True, "clearcoat": True},
        {
            "base_color": [0.2, 0.3, 0.6],
            "roughness": 0.3,
            "specular": 0.4,
            "flatness": 0.6,
            "clearcoat": 0.8,
            "clearcoat_gloss": 0.5,
        },
    ),
    Case(
        "principled",
        {"anisotropic": True, "sheen": True},
        {
            "base_color": [0.9, 0.6, 0.3],
            "metallic": 0.9,
            "roughness": 0.5,
            "specular": 0.5,
            "anisotropic": 0.7,
            "sheen": 0.5,
        },
    ),
]
