"""Model reduction (brdffit.simplify): synthetic data made without a feature lose it, data
made with it keep it; the grey variant's spec round trip; typed errors.

Small strided MERL sub-grids (stride 5, 5, 9: 6,480 cells, about 3,000 inside the 80-degree
cut) and 5% multiplicative noise keep each search to a few seconds once compiled; both
walter searches share one grid, so their variants compile once.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from brdffit.models._grey import Grey

from brdffit import ParameterError, Reduction, models, simplify, synthesize
from tests.helpers import random_pairs

STRIDE = (5, 5, 9)
NO_DIFFUSE = models.get("walter", diffuse=False)


def _walter_data(f0, seed: int):
    truth = {"ks": 0.6, "f0": f0, "alpha": 0.15}
    return synthesize(NO_DIFFUSE, truth, stride=STRIDE, noise_mult=0.05, seed=seed)


@pytest.fixture(scope="module")
def grey_reduction() -> Reduction:
    # screen=8: the start model's fit needs fewer screened starts on this easy problem
    return simplify(models.get("walter"), _walter_data(0.3, seed=2), screen=8)


def test_lafortune_two_lobes_reduce_to_one_by_bic():
    # grey kd from the start: fewer variants to compile, and the drop of a lobe must carry
    # the grey option along (a lobe's grey name moves with the lobe)
    truth = {"kd": 0.3, "rho_1": [0.5, 0.4, 0.3], "cxy_1": -1.0, "n_1": 40.0}
    made = models.from_spec("lafortune[grey=kd]")
    data = synthesize(made, truth, stride=STRIDE, noise_mult=0.05, seed=1)
    start = models.from_spec("lafortune[n_lobes=2,grey=kd]")
    r = simplify(start, data, criterion="bic", screen=8)
    print(r.table())
    assert r.chosen == "lafortune[grey=kd]" and r.result.n_free == 6 and r.full.n_free == 11
    assert [row.decision for row in r.path if row.change == "n_lobes=1"] == ["chosen"]
    for name in ("rho_1", "n_1"):  # the surviving lobe is the generating one
        got, want = np.asarray(r.result.params[name]), np.asarray(truth[name])
        digits = -np.log10(np.max(np.abs(got - want) / np.abs(want)))
        print(f"{name}: {digits:.1f} matching digits")
        assert digits > 1.3  # 5% noise on ~3,000 cells: a few parts per thousand


def test_walter_without_diffuse_drops_it_and_keeps_the_specular_weight(grey_reduction):
    # The diffuse term goes and ks stays on every seed tried; the grey move (the truth is
    # grey) is taken on 4 of 6 seeds only, a narrow one-SE call: not asserted here, it
    # belongs to the recovery benchmark of issue 21.
    r = grey_reduction
    print(r.table())
    assert "diffuse=false" in r.chosen and "specular_weight" not in r.chosen
    assert r.result.n_free < r.full.n_free == 10
    assert np.allclose(r.result.params["f0"], 0.3, rtol=0.05)  # 5% noise
    assert [row.decision for row in r.path].count("chosen") == 1
    assert r.path[0].decision == "start" and r.criterion == "cv" and r.folds == 5
    assert 0 < r.cost_ratio < math.inf


def test_reduction_table_plot_and_json(grey_reduction):
    r = grey_reduction
    md = r.table("markdown")
    assert "| walter[diffuse=false] |" in md and "1-SE rule" in md and r.chosen in md
    ax = r.plot()
    assert ax.get_xlabel() == "free parameters" and len(ax.lines) == 3
    d = r.to_dict()
    assert d["chosen"] == r.chosen and d["start"] == "walter" and len(d["path"]) == len(r.path)
    assert '"chosen": "walter[diffuse=false,grey=ks+f0]"' in r.to_json()


def test_coloured_specular_keeps_its_colour():
    r = simplify(models.get("walter"), _walter_data([0.9, 0.6, 0.3], seed=3), screen=8)
    print(r.table())
    assert "diffuse=false" in r.chosen
    assert np.shape(r.result.params["f0"]) == (3,)
    assert np.allclose(r.result.params["f0"], [0.9, 0.6, 0.3], rtol=0.05)


@pytest.mark.parametrize(
    ("spec", "canonical"),
    [
        ("walter[grey=f0+ks]", "walter[grey=ks+f0]"),
        ("walter[grey=f0,diffuse=false]", "walter[diffuse=false,grey=f0]"),
        ("lafortune[grey=rho_2+kd,n_lobes=2]", "lafortune[n_lobes=2,grey=kd+rho_2]"),
    ],
)
def test_grey_spec_round_trip(spec, canonical):
    m = models.from_spec(spec)
    assert isinstance(m, Grey) and models.label(m) == canonical
    assert models.from_spec(models.label(m)) == m
    assert models.label(m.name, m.options()) == canonical  # as a FitResult stores it
    assert models.split_specs(f"lambert,{canonical}") == ["lambert", canonical]
    # a grey variant is its base with equal channels, exactly
    params = {p.name: p.default_array() for p in m.parameters}
    wi, wo = random_pairs(0, 64)
    base = {k: jnp.broadcast_to(v, (3,)) if k in m.names else v for k, v in params.items()}
    assert np.array_equal(m.eval(params, wi, wo), m.base.eval(base, wi, wo))


def test_grey_of_nothing_is_the_base_and_bad_names_are_typed_errors():
    assert models.get("walter", grey=()) == models.get("walter")
    with pytest.raises(ParameterError, match="grey=alpha names no RGB parameter"):
        models.from_spec("walter[grey=alpha]")
    with pytest.raises(ParameterError, match="its RGB parameters: ks\\+f0"):
        models.from_spec("walter[diffuse=false,grey=kd]")


def test_bad_criterion_and_folds_are_typed_errors():
    data = _walter_data(0.3, seed=2)
    with pytest.raises(ParameterError, match="criterion='aic'.*cv, bic"):
        simplify(models.get("walter"), data, criterion="aic")
    with pytest.raises(ParameterError, match="folds=1"):
        simplify(models.get("walter"), data, folds=1)
