"""A fit of the ``principled`` model (Mitsuba's plugin as a model) exports to Mitsuba exactly.

The export copies the parameters (exact, not fitted, error at round-off), and Mitsuba 3
itself (scalar_rgb, float32), given the exported dict and its XML, evaluates what the model
evaluates, at pairs other than the export's own.
"""

from __future__ import annotations

import numpy as np
import pytest

from brdffit import models
from brdffit.export import EXACT_TOL, export
from tests.export.test_export import mitsuba_fcos, model_f, result
from tests.models.test_mitsuba_principled import FULL, coat_rounding, pairs

CASES = [
    ("principled", {"base_color": [0.8, 0.5, 0.2], "metallic": 0.3, "roughness": 0.4}),
    (
        "principled[spec_tint=true,anisotropic=true,sheen=true,sheen_tint=true,"
        "flatness=true,clearcoat=true]",
        FULL,
    ),
    ("principled[metallic=false,clearcoat=true]", {**FULL, "specular": 0.0}),  # no lobe
    ("principled", {"metallic": 0.5, "specular": 0.0}),  # Mitsuba drops the metal's lobe too
    ("principled[grey=base_color,neutral=specular]", {"base_color": 0.4, "roughness": 0.2}),
]


@pytest.fixture(scope="module")
def mi():
    mitsuba = pytest.importorskip("mitsuba")
    mitsuba.set_variant("scalar_rgb")
    return mitsuba


@pytest.mark.parametrize("spec,values", CASES, ids=[c[0] for c in CASES])
def test_principled_model_exports_to_mitsuba_exactly(mi, spec, values):
    name, options = models.parse_spec(spec)
    model = models.get(name, **options)
    params = {p.name: values.get(p.name, FULL.get(p.name, 0.5)) for p in model.parameters}
    r = result(spec, params)
    e = export(r, "mitsuba")
    assert e.exact and not e.fitted and e.error <= EXACT_TOL, e.summary()
    assert e.target_model == "principled" and e.material["type"] == "principled"
    wi, wo = pairs(3)
    ref = model_f(r, wi, wo) * wi[:, 2:3]
    rtol = np.full(len(wi), 1e-5)  # Mitsuba's float32 (tests/models/test_mitsuba_principled.py)
    if "clearcoat" in e.material:
        rtol += coat_rounding(wi, wo, e.material["clearcoat_gloss"])
    for bsdf in (mi.load_dict(e.material), mi.load_string(e.files[".mitsuba.xml"])):
        got = mitsuba_fcos(mi, bsdf, wi, wo)
        np.testing.assert_array_less(np.abs(got - ref), rtol[:, None] * ref + 1e-7 * ref.max())
