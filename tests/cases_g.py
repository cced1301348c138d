"""Rows of group g for the generic model tests: Walter's optional lobes and layers (two
specular lobes, a narrow peak inside a wide halo; the Charlie sheen; the glTF clear coat;
all three together)."""

from __future__ import annotations

from tests.cases import Case

_TWO = {
    "kd": [0.05, 0.08, 0.2],
    "ks_1": [0.3, 0.3, 0.4],
    "f0_1": [0.9, 0.8, 0.7],
    "alpha_1": 0.04,
    "ks_2": [0.2, 0.3, 0.6],
    "f0_2": [0.5, 0.6, 0.9],
    "alpha_2": 0.35,
}

ROWS: list[Case] = [
    Case("walter", {"n_lobes": 2}, _TWO),
    Case(
        "walter",
        {"sheen": True},
        {
            "kd": [0.5, 0.1, 0.2],
            "f0": [0.04, 0.04, 0.04],
            "ks": [0.5, 0.5, 0.5],
            "alpha": 0.3,
            "sheen_color": [0.6, 0.3, 0.4],
            "sheen_roughness": 0.4,
        },
    ),
    Case(
        "walter",
        {"clearcoat": True, "masking": "height_correlated"},
        {
            "kd": [0.3, 0.05, 0.05],
            "ks": [0.6, 0.5, 0.4],
            "f0": [0.7, 0.5, 0.3],
            "alpha": 0.25,
            "clearcoat": 0.8,
            "clearcoat_alpha": 0.02,
        },
    ),
    Case(
        "walter",
        {"n_lobes": 2, "sheen": True, "clearcoat": True, "anisotropic": True},
        {
            **{k: v for k, v in _TWO.items() if not k.startswith("alpha")},
            "alpha_x_1": 0.04,
            "alpha_y_1": 0.08,
            "alpha_x_2": 0.3,
            "alpha_y_2": 0.4,
            "sheen_color": [0.2, 0.1, 0.1],
            "sheen_roughness": 0.6,
            "clearcoat": 0.5,
            "clearcoat_alpha": 0.01,
        },
    ),
]

ROWS.append(
    Case(
        "walter",
        {"thin_film": True},
        {
            "kd": [0.02, 0.02, 0.03],
            "ks": [0.9, 0.9, 0.9],
            "f0": [0.3, 0.3, 0.3],
            "alpha": 0.12,
            "film_weight": 0.8,
            "film_thickness": 320.0,
            "film_ior": 1.6,
        },
    )
)
