"""The one table every generic model test is parametrised over.

Each row is a :class:`Case`: a model name, static options, a dict of natural
parameter values (missing names take the model's default), and the parameters that
synthetic data cannot identify, each with the reason. A new model joins every
generic check (positivity, horizon, reciprocity, rotation invariance, extremes,
jit/vmap, float32, identifiability) by adding its rows: here, or in a file
``tests/cases_<group>.py`` that defines ``ROWS: list[Case]`` (collected below).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path

import jax.numpy as jnp

from brdffit import models
from brdffit.core.abstract_model import AbstractModel


@dataclass(frozen=True)
class Case:
    """A model with options and parameter values (natural units)."""

    model: str
    options: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)
    not_identifiable: dict = field(default_factory=dict)

    @property
    def id(self) -> str:
        opts = ",".join(f"{k}={v}" for k, v in self.options.items())
        return f"{self.model}[{opts}]" if opts else self.model

    def build(self) -> tuple[AbstractModel, dict]:
        """The model and a full parameter dict."""
        m = models.get(self.model, **self.options)
        p = m.defaults()
        for k, v in self.params.items():
            p[k] = jnp.broadcast_to(jnp.asarray(v, float), m.parameter(k).shape)
        return m, p


CASES: list[Case] = [
    Case("lambert", params={"kd": [0.2, 0.5, 0.8]}),
    Case("blinn_phong", params={"kd": [0.2, 0.3, 0.4], "ks": [0.3, 0.2, 0.1], "n": 120.0}),
    Case("walter", params={"kd": [0.1, 0.2, 0.3], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}),
    Case("walter", {"distribution": "beckmann"}, {"alpha": 0.3}),
    Case("walter", {"distribution": "beckmann", "smith": "rational"}, {"alpha": 0.3}),
    Case("walter", {"masking": "height_correlated"}, {"alpha": 0.5}),
    Case("walter", {"anisotropic": True}, {"alpha_x": 0.1, "alpha_y": 0.4}),
    Case(
        "walter",
        {"anisotropic": True, "distribution": "beckmann"},
        {"alpha_x": 0.3, "alpha_y": 0.05},
    ),
    Case("walter", {"diffuse": False}, {"alpha": 0.05}),
]


for _path in sorted(Path(__file__).parent.glob("cases_*.py")):
    CASES += importlib.import_module(f"tests.{_path.stem}").ROWS


def params_of(model: str, **options: object) -> dict:
    """The parameter values of the first row of :data:`CASES` for ``model`` built with
    exactly ``options`` (the benchmarks' truths reuse the rows the tests check)."""
    for case in CASES:
        if case.model == model and case.options == options:
            return dict(case.params)
    raise KeyError(f"no case row {model} {options}")
