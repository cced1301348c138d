"""Rows of group b for the generic model tests: Lafortune, Ashikhmin-Shirley, Kurt,
Nishino-Lombardi (one row per option combination). Rows with several lobes order them as
the defaults do (lobe 1 the broadest), since lobes are interchangeable: a fit started from
the defaults finds the labelling of the defaults."""

from __future__ import annotations

from tests.cases import Case

ROWS: list[Case] = [
    Case(
        "lafortune",
        params={"kd": [0.1, 0.2, 0.3], "rho_1": [0.5, 0.4, 0.3], "cxy_1": -1.2, "n_1": 30.0},
    ),
    Case(
        "lafortune",
        {"anisotropic": True},
        {"rho_1": [0.3, 0.3, 0.2], "cx_1": 0.9, "cy_1": 0.6, "n_1": 20.0},
    ),
    Case(
        "lafortune",
        {"n_lobes": 2},
        {
            "rho_1": [0.3, 0.2, 0.1],
            "cxy_1": -1.3,
            "n_1": 5.0,
            "rho_2": [0.2, 0.3, 0.4],
            "cxy_2": -1.0,
            "n_2": 300.0,
        },
    ),  # fmt: skip
    Case(
        "lafortune",
        {"n_lobes": 2, "anisotropic": True},
        {"cx_1": -2.0, "cy_1": -1.5, "n_1": 3.0, "cx_2": -1.0, "cy_2": -1.05, "n_2": 150.0},
    ),
    Case("ashikhmin_shirley", params={"rd": [0.5, 0.3, 0.2], "rs": [0.1, 0.2, 0.3], "n": 300.0}),
    Case(
        "ashikhmin_shirley",
        {"anisotropic": True},
        {"rd": [0.2, 0.4, 0.6], "rs": [0.6, 0.5, 0.4], "nu": 30.0, "nv": 2000.0},
    ),
    Case(
        "ashikhmin_shirley",
        {"diffuse": "lambert"},
        {"kd": [0.2, 0.1, 0.05], "ks": [0.7, 0.5, 0.3], "rs": [0.05, 0.1, 0.2], "n": 800.0},
    ),
    Case(
        "ashikhmin_shirley",
        {"diffuse": "lambert", "fresnel": "dielectric"},
        {"kd": [0.1, 0.2, 0.3], "ks": [1.8, 1.2, 0.6], "eta": 2.7, "n": 40.0},
    ),
    Case(
        "kurt",
        params={
            "kd": [0.2, 0.1, 0.05],
            "ks_1": [0.6, 0.5, 0.4],
            "f0_1": 0.3,
            "m_1": 0.2,
            "alpha_1": 0.3,
        },
    ),
    Case(
        "kurt",
        {"anisotropic": True},
        {"ks_1": [0.8, 0.8, 0.7], "mx_1": 0.08, "my_1": 0.3, "alpha_1": 0.7},
    ),
    Case(
        "kurt",
        {"n_lobes": 2},
        {
            "ks_1": [0.2, 0.1, 0.1],
            "f0_1": 0.5,
            "m_1": 0.4,
            "alpha_1": 0.8,
            "ks_2": [0.3, 0.4, 0.5],
            "m_2": 0.05,
            "alpha_2": 0.2,
        },
    ),  # fmt: skip
    Case(
        "nishino_lombardi",
        params={"kd": [0.3, 0.2, 0.1], "f0": [0.9, 0.7, 0.5], "k": 3.0, "m": 200.0},
    ),
    Case("nishino_lombardi", params={"f0": [0.05, 0.05, 0.05], "k": 0.05, "m": 8.0}),
]
