"""``brdffit material`` (:mod:`brdffit.export.material`): render-space errors against closed
forms, the choice rule, one end-to-end run of the command with its files, and bad input.

The closed forms: a Lambertian measurement ``kd / pi`` and a Lambertian fit ``s kd / pi``
have directional albedos in the ratio ``s`` at every view, and ``f cos(theta_i)`` in the
ratio ``s`` at every direction pair, so both errors are exactly ``|s - 1|`` whatever the
grid, the lookup or the quadrature.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from brdffit import ExportError, MeasurementsError, ParameterError, models, synthesize, write_merl
from brdffit.cli import main
from brdffit.core.result import FitResult
from brdffit.export import export
from brdffit.export.material import (
    FORMS,
    SCORE_TOLERANCE,
    Form,
    RenderError,
    best_material,
    choose,
    render_error,
)

KD = np.array([0.6, 0.4, 0.2])
STRIDE = (9, 9, 15)


def _lambert_result(kd) -> FitResult:
    return FitResult.from_dict(
        {"model": "lambert", "options": {}, "metric": "ngan", "params": {"kd": list(kd)},
         "loss": 0.0, "status": "CONVERGED", "source": "test"}
    )  # fmt: skip


@pytest.fixture(scope="module")
def matte():
    return synthesize(models.get("lambert"), {"kd": KD}, stride=STRIDE)


@pytest.mark.parametrize("scale", [1.0, 1.1, 0.7])
def test_render_error_of_a_scaled_lambert_is_the_scale(matte, scale):
    e = render_error(matte, _lambert_result(scale * KD))
    assert e.albedo == pytest.approx(abs(scale - 1), abs=1e-12)
    assert e.point == pytest.approx(abs(scale - 1), abs=1e-12)
    np.testing.assert_allclose(e.ratio, scale, rtol=1e-12)
    inexact = dataclasses.replace(export(_lambert_result(KD), "mitsuba"), exact=False)
    inexact = dataclasses.replace(inexact, error=0.05, albedo_error=0.02)
    e = render_error(matte, _lambert_result(KD), inexact)
    assert (e.point, e.albedo) == pytest.approx((0.05, 0.02), abs=1e-12)


def test_a_lobe_narrower_than_a_pixel_adds_only_what_it_shows(matte):
    """A fit with a near-delta lobe (alpha 1e-4, F = 1) over the measured body. Under the
    point light a pixel averages it: the error is the lobe's energy in the few pixels whose
    footprint holds the mirror normal (0.06), not its peak (1e7 1/sr). Under the white
    environment it reflects everything: the albedo rises by 1 at every view."""
    r = FitResult.from_dict(
        {"model": "walter", "options": {}, "metric": "ngan", "loss": 0.0,
         "params": {"kd": list(KD), "ks": [1.0] * 3, "f0": [1.0] * 3, "alpha": 1e-4},
         "status": "CONVERGED", "source": "test"}
    )  # fmt: skip
    e = render_error(matte, r)
    assert e.point < 0.1
    body = KD * np.sin(np.radians(80.0)) ** 2  # kd/pi integrated over theta_i < 80 degrees
    # 2%: the half-vector quadrature steps over the 80-degree edge (1.1% on a Lambertian)
    np.testing.assert_allclose(e.ratio, (body + 1.0) / body, rtol=0.02)


def test_the_scoring_directions_are_unit_and_the_sphere_sees_one_light():
    """Every direction the scores evaluate is a unit vector (the light was (3, 3, 4) / 5,
    of length 1.17, so every model saw cos_i 17% high and a wrong half vector), and on the
    point-light sphere the angle between light and viewer is the scene's in every pixel."""
    from brdffit.export.render_score import LIGHT, _albedo_pairs, _sphere_pairs

    wi, wo, _ = _sphere_pairs()
    for v in (wi, wo, *_albedo_pairs()[:2]):
        np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(np.sum(wi * wo, axis=1), LIGHT[2], rtol=1e-12)


def test_choose_takes_the_simplest_form_within_the_tolerance():
    def form(k: int, score: float) -> Form:
        r = dataclasses.replace(_lambert_result(KD), n_free=k)
        return Form(f"f{k}", r, None, RenderError(score, 0.0, (1.0,) * 3, (1.0,) * 3), 0.0)

    forms = [form(3, 0.100), form(9, 0.100 * (1 - SCORE_TOLERANCE / 2)), form(12, 0.05)]
    assert choose(forms).spec == "f12"  # a real gain
    assert choose(forms[:2]).spec == "f3"  # half the tolerance: the simpler stays


def test_material_command_writes_the_chosen_form_and_says_what_it_is(tmp_path, capsys):
    """One of MaterialX's forms (``--forms``): all four took 94 s of the suite's time, two
    42 s, and the choice among forms is :func:`choose`, tested above; here the command
    line is: a fit, its score line, the choice, the file."""
    path = tmp_path / "matte.binary"
    write_merl(path, synthesize(models.get("lambert"), {"kd": KD}, noise_mult=0.01, seed=3))
    prefix = tmp_path / "out" / "matte"
    prefix.parent.mkdir()
    forms = FORMS["materialx"][:1]
    argv = ["material", path, "--target", "materialx", "--out", prefix, "--stride", *STRIDE]
    argv += ["--forms", ",".join(forms), "--reference", "none", "--no-progress"]
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "chosen: openpbr" in out and "render-space error against the measurement" in out
    assert (tmp_path / "out" / "matte.mtlx").is_file()
    assert len([ln for ln in out.splitlines() if "score" in ln and "k=" in ln]) == len(forms)


def test_bad_input_fails_before_any_fit(tmp_path, capsys, matte):
    with pytest.raises(ParameterError, match="unknown model"):
        best_material(matte, "gltf", forms=["gltf", "nosuchmodel"])
    with pytest.raises(ExportError, match="one target"):
        best_material(matte, "gltf,mitsuba")
    scattered = synthesize(models.get("lambert"), {"kd": KD}, grid="random", n=500)
    with pytest.raises(MeasurementsError, match="MERL grid"):
        best_material(scattered, "gltf", reference=None)
    code = main(["material", str(tmp_path / "missing.binary"), "--target", "gltf", "--out", "x"])
    _, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1 and "missing.binary" in err
    with pytest.raises(SystemExit) as stop:  # argparse's own one-line refusal
        main(["material", "f", "--target", "usd", "--out", "x"])
    _, err = capsys.readouterr()
    assert stop.value.code == 2 and err.count("\n") == 1 and "'usd'" in err
