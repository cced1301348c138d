"""Model reduction (brdffit.simplify): synthetic data made without a feature lose it, data
made with it keep it; a move refused and taken later reads "deferred" in the path; the grey
and neutral variants' spec round trips; typed errors.

Small strided MERL sub-grids (stride 5, 5, 9: 6,480 cells, about 3,000 inside the 80-degree
cut) and 5% multiplicative noise keep each search to a few seconds once compiled; both
walter searches share one grid, so their variants compile once.
"""

from __future__ import annotations

import json
import math

import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from brdffit import ParameterError, Reduction, models, simplify, synthesize, write_sweep_html
from brdffit.cli import main
from brdffit.engine import metrics
from brdffit.engine.block_errors import block_cells, block_index
from brdffit.errors import SweepError
from brdffit.models._restrict import Restricted, make_neutral
from brdffit.report import write_report
from brdffit.selection import variants
from brdffit.selection.folds import deal_blocks, fold_t, keep_threshold, sign_count
from brdffit.selection.reduction import DECISIONS, PathRow
from brdffit.selection.simplify import _mark_deferred
from brdffit.selection.survival import has_reduction, survival_table
from brdffit.sweep import run_sweep, synthetic_materials
from tests.helpers import random_pairs

STRIDE = (5, 5, 9)
NO_DIFFUSE = models.get("walter", diffuse=False)


def _walter_data(f0, seed: int):
    truth = {"ks": 0.6, "f0": f0, "alpha": 0.15}
    return synthesize(NO_DIFFUSE, truth, stride=STRIDE, noise_mult=0.05, seed=seed)


@pytest.fixture(scope="module")
def coloured_reduction() -> Reduction:
    # screen=8: the start model's fit needs fewer screened starts on this easy problem.
    # The start has no diffuse term already (the data have none): 11 variants compiled
    # from plain walter, fewer from here. 52-92 s on 2 cores: its two tests are slow; the
    # Lambert reductions below keep the same checks in the default suite.
    return simplify(NO_DIFFUSE, _walter_data([0.9, 0.6, 0.3], seed=3), screen=8)


@pytest.fixture(scope="module")
def lambert_reductions() -> dict[str, Reduction]:
    """Lambert reduced from grey and from coloured albedo data (one variant, grey kd; 11 s
    on 2 cores, nearly all compilation, which the second search reuses)."""
    lam = models.get("lambert")
    out = {}
    for name, kd in (("grey", 0.5), ("coloured", [0.9, 0.6, 0.3])):
        data = synthesize(lam, {"kd": kd}, stride=STRIDE, noise_mult=0.05, seed=3)
        out[name] = simplify(lam, data, screen=8)
    return out


def test_a_feature_the_data_lack_goes_and_the_reduction_tables_plots_and_saves(
    lambert_reductions,
):
    r = lambert_reductions["grey"]
    md = r.table("markdown")
    assert "| lambert |" in md and "t > 2.13" in md and "| grey kd |" in md
    assert r.chosen == "lambert[grey=kd]" and np.shape(r.result.params["kd"]) == ()
    assert r.result.params["kd"] == pytest.approx(0.5, rel=0.01)
    ax = r.plot()  # every variant, the path, the chosen star
    assert ax.get_xlabel() == "free parameters" and len(ax.lines) == 3
    d = json.loads(r.to_json())
    assert d["start"] == "lambert" and d["chosen"] == "lambert[grey=kd]"
    assert d["removed"] == ["grey kd"] and d["kept"] == []
    assert [row["decision"] for row in d["path"]] == ["start", "chosen"]
    assert r.criterion == "cv" and r.folds == 5 and 0 < r.cost_ratio < math.inf


def test_a_colour_the_data_have_stays(lambert_reductions):
    r = lambert_reductions["coloured"]
    assert r.chosen == "lambert" and r.to_dict()["kept"] == ["RGB kd"]
    assert [row.decision for row in r.path] == ["chosen", "kept"]
    np.testing.assert_allclose(r.result.params["kd"], [0.9, 0.6, 0.3], rtol=0.01)


@pytest.mark.slow  # 32 s; the Lambert reductions above keep simplify in the default suite
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


@pytest.mark.slow  # 48 s (two steps, each variant's CV folds); coloured_reduction is fast
def test_walter_without_diffuse_finds_the_generating_variant():
    # the diffuse term goes, the specular weight stays, ks and f0 turn grey: the truth.
    # How often this holds over seeds is benchmarks/simplify_recovery.py's job.
    r = simplify(models.get("walter"), _walter_data(0.3, seed=2), screen=8)
    print(r.table())
    assert r.chosen == "walter[diffuse=false,grey=ks+f0]"
    assert r.result.n_free < r.full.n_free == 10
    assert np.allclose(r.result.params["f0"], 0.3, rtol=0.05)  # 5% noise
    assert [row.decision for row in r.path].count("chosen") == 1
    assert r.path[0].decision == "start" and r.criterion == "cv" and r.folds == 5
    assert 0 < r.cost_ratio < math.inf


@pytest.mark.slow  # the fixture's 52-92 s; the Lambert tests above check the same
def test_reduction_table_plot_and_json(coloured_reduction):
    r = coloured_reduction
    md = r.table("markdown")
    assert "| walter[diffuse=false] |" in md and "t > 2.13" in md and r.chosen in md
    ax = r.plot()
    assert ax.get_xlabel() == "free parameters" and len(ax.lines) == 3
    d = r.to_dict()
    assert d["chosen"] == r.chosen and d["start"] == "walter[diffuse=false]"
    assert len(d["path"]) == len(r.path)
    assert '"chosen": "walter[diffuse=false,grey=ks]"' in r.to_json()
    assert d["removed"] == list(r.removed)
    # made with f0 (0.9, 0.6, 0.3), not 0.04, and coloured
    assert d["kept"] == ["specular_weight", "RGB f0", "free f0"]
    assert [row.decision for row in r.path].count("chosen") == 1
    assert r.path[0].decision == "start" and r.criterion == "cv" and r.folds == 5
    assert 0 < r.cost_ratio < math.inf


@pytest.mark.slow  # the fixture's 52-92 s; a coloured Lambert albedo stays above
def test_coloured_specular_keeps_its_colour(coloured_reduction):
    r = coloured_reduction
    print(r.table())
    assert "diffuse=false" in r.chosen
    assert np.shape(r.result.params["f0"]) == (3,)
    assert np.allclose(r.result.params["f0"], [0.9, 0.6, 0.3], rtol=0.05)


def test_simplify_table_defers_a_change_taken_later():
    """A move refused at step 1 and taken at step 2 reads 'deferred', not 'kept'."""

    def row(step, change, decision):
        return PathRow(step, f"w[{change}]", change, 8, 1.0, 1.0, np.nan, np.nan, decision)

    path = [
        row(0, "-", "start"),
        row(1, "grey ks", "kept"),
        row(1, "diffuse=false", "removed"),
        row(1, "grey kd", "kept"),
        row(2, "grey ks", "chosen"),
    ]
    got = [r.decision for r in _mark_deferred(path)]
    assert got == ["start", "deferred", "removed", "kept", "chosen"]
    assert set(got) <= set(DECISIONS)


def test_fold_t_and_threshold_against_scipy():
    r = np.array([0.3, -0.1, 0.8, 0.25, 0.4])
    assert math.isclose(fold_t(r), stats.ttest_1samp(r, 0.0).statistic, rel_tol=1e-12)
    assert fold_t(np.zeros(5)) == 0.0 and fold_t(np.full(5, 0.2)) == math.inf
    assert math.isclose(keep_threshold(5), 2.131846786, rel_tol=1e-9)  # t table, 4 d.o.f.


@pytest.mark.parametrize("stride", [STRIDE, (9, 9, 15), (3, 3, 5)])
def test_deal_blocks_spreads_every_band_over_every_fold(stride):
    data = synthesize(NO_DIFFUSE, {"f0": 0.5}, stride=stride)
    prep = metrics.prepare(data, metrics.get_metric("low_e2"))
    fold = deal_blocks(prep, 5, seed=3)
    ids, n_blocks = block_index(prep)
    i, j = block_cells(prep)
    assert all(len(set(fold[ids == b])) == 1 for b in range(n_blocks))  # whole blocks
    for band in (i, j):  # a theta_h or theta_d band of k blocks reaches min(k, 5) folds
        for v in np.unique(band):
            blocks = np.unique(ids[band == v])
            assert len({fold[ids == b][0] for b in blocks}) == min(len(blocks), 5), v


def test_sign_count_is_the_binomial_tail():
    # P(all 5 of 5) = 1/32 = 0.031; for 10 folds P(>= 9) = 11/1024 = 0.011 and
    # P(>= 8) = 56/1024 = 0.055 > 0.05; 4 folds cannot reach 5% (1/16 = 0.0625)
    assert (sign_count(5), sign_count(10), sign_count(4)) == (5, 9, 5)


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
    assert isinstance(m, Restricted) and models.label(m) == canonical
    assert models.from_spec(models.label(m)) == m
    assert models.label(m.name, m.options()) == canonical  # as a FitResult stores it
    assert models.split_specs(f"lambert,{canonical}") == ["lambert", canonical]
    # a grey variant is its base with equal channels, exactly
    params = {p.name: p.default_array() for p in m.parameters}
    wi, wo = random_pairs(0, 64)
    base = {k: jnp.broadcast_to(v, (3,)) if k in m.grey else v for k, v in params.items()}
    assert np.array_equal(m.eval(params, wi, wo), m.base.eval(base, wi, wo))


def test_grey_of_nothing_is_the_base_and_bad_names_are_typed_errors():
    assert models.get("walter", grey=()) == models.get("walter")
    with pytest.raises(ParameterError, match="grey=alpha names no free RGB parameter"):
        models.from_spec("walter[grey=alpha]")
    with pytest.raises(ParameterError, match="its RGB parameters: ks\\+f0"):
        models.from_spec("walter[diffuse=false,grey=kd]")
    with pytest.raises(ParameterError, match="grey=f0 names no free RGB.*parameters: kd\\+ks$"):
        models.from_spec("walter[neutral=f0,grey=f0]")  # pinned: no channels left to tie


@pytest.mark.parametrize(
    ("spec", "canonical", "pinned"),
    [
        ("disney[neutral=sheen_tint+specular]", "disney[neutral=specular+sheen_tint]",
         {"specular": 0.5, "sheen_tint": 0.0}),
        ("walter[neutral=f0,grey=kd]", "walter[grey=kd,neutral=f0]", {"f0": [0.04] * 3}),
        ("std[fresnel=dielectric,neutral=gamma+eta]", "std[neutral=eta+gamma]",
         {"eta": 1.5, "gamma": 2.0}),
        ("filament[neutral=reflectance]", "filament[neutral=reflectance]", {"reflectance": 0.5}),
    ],
)  # fmt: skip
def test_neutral_spec_round_trip_is_the_base_at_the_neutral_values(spec, canonical, pinned):
    m = models.from_spec(spec)
    assert isinstance(m, Restricted) and models.label(m) == canonical
    assert models.from_spec(models.label(m)) == m
    assert models.label(m.name, m.options()) == canonical
    names = {p.name for p in m.parameters}
    assert not names & set(pinned) and len(names) + len(pinned) == len(m.base.parameters)
    # the published values: Disney's and Filament's 0.5 mean F0 = 0.04, ((1.5-1)/(1.5+1))^2
    params = {p.name: p.default_array() for p in m.parameters}
    wi, wo = random_pairs(1, 64)
    base = {k: jnp.broadcast_to(v, (3,)) if k in m.grey else v for k, v in params.items()}
    base |= {k: jnp.asarray(v, float) for k, v in pinned.items()}
    assert np.array_equal(m.eval(params, wi, wo), m.base.eval(base, wi, wo))


def test_neutral_names_a_parameter_with_a_neutral_value():
    assert models.get("walter", neutral=()) == models.get("walter")
    with pytest.raises(ParameterError, match="neutral=alpha names no parameter with a neutral "
                       "value; those with one: f0"):  # fmt: skip
        models.from_spec("walter[neutral=alpha]")
    with pytest.raises(ParameterError, match="neutral=roughness.*specular\\+sheen_tint"):
        models.from_spec("disney[neutral=roughness]")
    # a grey parameter pinned stops being grey
    m = make_neutral(models.from_spec("walter[grey=ks+f0]"), "f0")
    assert models.label(m) == "walter[grey=ks,neutral=f0]"


def test_bad_criterion_and_folds_are_typed_errors():
    data = _walter_data(0.3, seed=2)
    with pytest.raises(ParameterError, match="criterion='aic'.*cv, bic"):
        simplify(models.get("walter"), data, criterion="aic")
    with pytest.raises(ParameterError, match="folds=1"):
        simplify(models.get("walter"), data, folds=1)


@pytest.mark.slow  # 30-38 s: a sweep with --simplify, twice (resume); slow tier
def test_sweep_simplify_stores_the_reduction_resumes_and_tables_the_survivors(tmp_path, capsys):
    # two synthetic walter materials: plastic (coloured kd, grey specular weight, f0 0.04)
    # and metal (kd up to 0.03, coloured f0); stride as above, so the variants compiled
    # by the tests before are reused
    out = tmp_path / "sweep"
    cmd = ["sweep", str(out), "--synthetic", "2", "--models", "walter", "--jobs", "1"]
    cmd += ["--stride", *map(str, STRIDE), "--screen", "8", "--restarts", "0", "--no-progress"]
    assert main([*cmd, "--simplify"]) == 0
    files = sorted(out.glob("*/walter__low_e2.json"))
    assert len(files) == 2
    for p in files:
        d = json.loads(p.read_text())
        red = d["simplify"]
        assert red["criterion"] == "cv" and red["start"] == "walter" and red["n_free_full"] == 10
        assert red["n_free"] < 10 and red["loss_ratio"] >= 1 - 1e-9  # the start nests them all
        assert models.label(models.from_spec(red["chosen"])) == red["chosen"]
        assert red["path"][0]["decision"] == "start" and red["removed"]
    plastic = json.loads(files[0].read_text())["simplify"]  # syn00-plastic: kd is coloured
    assert "RGB kd" in plastic["kept"] and "diffuse" in plastic["kept"]
    assert "free f0" not in plastic["kept"]  # made with f0 0.04: held at its neutral value
    stamps = [p.stat().st_mtime_ns for p in files]
    again = run_sweep(out, synthetic_materials(2), ["walter"], ["low_e2"], stride=STRIDE,
                      screen=8, n_restarts=0, jobs=1, progress=False, simplify="cv")  # fmt: skip
    assert again.n_skipped == 2 and [p.stat().st_mtime_ns for p in files] == stamps
    assert not has_reduction(files[0], "bic") and has_reduction(files[0], "cv")
    text = survival_table(out)
    assert "### syn00-plastic" in text and "### Features that survive" in text
    n_kd = sum("RGB kd" in json.loads(p.read_text())["simplify"]["kept"] for p in files)
    assert f"| walter | low_e2 | RGB kd | {n_kd} of 2 |" in text
    report = write_report(out, n_boot=50).read_text()  # the sweep report carries the table
    assert "## Model reduction (sweep --simplify)" in report and text.strip() in report
    page = write_sweep_html(out, n_boot=50).read_text()
    assert "Model reduction (sweep --simplify)" in page and "syn00-plastic" in page
    with pytest.raises(SweepError, match="simplify='aic'"):
        run_sweep(out, synthetic_materials(2), ["walter"], ["low_e2"], stride=STRIDE,
                  simplify="aic", jobs=1, progress=False)  # fmt: skip


def test_a_lone_lobe_left_takes_the_unindexed_names():
    """walter names one lobe ``ks``/``f0``/``alpha`` and two ``ks_1``.. ``alpha_2``: dropping
    lobe 1 starts the one-lobe child from lobe 2's values, with the grey option moved."""
    two = models.from_spec("walter[n_lobes=2,grey=ks_2]")
    rows = {p.name: np.full((1,) + p.shape, 0.1 * (i + 1)) for i, p in enumerate(two.parameters)}
    moves = {m[2]: m for m in variants.moves(two, rows)}
    child, start, _, drop = moves["n_lobes=1"]
    assert drop == 1 and models.label(child) == "walter[grey=ks]"
    assert [p.name for p in child.parameters] == ["kd", "ks", "f0", "alpha"]
    for name in ("ks", "f0", "alpha"):
        np.testing.assert_allclose(start[name], np.mean(rows[name + "_2"], axis=-1, keepdims=True)
                                   if name == "ks" else rows[name + "_2"])  # fmt: skip
    assert variants.lobe_name("ks_1", ["ks", "kd"]) == "ks"
    assert variants.lobe_name("cx_1", ["cx_1"]) == "cx_1"  # Lafortune keeps its index
    assert variants.lobe_name("ks_2", ["ks"]) == "ks_2"


@pytest.mark.slow  # 21 -> 8 parameters, 20 variants compiled: 7 min on a busy 2-core box
def test_walter_drops_a_second_lobe_and_a_sheen_the_data_lack():
    truth = {"kd": [0.3, 0.2, 0.1], "ks": 0.5, "f0": [0.9, 0.6, 0.3], "alpha": 0.15}
    data = synthesize(models.get("walter"), truth, stride=STRIDE, noise_mult=0.05, seed=4)
    r = simplify(models.get("walter", n_lobes=2, sheen=True), data, criterion="bic", screen=8)
    print(r.table())
    assert r.chosen == "walter[grey=ks]"  # the truth: one lobe, grey ks, no sheen
    assert np.isclose(float(r.result.params["alpha"]), 0.15, rtol=0.05)
