"""Rows of group d for the generic model tests: Löw 2012, Filament, course Cook-Torrance."""

from __future__ import annotations

from tests.cases import Case

# Filament rows use a coloured base_color: with a grey one, metallic and reflectance trade
# off exactly (only the diffuse colour b(1 - m) and f0 are observed).
ROWS: list[Case] = [
    Case(
        "low",
        {"variant": "abc"},
        {"kd": [0.1, 0.2, 0.3], "ks": [0.5, 0.4, 0.3], "B": 500.0, "C": 1.3, "eta": 1.6},
    ),
    # C = 1 and C = 2 hit the removable singularities of the normalisation.
    Case("low", {"variant": "abc"}, {"B": 3e4, "C": 1.0, "eta": 3.0}),
    Case(
        "low",
        {"variant": "smooth"},
        {"kd": [0.3, 0.2, 0.1], "ks": [0.2, 0.3, 0.4], "B": 2000.0, "C": 0.8, "eta": 1.4},
    ),
    Case("low", {"variant": "smooth"}, {"B": 50.0, "C": 2.0, "eta": 8.0}),
    Case(
        "filament",
        {},
        {"base_color": [0.8, 0.5, 0.2], "metallic": 0.3, "reflectance": 0.6, "roughness": 0.4},
    ),
    Case(
        "filament",
        {"diffuse": "burley"},
        {"base_color": [0.7, 0.5, 0.3], "metallic": 0.1, "roughness": 0.7},
    ),
    Case(
        "filament",
        {"anisotropy": True},
        {"base_color": [0.3, 0.5, 0.7], "anisotropy": 0.6, "roughness": 0.5},
    ),
    Case(
        "filament",
        {"clearcoat": True},
        {
            "base_color": [0.6, 0.3, 0.2],
            "clear_coat": 0.7,
            "clear_coat_roughness": 0.15,
            "roughness": 0.3,
        },
    ),
    Case(
        "filament",
        {"sheen": True},
        {
            "base_color": [0.2, 0.4, 0.6],
            "sheen_color": [0.3, 0.2, 0.1],
            "sheen_roughness": 0.6,
            "metallic": 0.2,
        },
    ),
    Case(
        "filament",
        {"diffuse": "burley", "anisotropy": True, "clearcoat": True, "sheen": True},
        {
            "base_color": [0.5, 0.7, 0.4],
            "anisotropy": -0.4,
            "clear_coat": 0.5,
            "clear_coat_roughness": 0.6,
            "roughness": 0.3,
        },
    ),
    Case(
        "filament",
        {"shading": "cloth"},
        {"base_color": [0.2, 0.3, 0.5], "sheen_color": [0.5, 0.4, 0.3], "roughness": 0.8},
    ),
    Case(
        "filament",
        {"shading": "cloth", "diffuse": "burley", "subsurface": True},
        {"subsurface_color": [0.4, 0.2, 0.1], "roughness": 0.6},
    ),
    Case(
        "course_cook_torrance",
        {},
        {"albedo": [0.7, 0.4, 0.2], "f0": [0.04, 0.05, 0.06], "roughness": 0.4},
    ),
    Case(
        "course_cook_torrance",
        {"metallic": True},
        {"albedo": [0.9, 0.6, 0.3], "metallic": 0.7, "roughness": 0.25},
    ),
]
