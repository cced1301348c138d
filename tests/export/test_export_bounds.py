"""Every model exports to every target it supports at every in-bound parameter value.

Parameters are drawn inside the bounds, exactly on each bound, and a hair inside them
(1e-40 above a bound of 0, the next float below 1, 1e30 for an unbounded scale). Each
export must be one its renderer parses -- Mitsuba 3 loads the dict (``load_dict``) and
the written XML (``load_file``); the glTF is strict JSON with every value inside the
glTF 2.0 schema's ranges; the MaterialX is XML with every input in the ``open_pbr_surface``
nodedef's range -- every number in the files is finite and 0 or float32-normal, and the
reported error is the one an independent evaluation measures (Mitsuba's own ``eval``, the
glTF spec's BRDF written in tests/export/test_export.py, MaterialX's own node graph
interpreted in tests/references_openpbr.py);
an exact export matches the model pointwise. A model whose own values are not finite at
the drawn parameters must be refused with ExportValueError before any file is written.

The corners go through the closed-form mappings (``fit=False``: the number-writing path
every target shares); the least-squares path is checked at the corners of three models.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from brdffit import models
from brdffit.export import (
    EXACT_TOL,
    ExportValueError,
    check_targets,
    error_directions,
    evaluate_model,
    export,
    write_exports,
)
from brdffit.export._numbers import FLOAT32_MAX, FLOAT32_TINY
from tests.export.test_export import (
    check_gltf_document,
    gltf_brdf,
    load_gltf,
    log_err,
    mitsuba_fcos,
    openpbr_inputs,
    result,
)
from tests.references_openpbr import open_pbr_brdf

SPECS = [
    *models.available(),
    "walter[grey=ks]",
    "walter[diffuse=false,specular_weight=false]",
    "walter[anisotropic=true]",
    "walter[distribution=beckmann,smith=rational,diffuse=false]",
    "walter[masking=height_correlated,diffuse=false,grey=ks]",
    "disney[clearcoat=false]",
    "filament[clearcoat=true,anisotropy=true,sheen=true]",
]
BIG = 1e30
"""Stands for the upper bound of an unbounded scale (sgd's and brady's ks)."""


@pytest.fixture(scope="module")
def mi():
    mitsuba = pytest.importorskip("mitsuba")
    mitsuba.set_variant("scalar_rgb")
    return mitsuba


def rows(spec: str) -> list[tuple[str, tuple[int, ...], float, float]]:
    """(name, shape, lower, upper) of every free parameter of ``spec`` (grey ones scalar)."""
    model = models.from_spec(spec)
    return [(p.name, p.shape, p.bounds[0], min(p.bounds[1], BIG)) for p in model.parameters]


def edges(lo: float, hi: float) -> list[float]:
    """On each bound and a hair inside it: 1e-40 above 0, the next float below 1."""
    near_lo = 1e-40 if lo == 0.0 else float(np.nextafter(lo, hi))
    return [lo, near_lo, float(np.nextafter(hi, lo)), hi]


def corner(spec: str, which: int) -> dict:
    """Every parameter at ``edges(...)[which]``: on or next to the lower or upper bound."""
    return {n: np.full(s, edges(lo, hi)[which]).tolist() for n, s, lo, hi in rows(spec)}


def numbers_in(text: str) -> list[float]:
    """Every number in a file's attribute values and JSON (ints and floats)."""
    return [float(x) for x in re.findall(r"-?\d+\.?\d*(?:[eE][-+]?\d+)?", text)]


def check_numbers(text: str) -> None:
    """Every number is finite, and 0 or a normal float32 (std::stof's range). A glTF
    file's embedded mesh buffer (a base64 data URI, checked in test_gltf_mesh.py) is not
    text to read numbers from."""
    text = re.sub(r'"data:[^"]*"', '""', text)
    for x in numbers_in(text):
        assert x == 0.0 or FLOAT32_TINY <= abs(x) <= FLOAT32_MAX, x
    assert "nan" not in text.lower() and "inf" not in text.lower().replace("info", "")


def model_fcos(r, wi, wo) -> np.ndarray:
    """f cos(theta_i) of the fitted model (compiled once per model: see evaluate_model)."""
    model = models.get(r.model, **r.options)
    params = {k: np.asarray(v, float) for k, v in r.params.items()}
    return np.asarray(evaluate_model(model, params, wi, wo)) * wi[:, 2:3]


def rel_rms(f_cos: np.ndarray, ref_cos: np.ndarray) -> float:
    """||a - b|| / max(||b||, sqrt(n) 1e-10): relative, but black below 1e-10 1/sr RMS."""
    floor = np.sqrt(ref_cos.size) * 1e-10  # brdffit.export's BLACK (ERROR_DEFINITION)
    return float(np.linalg.norm(f_cos - ref_cos) / max(np.linalg.norm(ref_cos), floor))


def close(measured: float, reported: float, rtol: float, atol: float) -> bool:
    return abs(measured - reported) <= rtol * abs(reported) + atol


def check_mitsuba(mi, e, ref, wi, wo, tmp_path, every: int) -> None:
    """Loads from the dict and the XML file; an exact export matches the model pointwise
    at every ``every``-th pair; at all pairs (``every`` 1) Mitsuba's eval gives the
    reported error."""
    assert json.loads(e.files[".mitsuba.json"]) == e.material
    path = tmp_path / "m.xml"
    path.write_text(e.files[".mitsuba.xml"])
    mi.load_file(str(path))
    got = mitsuba_fcos(mi, mi.load_dict(e.material), wi[::every], wo[::every])
    # float32 in Mitsuba: ~10 roundings (test_export), amplified in sharp peaks, where the
    # half vector's float32 rounding enters D through (h / alpha)^2: measured relative
    # differences 2.5e-5 at alpha 0.01, 1.3e-4 at 0.001 (f ~ 1e5), 1e-3 at 1e-4 (f ~ 4e6),
    # 2.5e-3 for alphas 0.05 x 1e-4
    rtol = 5e-3
    if every > 1:
        if e.exact:
            scale = np.abs(ref).max()
            np.testing.assert_allclose(got, ref[::every], rtol=rtol, atol=1e-6 * scale + 1e-12)
        return
    if e.exact:  # Mitsuba's own error is then float32 noise, up to 2e-4 in sharp peaks
        np.testing.assert_allclose(got, ref, rtol=rtol, atol=1e-6 * np.abs(ref).max() + 1e-12)
        return
    # float32 evaluation in Mitsuba: 1% of the error (principled's clear coat at gloss 1,
    # alpha 0.001, cancels in 1 + (a^2 - 1) cos^2: 0.5% of the log error), or the float32
    # noise of sharp peaks (above: up to 2e-4 relative, 3e-5 in the RMS error)
    assert close(rel_rms(got, ref), e.error, 1e-2, 3e-4), (rel_rms(got, ref), e.summary())
    assert close(log_err(got, ref), e.log_error, 1e-2, 3e-5), e.summary()


def check_gltf(e, ref, wi, wo) -> None:
    """Strict JSON, schema ranges; the spec's BRDF from the JSON gives the reported error."""
    mat = check_gltf_document(load_gltf(e.files[".gltf"]))
    got = gltf_brdf(mat, wi, wo) * wi[:, 2:3]
    # float64 both sides
    assert close(rel_rms(got, ref), e.error, 1e-7, 1e-12), e.summary()
    assert close(log_err(got, ref), e.log_error, 1e-7, 1e-12), e.summary()
    if e.exact:  # EXACT_TOL bounds the RMS: a snapped 1e-16 lobe differs by 1e-8 pointwise
        np.testing.assert_allclose(got, ref, rtol=1e-8, atol=1e-7 * np.abs(ref).max() + 1e-15)


def check_exports(mi, spec: str, params: dict, tmp_path, fit: bool = False, every: int = 1):
    """Export ``spec`` at ``params`` to every target it supports and check each file;
    Mitsuba evaluates every ``every``-th direction pair (1: all, and the errors)."""
    r = result(spec, params)
    targets = check_targets(models.from_spec(spec), "mitsuba,gltf,materialx")
    wi, wo = error_directions()
    ref = model_fcos(r, wi, wo)
    if not np.all(np.isfinite(ref)):  # the model itself cannot be evaluated there
        with pytest.raises(ExportValueError, match="not finite"):
            write_exports(r, targets, tmp_path / "x")
        assert not list(tmp_path.glob("x.*"))
        return
    for target in targets:
        e = export(r, target, fit=fit)
        for text in e.files.values():
            check_numbers(text)
        if target == "mitsuba":
            check_mitsuba(mi, e, ref, wi, wo, tmp_path, every)
            assert e.target_model.startswith(e.material["type"])
        elif target == "gltf":
            check_gltf(e, ref, wi, wo)
        else:
            check_materialx(e, ref, wi, wo)


def check_materialx(e, ref, wi, wo) -> None:
    """XML with every input in the nodedef's range; MaterialX's own graph
    (tests/references_openpbr.py) on the written inputs gives the reported error."""
    assert ET.fromstring(e.files[".mtlx"]).tag == "materialx"
    got = open_pbr_brdf(openpbr_inputs(e.files[".mtlx"]), wi, wo) * wi[:, 2:3]
    # float64 both sides, 9 digits written: ~1e-9 relative per value, so 1e-5 of the error
    # or 1e-7 absolute (an exact export's error is round-off, the written digits' is 1e-9)
    assert close(rel_rms(got, ref), e.error, 1e-5, 1e-7), (rel_rms(got, ref), e.summary())
    assert close(log_err(got, ref), e.log_error, 1e-5, 1e-7), e.summary()
    if e.exact:
        np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-7 * np.abs(ref).max() + 1e-15)


@pytest.mark.parametrize("which", range(4), ids=["low", "near_low", "near_high", "high"])
@pytest.mark.parametrize("spec", SPECS)
def test_every_model_exports_at_its_bounds(mi, spec, which, tmp_path):
    check_exports(mi, spec, corner(spec, which), tmp_path, every=8)  # Mitsuba: 50 ms -> 7


def values(lo: float, hi: float) -> st.SearchStrategy[float]:
    """A bound, a hair inside one, or any float between."""
    inside = st.floats(lo, hi, allow_nan=False, allow_infinity=False, allow_subnormal=lo == 0)
    return st.one_of(st.sampled_from(edges(lo, hi)), inside)


@settings(max_examples=2, deadline=None, derandomize=True)
@given(data=st.data())
@pytest.mark.parametrize("spec", SPECS)
def test_every_model_exports_at_drawn_parameters(mi, spec, data, tmp_path_factory):
    params = {
        n: data.draw(st.lists(values(lo, hi), min_size=3, max_size=3) if s else values(lo, hi))
        for n, s, lo, hi in rows(spec)
    }
    check_exports(mi, spec, params, tmp_path_factory.mktemp("x"))


@pytest.mark.parametrize(  # least squares costs 1-10 s an export: two corners only
    "spec,which", [("ward", 2), ("blinn_phong", 1)], ids=["ward-near_high", "phong-near_low"]
)
def test_fitted_exports_at_bounds(mi, spec, which, tmp_path):
    check_exports(mi, spec, corner(spec, which), tmp_path, fit=True)


@pytest.mark.parametrize(
    "spec,params,target",
    [
        ("walter[grey=ks]", {"kd": [1e-40, 0.3, 0.1], "ks": 0.5, "alpha": 0.2}, "mitsuba"),
        ("walter[diffuse=false,specular_weight=false]", {"f0": [1e-40, 1.0, 0.3]}, "mitsuba"),
        ("disney[clearcoat=false]", {"metallic": 1.0, "sheen_tint": 1e-39}, "mitsuba"),
        ("disney[clearcoat=false]", {"metallic": 1.0, "specular_tint": 6.1e-19}, "mitsuba"),
        ("lambert", {"kd": [1e-40, 1.0 - 1e-16, 0.5]}, "gltf"),
        ("openpbr", {"base_color": [1e-40, 1.0 - 1e-16, 0.5]}, "materialx"),
    ],
)
def test_exact_mappings_stay_exact_at_extreme_values(mi, spec, params, target, tmp_path):
    model = models.from_spec(spec)
    full = {n: np.asarray(v).tolist() for n, v in model.defaults().items()} | params
    e = export(result(spec, full), target)
    assert e.exact and e.error <= EXACT_TOL, e.summary()
    for text in e.files.values():
        check_numbers(text)
    if target == "mitsuba":
        mi.load_dict(e.material)
        (tmp_path / "m.xml").write_text(e.files[".mitsuba.xml"])
        mi.load_file(str(tmp_path / "m.xml"))


def test_non_finite_parameters_are_refused_by_name_before_writing(tmp_path):
    r = result("walter", {"kd": [0.2, float("nan"), 0.1], "ks": 0.5, "f0": 0.04, "alpha": 0.2})
    with pytest.raises(ExportValueError, match="'kd'") as info:
        write_exports(r, "mitsuba,gltf", tmp_path / "w")
    assert info.value.parameter == "kd" and not list(tmp_path.iterdir())
