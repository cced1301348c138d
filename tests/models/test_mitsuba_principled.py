"""Mitsuba 3's ``principled`` as a model (``models/mitsuba_principled.py``) against Mitsuba itself.

* ``f cos(theta_i)`` equals Mitsuba's ``BSDF.eval`` (scalar_rgb, float32) at random direction
  pairs, for parameter sets that switch each feature on and off and reach the edges Mitsuba
  treats specially (roughness below its alpha floor, ``specular = 0``, a black base colour
  under a tint, the glossiest clear coat);
* a feature that is off is the full model with that parameter at 0 (Mitsuba's switch);
* the options are checked (``sheen_tint`` needs ``sheen``).
"""

from __future__ import annotations

import numpy as np
import pytest

from brdffit import models
from brdffit.core.geometry import halfdiff_to_io
from brdffit.errors import ParameterError
from tests.export.test_export import mitsuba_fcos
from tests.helpers import random_pairs

ALL = dict.fromkeys(
    ("metallic", "spec_tint", "anisotropic", "sheen", "sheen_tint", "flatness", "clearcoat"), True
)
NONE = dict.fromkeys(ALL, False)
FULL = {  # every parameter, inside its bounds, base colour not grey
    "base_color": [0.8, 0.5, 0.2], "metallic": 0.3, "roughness": 0.4, "specular": 0.6,
    "spec_tint": 0.3, "anisotropic": 0.5, "sheen": 0.4, "sheen_tint": 0.6, "flatness": 0.4,
    "clearcoat": 0.5, "clearcoat_gloss": 0.7,
}  # fmt: skip

# (options, parameter values): the model's parameters missing here take FULL's values
SETS = [
    (ALL, {}),
    ({}, {}),  # the defaults: metallic only
    (NONE, {"roughness": 0.15, "specular": 0.3}),
    ({**NONE, "anisotropic": True}, {"roughness": 0.3, "anisotropic": 0.9}),
    ({"flatness": True, "clearcoat": True}, {"metallic": 0.0, "clearcoat_gloss": 1.0}),
    ({"sheen": True, "sheen_tint": True}, {"metallic": 0.8, "roughness": 0.9}),
    ({"spec_tint": True}, {"base_color": [0.0, 0.0, 0.0], "spec_tint": 0.7}),  # lum = 0
    ({"spec_tint": True}, {"base_color": [0.3, 0.9, 0.6], "specular": 1.0, "spec_tint": 1.0}),
    ({}, {"roughness": 0.01, "metallic": 1.0}),  # alpha on Mitsuba's floor .001
    ({}, {"specular": 0.0}),  # eta = 1: Mitsuba drops the whole specular lobe
]


@pytest.fixture(scope="module")
def mi():
    mitsuba = pytest.importorskip("mitsuba")
    mitsuba.set_variant("scalar_rgb")
    return mitsuba


def build(options: dict, values: dict) -> tuple[object, dict]:
    """The model and its full parameter dict (FULL, overridden by ``values``)."""
    model = models.get("principled", **options)
    return model, {p.name: np.asarray({**FULL, **values}[p.name], float) for p in model.parameters}


def pairs(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """300 random pairs and 100 near the mirror direction (``theta_h = .1 u^2``), each
    direction rounded to float32 as Mitsuba receives it (an ulp of ``h`` is 6e-5 of an
    alpha of .001) and given to the model as it is."""
    wi, wo = random_pairs(seed, 300)
    u = np.random.default_rng(seed).uniform(size=(4, 100))
    near = halfdiff_to_io(0.1 * u[0] ** 2, 1.4 * u[1], 2 * np.pi * u[2], 2 * np.pi * u[3])
    wi, wo = np.vstack([wi, near[0]]), np.vstack([wo, near[1]])
    return wi.astype(np.float32).astype(float), wo.astype(np.float32).astype(float)


def mitsuba_dict(params: dict) -> dict:
    """Mitsuba's plugin with exactly the model's parameters given (the others absent: off)."""
    out = {k: float(v) for k, v in params.items() if k != "base_color"}
    base = {"type": "rgb", "value": params["base_color"]}
    return {"type": "principled", "base_color": base} | out


@pytest.mark.parametrize("options,values", SETS, ids=[f"set{i}" for i in range(len(SETS))])
def test_equals_mitsubas_eval_to_float32(mi, options, values):
    model, params = build(options, values)
    wi, wo = pairs(len(values) + 17 * len(options))
    ours = np.asarray(model.eval(params, wi, wo)) * wi[:, 2:3]
    ref = mitsuba_fcos(mi, mi.load_dict(mitsuba_dict(params)), wi, wo)
    assert ref.max() > 0.05  # a lit material: the comparison is not of zeros
    # Mitsuba evaluates in float32 (ulp 6e-8, ~20 roundings): measured worst 3e-6 relative,
    # plus the clear coat's cancellation near its peak (coat_rounding)
    rtol = np.full(len(wi), 1e-5)
    if "clearcoat" in params:
        rtol += coat_rounding(wi, wo, params["clearcoat_gloss"])
    np.testing.assert_array_less(np.abs(ours - ref), rtol[:, None] * ref + 1e-7 * ref.max())


def coat_rounding(wi: np.ndarray, wo: np.ndarray, gloss: float) -> np.ndarray:
    """Bound on the relative float32 error of Mitsuba's GTR1, (N,): it forms its denominator
    ``t = 1 + (a^2 - 1) cos_h^2`` from the rounded ``cos_h^2`` (absolute error ~2 ulp = 1.2e-7),
    which near the peak is ``a^2 cos_h^2 + sin_h^2``, as small as ``a^2`` (1e-6 at gloss 1)."""
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=1, keepdims=True)
    a2 = (0.1 + float(gloss) * (0.001 - 0.1)) ** 2
    return 2.4e-7 / (a2 * h[:, 2] ** 2 + h[:, 0] ** 2 + h[:, 1] ** 2)


def test_a_feature_that_is_off_is_the_full_model_with_its_parameter_at_zero():
    wi, wo = random_pairs(5, 64)
    full = models.get("principled", **ALL)
    for name in ALL:
        off = {**ALL, name: False} | ({"sheen_tint": False} if name == "sheen" else {})
        model, params = build(off, {})
        zero = {p.name: np.asarray(FULL[p.name], float) for p in full.parameters}
        zero |= {name: np.asarray(0.0)} | ({"sheen": np.asarray(0.0)} if name == "sheen" else {})
        np.testing.assert_allclose(
            np.asarray(model.eval(params, wi, wo)),
            np.asarray(full.eval(zero, wi, wo)),
            rtol=1e-13,
            atol=1e-15,
            err_msg=name,
        )


def test_options_are_checked():
    with pytest.raises(ParameterError, match="sheen_tint=True needs sheen=True"):
        models.get("principled", sheen_tint=True)
    with pytest.raises(ParameterError, match="clearcoat"):  # not a bool
        models.get("principled", clearcoat=1)
    names = [p.name for p in models.get("principled").parameters]
    assert names == ["base_color", "metallic", "roughness", "specular"]
    assert models.get("principled").parameter("specular").neutral == 0.5  # Mitsuba's default
