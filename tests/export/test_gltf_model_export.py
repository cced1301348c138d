"""Exports of the ``gltf`` model (``brdffit/models/gltf_pbr.py``), the glTF material itself.

* glTF: exact by construction for every option group at random values, and (slow) for
  a real fit of a plastic that the model does not hold exactly; the document
  validates and the spec's BRDF read from its JSON alone (``gltf_brdf``, or with a film
  ``document_brdf``: ``tests/models/test_gltf_pbr.py::spec_brdf``) is the model. The
  film is written as ``KHR_materials_iridescence`` with the fitted values, the thickness
  as the maximum (the thickness without a texture).
* walter's thin film maps exactly onto glTF's iridescence where walter's lobe is glTF's
  (GGX, height-correlated masking, no diffuse) and ``ks = 1``; with ``ks < 1`` or a
  Lambert term it is fitted, with its error measured.
* Mitsuba: the generic route (diffuse, conductor, dielectric candidates) gives a measured
  approximate export; so does MaterialX (an OpenPBR form fitted, its error measured).
"""

from __future__ import annotations

import numpy as np
import pytest

from brdffit import fit, models, synthesize
from brdffit.export import EXACT_TOL, export
from tests.export.test_export import load_gltf, model_f, other_pairs, result
from tests.models.test_gltf_pbr import FILM_PAIRS, OPTIONS, checked_material, draw, spec_brdf

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
    mat = checked_material(load_gltf(e.files[".gltf"]))
    wi, wo = other_pairs()
    if "KHR_materials_iridescence" in mat.get("extensions", {}):
        wi, wo = wi[:FILM_PAIRS], wo[:FILM_PAIRS]  # the mpmath reader
    np.testing.assert_allclose(spec_brdf(mat, wi, wo), model_f(r, wi, wo), rtol=1e-10)
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


def test_the_film_is_written_with_the_fitted_values():
    model = models.get("gltf", iridescence=True)
    params = {k: v.tolist() for k, v in draw(model, np.random.default_rng(8)).items()}
    e = export(result(models.label(model), params), "gltf")
    doc = load_gltf(e.files[".gltf"])
    assert "KHR_materials_iridescence" in doc["extensionsUsed"]
    assert "KHR_materials_iridescence" in e.target_model
    film = doc["materials"][0]["extensions"]["KHR_materials_iridescence"]
    assert film == {
        "iridescenceFactor": params["iridescence"],
        "iridescenceIor": params["iridescence_ior"],
        "iridescenceThicknessMaximum": params["iridescence_thickness"],
    }
    assert any(n.startswith("iridescence: the film's Fresnel evaluated at V.H") for n in e.notes)


FILM = {"film_weight": 0.7, "film_ior": 1.6, "film_thickness": 500.0}
WALTER_FILM = {"f0": [0.9, 0.6, 0.3], "alpha": 0.1} | FILM
GLTF_LOBE = "masking=height_correlated,diffuse=false,thin_film=true"


@pytest.mark.parametrize(
    "spec, params",
    [
        (f"walter[{GLTF_LOBE},specular_weight=false]", WALTER_FILM),
        (f"walter[{GLTF_LOBE}]", WALTER_FILM | {"ks": [1.0, 1.0, 1.0]}),
        (
            f"walter[anisotropic=true,{GLTF_LOBE},specular_weight=false]",
            {"f0": [0.3, 0.5, 0.9], "alpha_x": 0.3, "alpha_y": 0.05} | FILM,
        ),
    ],
)
def test_walter_thin_film_with_ks_1_is_gltf_iridescence_exactly(spec, params):
    mat = check_exact(result(spec, params))
    film = mat["extensions"]["KHR_materials_iridescence"]
    assert film["iridescenceFactor"] == 0.7 and film["iridescenceIor"] == 1.6
    assert film["iridescenceThicknessMaximum"] == 500.0


@pytest.mark.parametrize(
    "spec, extra",
    [
        (f"walter[{GLTF_LOBE}]", {"ks": [0.7, 0.7, 0.7]}),  # glTF's film ignores specular
        ("walter[masking=height_correlated,thin_film=true]", {"kd": [0.1, 0.2, 0.3]}),
    ],
)
def test_walter_thin_film_gltf_cannot_hold_is_fitted_and_measured(spec, extra):
    e = export(result(spec, WALTER_FILM | {"ks": [1.0, 1.0, 1.0]} | extra), "gltf")
    print(e.summary())
    assert not e.exact and e.fitted and 0 < e.error < 0.2, e.summary()
    assert "KHR_materials_iridescence" in e.target_model


def test_mitsuba_export_is_approximate_and_measured():
    e = export(result("gltf", PLASTIC), "mitsuba")
    print(e.summary())
    assert not e.exact and np.isfinite(e.error) and np.isfinite(e.log_error)
    assert e.error < 0.5, e.summary()  # a plastic: diffuse + GGX lobe, close in Mitsuba's forms


def test_materialx_export_is_approximate_and_measured():
    """OpenPBR fitted to the glTF material (its diffuse is weighted by 1 - max F, OpenPBR's
    by the dielectric's albedo), the error measured (tests/export/test_openpbr_export.py
    checks such errors against MaterialX's own graph)."""
    e = export(result("gltf", PLASTIC), "materialx")
    print(e.summary())
    assert not e.exact and e.fitted and 0 < e.error < 0.2, e.summary()
