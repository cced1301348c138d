"""Exports of the ``gltf`` model (``brdffit/models/gltf_pbr.py``), the glTF material itself.

* glTF: exact by construction for every option group at random values, and (slow) for
  a real fit of a plastic that the model does not hold exactly; the document
  validates and the spec's BRDF read from its JSON alone (``gltf_brdf``) is the model.
* Mitsuba: the generic route (diffuse, conductor, dielectric candidates) gives a measured
  approximate export; MaterialX refuses the model with the reason (no clean OpenPBR
  mapping, as for every model but lambert and a GGX walter metal).
"""

from __future__ import annotations

import numpy as np
import pytest

from brdffit import fit, models, synthesize
from brdffit.export import EXACT_TOL, ExportError, export
from tests.export.test_export import (
    check_gltf_document,
    gltf_brdf,
    load_gltf,
    model_f,
    other_pairs,
    result,
)
from tests.models.test_gltf_pbr import OPTIONS, draw

PLASTIC = {
    "base_color": [0.546, 0.109, 0.0545],
    "metallic": 0.0557,
    "roughness": 0.347,
    "specular": 0.577,
    "specular_f0": [0.0, 0.0441, 0.0496],
}
"""The fit of the slow test below, rounded (``specular_f0[r]`` on its bound)."""


def check_exact(r) -> dict:
    """The glTF export of ``r`` is exact, its document valid, and its spec BRDF is the model."""
    e = export(r, "gltf")
    assert e.exact and not e.fitted and e.error <= EXACT_TOL, e.summary()
    mat = check_gltf_document(load_gltf(e.files[".gltf"]))
    wi, wo = other_pairs()
    np.testing.assert_allclose(gltf_brdf(mat, wi, wo), model_f(r, wi, wo), rtol=1e-10)
    return mat


@pytest.mark.slow  # 45 s on 2 cores, nearly all compiling the gltf model's fit
def test_export_of_a_fitted_gltf_model_is_exact():
    # a red plastic (walter: Lambert + GGX), which glTF's coupled diffuse does not hold
    # exactly: the fitted values are arbitrary
    truth = {"kd": [0.5, 0.1, 0.05], "ks": [0.6] * 3, "f0": [0.05] * 3, "alpha": 0.12}
    data = synthesize(models.get("walter"), truth, stride=(5, 5, 9))
    fitted = fit(models.get("gltf"), data, "ngan", n_restarts=0, throw=False)
    print(fitted.report())
    assert np.isfinite(fitted.loss)
    mat = check_exact(fitted)
    pbr = mat["pbrMetallicRoughness"]
    assert pbr["roughnessFactor"] == float(np.asarray(fitted.params["roughness"]))
    assert pbr["baseColorFactor"][:3] == np.asarray(fitted.params["base_color"]).tolist()


@pytest.mark.parametrize("opts", OPTIONS, ids=str)
def test_every_option_group_exports_exactly(opts):
    model = models.get("gltf", **opts)
    params = draw(model, np.random.default_rng(7))
    check_exact(result(models.label(model), {k: v.tolist() for k, v in params.items()}))


def test_mitsuba_export_is_approximate_and_measured():
    e = export(result("gltf", PLASTIC), "mitsuba")
    print(e.summary())
    assert not e.exact and np.isfinite(e.error) and np.isfinite(e.log_error)
    assert e.error < 0.5, e.summary()  # a plastic: diffuse + GGX lobe, close in Mitsuba's forms


def test_materialx_refuses_the_gltf_model_with_the_reason():
    with pytest.raises(ExportError, match="no clean OpenPBR mapping for gltf"):
        export(result("gltf", PLASTIC), "materialx")
