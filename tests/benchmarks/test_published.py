"""The published-fit comparison's parts (``benchmarks/published_record.py``): the fit-file
reader, the scorer, and the maps between brdffit's parameters and the published forms.

The maps are checked through the published form itself: a brdffit parameter set written
as a bbm string and evaluated by the published formula must give brdffit's model's
values. Where the published form is evaluated by bbm's C++ (``benchmarks/published/bbm.py``,
built by ``benchmarks/published/build_bbm_eval.sh``), that check needs the binary and is
skipped without it; the Blinn-Phong reading is NumPy and always runs.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.published import bbm, score
from benchmarks.published.families import FAMILIES, blinn_reading
from benchmarks.published.fitfile import parse_line, read_fit_file
from brdffit import models
from brdffit.core.measurements import Measurements
from brdffit.engine.metrics import get_metric, prepare
from brdffit.engine.misfit import loss
from tests.helpers import random_pairs


def test_every_vendored_fit_file_parses_with_its_published_material_count():
    counts = {f.file: len(read_fit_file(f.file)) for f in FAMILIES.values()}
    assert all(n == (86 if name.startswith("ngan_") else 100) for name, n in counts.items())
    fit = read_fit_file("ngan_ward.fit")["blue-acrylic"]
    assert [c.cls for c in fit.components] == ["Lambertian", "NganWard"]
    assert fit.component("NganWard").params == {"albedo": [0.00774, 0.00547, 0.00339],
                                                "roughness": 0.0162}  # fmt: skip


def test_a_line_keeps_nested_lists_and_signs_and_rejects_code():
    fit = parse_line("m = Aggregate(Lambertian(albedo = [1e-3, 0.5, 2]), X(eta = [[1, -2.5]]))")
    assert fit.component("X").params == {"eta": [[1.0, -2.5]]}
    with pytest.raises(ValueError, match="not a number"):
        parse_line("m = X(a = __import__('os'))")


def _data(model, params, n=4000, seed=3) -> Measurements:
    wi, wo = random_pairs(seed, n)
    values = np.asarray(model.eval(params, wi, wo)) * np.exp(
        0.05 * np.random.default_rng(seed).standard_normal((n, 3))
    )
    return Measurements.from_directions(wi, wo, values, source="synthetic")


@pytest.mark.parametrize("metric", score.METRICS)
def test_the_scorer_equals_brdffits_own_losses(metric):
    # Two implementations of the papers' metrics, written separately, on the same cells.
    m = models.get("walter")
    truth = {"kd": [0.2, 0.3, 0.1], "ks": [0.5, 0.5, 0.5], "f0": [0.9, 0.8, 0.7], "alpha": 0.2}
    data = _data(m, truth)
    near = {"kd": [0.25, 0.3, 0.1], "ks": [0.4, 0.5, 0.6], "f0": [0.9, 0.8, 0.7], "alpha": 0.25}
    near = {k: np.asarray(v, float) for k, v in near.items()}
    at = score.cells(data)
    mine = score.loss(metric, np.asarray(m.eval(near, data.wi[at.index], data.wo[at.index])), at)
    prep = prepare(data, get_metric(metric))
    theirs = float(loss(m.evaluate(near, prep.g), prep))
    assert mine == pytest.approx(theirs, rel=1e-12)


def test_blinn_phong_map_and_reading_reproduce_brdffits_model():
    fam = FAMILIES["ngan_blinnphong"]
    m = models.from_spec(fam.spec)
    params = {"kd": np.array([0.1, 0.2, 0.3]), "ks": np.array([0.4, 0.3, 0.2]), "n": 350.0}
    wi, wo = random_pairs(5, 2000)
    want = np.asarray(m.eval(params, wi, wo))
    got = fam.reading(fam.to_published(params), wi, wo)
    np.testing.assert_allclose(got, want, rtol=1e-12)
    back = fam.from_published(parse_line("x = " + fam.to_published(params)))
    assert float(back["n"]) == 350.0
    np.testing.assert_allclose(back["ks"], params["ks"], rtol=1e-14)


def test_the_blinn_reading_is_kd_over_pi_at_the_horizon_and_the_lobe_at_the_peak():
    wi = np.array([[0.0, 0.0, 1.0]])
    got = blinn_reading(
        "Aggregate(Lambertian(albedo = [0.3, 0.3, 0.3]), "
        "NganBlinnPhong(albedo = [0.1, 0.1, 0.1], sharpness = 100.0))",
        wi,
        wi,
    )
    np.testing.assert_allclose(got, 0.3 / math.pi + 0.1 * 102 / (2 * math.pi), rtol=1e-14)


@pytest.mark.parametrize("key", [k for k, f in FAMILIES.items() if f.from_published])
def test_every_published_fit_maps_into_its_models_table(key):
    fam = FAMILIES[key]
    names = {p.name for p in models.from_spec(fam.spec).parameters}
    for fit in read_fit_file(fam.file).values():
        mapped = fam.from_published(fit)
        assert names <= set(mapped), (key, fit.material)
        assert all(np.all(np.isfinite(np.asarray(v, float))) for v in mapped.values())


@pytest.mark.skipif(not bbm.available(), reason="bbm_eval not built (build_bbm_eval.sh)")
@pytest.mark.parametrize("key", [k for k, f in FAMILIES.items() if f.to_published])
def test_a_brdffit_fit_written_as_its_published_form_is_the_same_function(key):
    # bbm's C++ evaluates the published form: the map and the formula are checked together.
    fam = FAMILIES[key]
    m = models.from_spec(fam.spec)
    material = sorted(read_fit_file(fam.file))[7]
    start = fam.from_published(read_fit_file(fam.file)[material])
    params = {p.name: np.asarray(start[p.name], float) for p in m.parameters}
    wi, wo = random_pairs(11, 3000)
    want = np.asarray(m.eval(params, wi, wo))
    got = (fam.reading or bbm.evaluate)(fam.to_published(params), wi, wo)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * np.max(want))
