"""Rows of group h for the generic model tests: the glTF 2.0 metallic-roughness material
(``brdffit/models/gltf_pbr.py``), one row per option group: the core material with
KHR_materials_specular, the bare core, clear coat, sheen, and everything on.

Every parameter is identifiable from noise-free data at these values: the specular
lobe's colour is ``A_c (1 - w) + B w`` with ``A_c = (1 - m) s f0_c + m b_c`` and ``B =
(1 - m) s + m``, the diffuse ``(1 - m)(1 - s (max f0 (1 - w) + w)) b_c / pi``; the
diffuse gives ``(1 - m) b_c``, ``s`` and ``s max f0``, then ``B`` gives ``m`` (while ``s <
1``) and ``A_c`` each ``f0_c``. So ``specular`` is kept below 1 and ``base_color``
coloured in the rows.
"""

from __future__ import annotations

from tests.cases import Case

BASE = {"base_color": [0.8, 0.5, 0.2], "metallic": 0.3, "roughness": 0.4}

ROWS: list[Case] = [
    Case("gltf", params=BASE | {"specular": 0.8, "specular_f0": [0.04, 0.05, 0.06]}),
    Case("gltf", {"specular": False}, {"base_color": [0.3, 0.5, 0.7], "roughness": 0.25}),
    Case(
        "gltf",
        {"clearcoat": True},
        BASE | {"specular": 0.7, "clearcoat": 0.6, "clearcoat_roughness": 0.15, "roughness": 0.5},
    ),
    Case(
        "gltf",
        {"sheen": True},
        BASE | {"specular": 0.9, "sheen_color": [0.3, 0.2, 0.1], "sheen_roughness": 0.6},
    ),
    Case(
        "gltf",
        {"clearcoat": True, "sheen": True},
        {
            "base_color": [0.5, 0.7, 0.4],
            "metallic": 0.1,
            "roughness": 0.3,
            "specular": 0.8,
            "specular_f0": [0.9, 0.6, 0.3],
            "clearcoat": 0.5,
            "clearcoat_roughness": 0.6,
            "sheen_color": [0.2, 0.3, 0.4],
            "sheen_roughness": 0.4,
        },
    ),
]
