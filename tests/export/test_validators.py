"""Every glTF export passes the Khronos glTF Validator with no error, warning or info, and
every MaterialX export validates against MaterialX's own library and generates GLSL
(:mod:`tests.export.validators`). Covered: the exact mappings of ``test_export``, an
inexact (fitted) mapping, and every form ``brdffit material`` fits for each target, at
the model's defaults."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit import models
from brdffit.export import export
from brdffit.export.material import FORMS
from tests.export.test_export import APPROX, EXACT, result
from tests.export.validators import gltf_reports, gltf_validator_modules, mtlx_problems


def _at_defaults(spec: str) -> tuple[str, dict]:
    name, options = models.parse_spec(spec)
    p = models.get(name, **options).defaults()
    return spec, {k: np.asarray(v).tolist() for k, v in p.items()}


def _cases(target: str) -> list[tuple[str, dict]]:
    exact = [(spec, params) for spec, params, targets in EXACT if target in targets]
    fitted = [APPROX[0]] if target in ("gltf", "materialx") else []
    return exact + fitted + [_at_defaults(s) for s in FORMS[target]]


def test_every_gltf_export_passes_the_khronos_validator(tmp_path):
    modules = gltf_validator_modules()
    paths = []
    for k, (spec, params) in enumerate(_cases("gltf")):
        paths.append(tmp_path / f"{k}.gltf")
        paths[-1].write_text(export(result(spec, params), "gltf").files[".gltf"])
    reports = gltf_reports(paths, modules)
    names = {str(p): spec for p, (spec, _) in zip(paths, _cases("gltf"), strict=True)}
    bad = {
        names[f]: r["messages"]
        for f, r in reports.items()
        if r["numErrors"] or r["numWarnings"] or r["numInfos"]
    }
    assert len(reports) == len(paths) and not bad, bad


def test_the_gltf_validator_reports_a_broken_file(tmp_path):
    """The harness reads real reports: a material index past the end is an error."""
    modules = gltf_validator_modules()
    text = export(result(*APPROX[0]), "gltf").files[".gltf"]
    path = tmp_path / "broken.gltf"
    path.write_text(text.replace('"material": 0', '"material": 7'))
    (report,) = gltf_reports([path], modules).values()
    assert report["numErrors"] >= 1, report


@pytest.mark.parametrize("spec,params", _cases("materialx"), ids=lambda v: str(v)[:60])
def test_every_materialx_export_validates_with_the_materialx_library(spec, params):
    text = export(result(spec, params), "materialx").files[".mtlx"]
    assert mtlx_problems(text) == []


def test_materialx_validation_finds_what_is_wrong():
    """A misspelt input, a wrong type, a misspelt node and a broken link are each found."""
    text = export(result("lambert", {"kd": [0.2, 0.3, 0.1]}), "materialx").files[".mtlx"]
    assert mtlx_problems(text) == []
    broken = [
        text.replace('name="base_color"', 'name="base_colour"'),
        text.replace('name="base_metalness" type="float"', 'name="base_metalness" type="color3"'),
        text.replace("<open_pbr_surface ", "<open_pbr_surfac ").replace(
            "</open_pbr_surface>", "</open_pbr_surfac>"
        ),
        text.replace('nodename="SR_', 'nodename="XX_'),
    ]
    for b in broken:
        assert b != text and mtlx_problems(b), b
