"""Rows of group f for the generic model tests: STD, the Student-t microfacet model of
Ribardière et al. 2017 (one row per option group: the paper's form, anisotropic with
height-correlated masking, Schlick without diffuse)."""

from __future__ import annotations

from tests.cases import Case

ROWS: list[Case] = [
    Case(
        "std",
        params={
            "kd": [0.1, 0.2, 0.3],
            "ks": [0.8, 0.6, 0.4],
            "eta": 1.8,
            "alpha": 0.15,
            "gamma": 3.0,
        },
    ),
    Case(
        "std",
        {"masking": "height_correlated", "anisotropic": True},
        {"ks": [0.9, 0.9, 0.8], "eta": 2.5, "alpha_x": 0.1, "alpha_y": 0.3, "gamma": 1.8},
    ),
    Case(
        "std",
        {"fresnel": "schlick", "diffuse": False},
        {"f0": [0.9, 0.7, 0.5], "alpha": 0.3, "gamma": 8.0},
    ),
]
