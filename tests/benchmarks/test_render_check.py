"""The render check of ``benchmarks/render_check.py`` on a small Lambertian ``.bsdf`` file.

The file tabulates ``albedo / pi`` (:func:`tests.rgl_fixture.lambert_file`); ``lambert``
fitted to it and exported to Mitsuba (``diffuse``) must render like Mitsuba's ``measured``
plugin on the file, and a material 10% too dark must be caught. The benchmark's run goes
on past an unreadable file and reports it.
"""

from pathlib import Path

import numpy as np
import pytest

import brdffit
from benchmarks.render_check import main, render_check, sphere_mask
from brdffit import models
from tests.rgl_fixture import lambert_file

pytest.importorskip("mitsuba")  # both renders and the reader run Mitsuba

ALBEDO = (0.6, 0.4, 0.2)


def test_sphere_mask_keeps_whole_pixels_on_the_disc():
    mask = sphere_mask(32)
    assert mask[16, 16] and not mask[0, 0] and mask.sum() > 0.85 * np.pi * (32 / 2 / 1.05) ** 2
    np.testing.assert_array_equal(mask, mask[::-1])  # symmetric about both axes
    np.testing.assert_array_equal(mask, mask[:, ::-1])


def test_lambert_fit_renders_like_the_measured_file(tmp_path: Path):
    path = lambert_file(tmp_path / "lambert.bsdf", ALBEDO)
    result = brdffit.fit(models.get("lambert"), brdffit.read_rgl(path, stride=(9, 9, 15)), "low_e2")
    exported = brdffit.export.export(result, "mitsuba")
    assert exported.material["type"] == "diffuse"
    dark = np.asarray(exported.material["reflectance"]["value"]) * 0.9
    wrong = {"type": "diffuse", "reflectance": {"type": "rgb", "value": dark.tolist()}}
    check = render_check(path, {"fit": exported.material, "dark": wrong}, res=32, spp=64)
    fit, bad = check["fit"], check["dark"]
    # The table's interpolation error is below 1.1% of albedo / pi
    # (rgl_fixture.lambert_error_bound(33)); the fit recovers the albedo to 0.3%; the
    # environment's mean over ~650 pixels x 64 spp has ~0.3% noise: 2% leaves a margin.
    np.testing.assert_allclose(fit["env"]["ratio"], 1.0, atol=0.02)
    np.testing.assert_allclose(bad["env"]["ratio"], 0.9, atol=0.02)
    # Point light: no Monte Carlo noise beyond pixel jitter (same seed): 0.3% measured.
    assert fit["point"]["rel_rmse"] < 0.01 < 0.09 < bad["point"]["rel_rmse"]
    # Environment: per-pixel noise of the measured plugin's uniform sampling dominates;
    # the export must not add more than the noise between two seeds of the file itself.
    assert fit["env"]["rel_rmse"] < check["noise"]["env"]


def test_unreadable_file_is_a_failed_row_and_the_run_goes_on(tmp_path: Path):
    """Garbage bytes named ``.bsdf`` stopped the whole run with no report written."""
    bad = tmp_path / "x.bsdf"
    bad.write_bytes(b"not a tensor file" * 8)
    good = lambert_file(tmp_path / "lambert.bsdf", ALBEDO, n=9)
    out = tmp_path / "report.md"
    # low_e2 at this stride: the fit the test above compiled is reused
    argv = [str(bad), str(good), "--models", "lambert", "--metric", "low_e2"]
    main([*argv, "--stride", "9", "9", "15", "--res", "8", "--spp", "4", "--out", str(out)])
    rows = {line.split(" | ")[0]: line for line in out.read_text().splitlines() if " | " in line}
    assert "| not read |" in rows["| x"] and "failed: MeasurementFileError: " in rows["| x"]
    assert "| lambert -> diffuse |" in rows["| lambert"]  # fitted and rendered
