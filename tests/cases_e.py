"""Rows of group e for the generic model tests: Bagher et al. 2012 (SGD). The second row
is a broad, long-tailed lobe like the paper's Teflon fit (p > 1: negative first argument of
the incomplete gamma) with a Fresnel curve that falls at normal incidence; the third has a
lobe per channel. Sharp lobes with p > 1 (alpha = 3e-4, p = 1.4) are not identifiable from
these 1500 random pairs: a handful of samples lie in the lobe, and a fit reached a relative
residual of 1e-8 with p = 1.56 and ks off by x3; the sharp case is covered by the value tests."""

from __future__ import annotations

from tests.cases import Case

ROWS: list[Case] = [
    Case(
        "sgd",
        params={
            "kd": [0.1, 0.2, 0.3],
            "ks": [0.5, 0.4, 0.3],
            "f0": [0.9, 0.6, 0.3],
            "f1": [0.1, -0.2, 0.05],
            "alpha": 0.02,
            "p": 0.6,
        },
    ),
    Case(
        "sgd",
        params={
            "ks": [0.2, 0.3, 0.4],
            "f0": [0.05] * 3,
            "f1": [0.04, -0.3, 0.0],
            "alpha": 0.5,
            "p": 1.3,
        },
    ),
    Case(
        "sgd",
        {"rgb_lobe": True},
        {"kd": [0.3, 0.2, 0.1], "alpha": [0.3, 0.15, 0.08], "p": [0.3, 0.8, 1.4]},
    ),
]
