"""OpenPBR as MaterialX itself evaluates it: the GLSL MaterialX generates for
``open_pbr_surface``, run on an OpenGL context (:mod:`tests.materialx_glsl`), against the
test suite's reference interpreter of the library's node graph
(:mod:`tests.references_openpbr`) on each feature alone and all together. GLSL runs in
float32, so the two agree to a few 1e-6 relative, not to float64."""

from __future__ import annotations

import numpy as np
import pytest

from tests.materialx_glsl import context, response
from tests.references_openpbr import evaluate

CASES = {
    "default": {},
    "diffuse_only": {"specular_weight": 0.0},
    "eon": {"base_diffuse_roughness": 0.8, "base_color": [0.9, 0.4, 0.1]},
    "metal": {"base_metalness": 1.0, "base_color": [0.9, 0.6, 0.3], "specular_roughness": 0.25},
    "metal_f82_aniso": {
        "base_metalness": 1.0,
        "base_color": [0.9, 0.6, 0.3],
        "specular_color": [0.6, 0.9, 0.7],
        "specular_roughness": 0.5,
        "specular_roughness_anisotropy": 0.7,
    },
    "specular_weight": {
        "specular_weight": 0.4,
        "specular_ior": 1.8,
        "specular_color": [1.0, 0.5, 0.7],
    },
    "coat": {
        "coat_weight": 1.0,
        "coat_roughness": 0.3,
        "coat_color": [0.8, 0.9, 0.6],
        "coat_ior": 1.45,
        "base_color": [0.3, 0.6, 0.9],
    },
    "coat_metal": {"coat_weight": 0.7, "coat_darkening": 0.5, "base_metalness": 1.0},
    "fuzz": {"fuzz_weight": 1.0, "fuzz_color": [0.9, 0.3, 0.5], "fuzz_roughness": 0.3},
    "thin_film": {"thin_film_weight": 1.0, "thin_film_thickness": 0.3, "thin_film_ior": 1.6},
    "thin_film_metal": {
        "thin_film_weight": 1.0,
        "thin_film_thickness": 0.6,
        "base_metalness": 1.0,
        "base_color": [0.9, 0.6, 0.3],
    },
    "all": {
        "base_color": [0.8, 0.5, 0.2],
        "base_metalness": 0.3,
        "base_diffuse_roughness": 0.5,
        "specular_roughness": 0.4,
        "specular_roughness_anisotropy": 0.3,
        "specular_color": [0.9, 0.7, 0.8],
        "coat_weight": 0.6,
        "coat_roughness": 0.2,
        "coat_color": [0.9, 0.8, 0.7],
        "fuzz_weight": 0.5,
        "fuzz_color": [0.2, 0.9, 0.3],
        "fuzz_roughness": 0.4,
        "thin_film_weight": 0.5,
        "thin_film_thickness": 0.4,
    },
}
TOLERANCE = 5e-5
"""Relative, on responses floored at 1e-3 of the largest: float32 GLSL against float64."""


def directions(n: int = 1500, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Random pairs above the horizon (z > 0.02), wi toward the light, wo toward the viewer."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(2):
        v = rng.normal(size=(4 * n, 3))
        v[:, 2] = np.abs(v[:, 2])
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        out.append(v[v[:, 2] > 0.02][:n])
    return out[0], out[1]


def relative_error(got: np.ndarray, ref: np.ndarray) -> float:
    scale = np.maximum(np.abs(ref), 1e-3 * np.abs(ref).max())
    return float(np.max(np.abs(got - ref) / scale))


FAST = ("default", "metal_f82_aniso", "all")
"""Cases of the default suite: every feature is on in ``all``; the metal's F82 tint and
anisotropy alone in ``metal_f82_aniso`` (2-3 s a case; ``benchmarks/slow_checks.sh``
runs each feature alone)."""


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=() if n in FAST else pytest.mark.slow) for n in CASES]
)
def test_reference_interpreter_equals_materialx_glsl(name):
    context()
    wi, wo = directions()
    glsl = response(CASES[name], wi, wo)
    ref = evaluate(CASES[name], wi, wo) * wi[:, 2:3]
    assert np.abs(ref).max() > 1e-3
    assert relative_error(glsl, ref) < TOLERANCE


def test_the_glsl_harness_sees_a_changed_input():
    """The harness renders the material it is given: one input changed moves the result."""
    context()
    wi, wo = directions(200)
    a = response({"base_color": [0.5, 0.5, 0.5]}, wi, wo)
    b = response({"base_color": [0.5, 0.5, 0.45]}, wi, wo)
    assert np.allclose(a[:, :2], b[:, :2], rtol=1e-6) and relative_error(b[:, 2], a[:, 2]) > 1e-2
