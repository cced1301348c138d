"""The user-facing defects of issue 22, each with the check that caught it.

Masked cells counted by reason in ``brdffit info``; per-channel ``at bound`` flags and
clean values without an error; scalars with huge standard errors named not identified;
losses per sample beside the sums; an unconverged fit with the lowest loss ranked by it
in ``brdffit report``; the Pareto medians over the materials every model has;
``--families``; figures whose labels all lie inside the canvas. (``brdffit sample``
saying what it does and showing each warning once: ``tests/cli/test_cli.py``.)
"""

from __future__ import annotations

import dataclasses
import json
import time

import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import Measurements, Status, fit, models, rank, synthesize
from brdffit.cli import main
from brdffit.core.result import FitResult, per_sample, value_text
from brdffit.engine import metrics as metrics_mod
from brdffit.engine.objective import Objective, all_losses, freeze_map
from brdffit.engine.uncertainty import Outcome, assemble, conditioning, covariance, unidentified
from brdffit.errors import SweepError
from brdffit.report.markdown import write_report
from brdffit.report.selection_figures import pareto_figure, rank_matrix_figure
from brdffit.selection.crossrank import matrices
from brdffit.selection.families import family_of, read_families
from brdffit.selection.pareto import error_vs_time
from brdffit.selection.sweep_results import load_sweep
from tests.sweep_fixtures import make_sweep


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# --------------------------------------------------------------------------- masked cells


def test_info_says_how_many_cells_are_masked_and_why(tmp_path, capsys):
    # a MERL file written by hand: 30% of the cells with a negative blue channel, 10%
    # with every channel negative (MERL's "not measured")
    rng = np.random.default_rng(0)
    shape = (90, 90, 180)
    raw = np.ones((3, *shape))
    one = rng.random(shape) < 0.3
    every = (rng.random(shape) < 0.1) & ~one
    raw[2][one] = -0.5
    raw[:, every] = -1.0
    path = tmp_path / "bad-blue.binary"
    path.write_bytes(np.asarray(shape, "<i4").tobytes() + raw.astype("<f8").tobytes())
    # the horizon from DESIGN.md's closed form at the bin centres, not from brdffit
    th = ((np.arange(90) + 0.5) / 90) ** 2 * np.pi / 2
    td = (np.arange(90) + 0.5) / 90 * np.pi / 2
    pd = (np.arange(180) + 0.5) / 180 * np.pi
    th, td, pd = np.meshgrid(th, td, pd, indexing="ij")
    a, b = np.cos(td) * np.cos(th), np.sin(td) * np.cos(pd) * np.sin(th)
    below = ~((a - b > 0) & (a + b > 0))
    n_below, n_every, n_one = (int(m.sum()) for m in (below, every & ~below, one & ~below))
    assert 0.2 < n_below / below.size < 0.3  # about 24% by geometry alone (DESIGN.md)
    code, out, _ = _run(capsys, "info", path)
    assert code == 0
    line = next(x for x in out.splitlines() if x.startswith("masked"))
    total = n_below + n_every
    # a cell with only its blue negative keeps red and green in the fit (issue 28)
    neg = n_every + n_one
    assert line.split(None, 1)[1] == (
        f"{total:,} of 1,458,000 samples: {n_below:,} below the horizon, {n_every:,} with no "
        f"channel measured; channels masked inside the cut: R {n_every:,} negative (not "
        f"measured), G {n_every:,} negative (not measured), B {neg:,} negative (not measured)"
    )


# --------------------------------------------------------------------------- reports


@pytest.fixture(scope="module")
def oren_nayar_fit():
    # rho[r] and rho[b] on their bounds, rho[g] inside (as in test_fit.py)
    on = models.get("oren_nayar")
    truth = {"rho": [0.0, 0.4857, 1.0], "sigma": 0.3917}
    data = synthesize(on, truth, grid="random", n=2000, seed=3)
    return fit(on, data, "low_e2", init=truth, n_restarts=0, screen=0)


def test_at_bound_names_only_the_channels_on_a_bound(oren_nayar_fit):
    r = oren_nayar_fit
    assert r.at_bound == ("rho[r]", "rho[b]")
    lines = {x.split()[0]: x for x in r.report().splitlines() if x.startswith("    rho")}
    assert "[at bound" not in lines["rho[g]"] and "%" in lines["rho[g]"]
    assert "[at bound" in lines["rho[r]"] and "[at bound" in lines["rho[b]"]
    assert "nan" not in r.report()
    # held on its bound by the active set: the solver's 4e-18 and a NaN error (the issue)
    pinned = dataclasses.replace(
        r,
        params={**r.params, "rho": np.array([4.24835e-18, *r.params["rho"][1:]])},
        stderr={**r.stderr, "rho": np.array([np.nan, *r.stderr["rho"][1:]])},
    )
    line = next(x for x in pinned.report().splitlines() if x.startswith("    rho[r]"))
    assert line.split()[1:6] == ["0", "(at", "bound;", "no", "error)"], line


@pytest.mark.parametrize(
    ("value", "err", "at_bound", "text"),
    [
        (4.24835e-18, float("nan"), True, "0 (at bound; no error)"),  # the line
        (1.0, float("nan"), True, "1 (at bound; no error)"),
        (0.3, float("nan"), False, "0.3 (no error)"),
        (0.0, 0.01, False, "0 +/- 0.01"),  # no relative error of a zero
        (0.5, 0.01, False, "0.5 +/- 0.01 (2.00%)"),
        (0.5, None, False, "0.5 +/- (none)"),
    ],
)
def test_values_without_an_error_print_cleanly(value, err, at_bound, text):
    assert value_text(value, err, at_bound=at_bound) == text


def test_results_written_with_names_read_back_with_per_scalar_labels(oren_nayar_fit):
    d = json.loads(oren_nayar_fit.to_json())
    assert d["at_bound"] == ["rho[r]", "rho[b]"]
    assert FitResult.from_dict(d).at_bound == ("rho[r]", "rho[b]")
    d["at_bound"] = ["rho", "sigma"]  # a result file from before the labels
    assert FitResult.from_dict(d).at_bound == ("rho[r]", "rho[g]", "rho[b]", "sigma")


def _result_at(model, params: dict, data: Measurements, freeze: dict) -> FitResult:
    """The FitResult of ``model`` at ``params`` (no descent): the real error path."""
    params = {k: jnp.asarray(v, float) for k, v in params.items()}
    obj = Objective.build(model, freeze_map(model, freeze, params))
    z = obj.layout.solver_vector(params)
    out = Outcome(
        z=z, status=Status.CONVERGED, binding=np.zeros(z.size, bool),
        start=obj.params(jnp.asarray(z)), n_steps=0, n_starts=1, coarse=(0, 0),
        robust_scale=None,
    )  # fmt: skip
    preps = metrics_mod.prepare_all(data, cut_deg=80.0)
    return assemble(
        obj, metrics_mod.get_metric("low_e2"), out, preps, errors="classic", cut=80.0,
        source="test", t0=time.perf_counter(),
    )  # fmt: skip


def test_a_scalar_with_an_enormous_error_is_named_not_identified_and_warned():
    # the specular lobe's weight at 1e-13: its exponent n barely moves the residuals, so
    # its column of J is tiny but not zero; J^T J scaled by its own columns is perfectly
    # conditioned (the old rule saw nothing), while the error of n is enormous
    bp = models.get("blinn_phong")
    truth = {"kd": [0.2, 0.3, 0.4], "ks": [1e-13] * 3, "n": 50.0}
    data = synthesize(bp, truth, stride=(9, 9, 9), noise_mult=0.03, seed=5)
    r = _result_at(bp, truth, data, {"ks": truth["ks"]})
    assert float(r.stderr["n"]) > 1e6 * 50.0
    assert r.condition_number < 10  # why the column-scaled eigen rule misses it
    assert r.not_identified == ("n",)
    assert any("not identified by the data: n" in w for w in r.warnings)
    assert "[not identified" in next(x for x in r.report().splitlines() if "    n " in x)


def test_unidentified_rule_compares_the_error_with_the_allowed_range():
    layout = Objective.build(models.get("walter")).layout
    labels = layout.labels()
    params = {"kd": np.array([0.2, 0.3, 0.4]), "f0": np.full(3, 0.5), "alpha": 0.01}
    params["ks"] = np.ones(3)
    params = {p.name: params[p.name] for p in layout.free}
    sd = np.full(len(labels), 1e-3)
    sd[labels.index("kd[g]")] = 1.5  # kd spans [0, 1]: wider than the whole range
    sd[labels.index("f0[r]")] = 0.9  # inside the range: identified, if loosely
    sd[labels.index("alpha")] = 0.02  # a scale fitted in ln alpha: 200% of its value
    sd[labels.index("kd[b]")] = np.nan  # held on a bound: the at-bound flag's business
    assert unidentified(layout, params, sd) == ["kd[g]", "alpha"]
    # the column-scaled rule of covariance() cannot see a tiny column
    jtj = np.diag([1.0, 1e-30])
    assert not covariance(jtj, jtj, 1.0, 100, "classic")[3].any()


# --------------------------------------------------------------------------- losses per sample


def test_losses_per_sample_do_not_depend_on_the_sample_count():
    walter = models.get("walter")
    truth = {"kd": [0.1, 0.2, 0.3], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}
    params = {**walter.defaults(), **{k: jnp.asarray(v) for k, v in truth.items()}}
    data = synthesize(walter, truth, stride=(9, 9, 9), noise_mult=0.05, seed=2)
    twice = Measurements.from_directions(
        *(np.vstack([a] * 2) for a in (data.wi, data.wo, data.values)),
        weights=np.concatenate([data.weights] * 2),
    )  # the same samples twice: a sum doubles, a per-sample value must not move

    def per(d):
        preps = metrics_mod.prepare_all(d, cut_deg=80.0)
        n = next(iter(preps.values())).n
        losses = all_losses(walter, params, preps)
        return {k: (float(v), per_sample(k, float(v), n)) for k, v in losses.items()}

    one, two = per(data), per(twice)
    for name in ("low_e1", "low_e2"):
        assert two[name][0] == pytest.approx(2 * one[name][0], rel=1e-12)
    for name in metrics_mod.METRICS:
        assert two[name][1] == pytest.approx(one[name][1], rel=1e-12), name
    # two sub-grids of one noisy material: sums 27x apart, per sample within 10% (the
    # noise, 5% multiplicative, is what is left at the truth)
    fine = synthesize(walter, truth, stride=(3, 3, 3), noise_mult=0.05, seed=3)
    f = per(fine)
    assert f["low_e2"][0] / one["low_e2"][0] > 20
    assert f["low_e2"][1] == pytest.approx(one["low_e2"][1], rel=0.1)


def test_reports_tables_and_json_give_the_loss_per_sample(oren_nayar_fit):
    r = oren_nayar_fit
    d = json.loads(r.to_json())
    assert d["loss_kind"] == "sum" and d["loss_per_sample"] == pytest.approx(r.loss / r.n_samples)
    assert d["losses_per_sample"]["ngan"] == d["losses"]["ngan"]  # an RMS already
    assert f"sum over {r.n_samples} samples; {r.loss / r.n_samples:.6g} per sample" in r.report()
    table = rank([r]).table("csv").splitlines()
    assert table[0].startswith("rank,model,options,low_e2 (sum),low_e2 per sample,")
    assert float(table[1].split(",")[4]) == pytest.approx(r.loss / r.n_samples, rel=1e-5)


# --------------------------------------------------------------------------- sweep report


def test_an_unconverged_fit_with_the_lowest_loss_is_shown_and_ranked_by_it(tmp_path):
    table = {
        "steel": {"a": (1.0, 0.1, 1.0, True), "b": (0.5, 0.1, 1.0, False)},  # b: MAX_STEPS
        "red-plastic": {"a": (1.0, 0.1, 1.0, True), "b": (2.0, 0.1, 1.0, True)},
    }
    src = make_sweep(tmp_path / "s", table=table)
    mx = matrices(load_sweep(src), "low_e2")
    assert mx.rank[mx.materials.index("steel")].tolist() == [2, 1]
    text = write_report(src).read_text()
    row = next(x for x in text.splitlines() if x.startswith("| steel | metal | b |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[3] == "0.5" and cells[7] == "1" and cells[-1] == "no", row


def test_pareto_medians_are_over_the_materials_every_model_has(tmp_path):
    # c3 is hard and only a has a result there: a median over each model's own
    # materials would charge a for it and b not
    table = {
        "c1": {"a": (2.0, 0.1, 1.0, True), "b": (3.0, 0.2, 2.0, True)},
        "c2": {"a": (4.0, 0.1, 1.0, True), "b": (5.0, 0.2, 2.0, True)},
        "c3": {"a": (1000.0, 0.1, 1.0, True)},
    }
    rows = {
        r.model: r for r in error_vs_time(load_sweep(make_sweep(tmp_path, table=table)), "low_e2")
    }
    assert rows["a"].median_loss == pytest.approx(np.median([2.0, 4.0]))
    assert rows["b"].median_loss == pytest.approx(np.median([3.0, 5.0]))
    assert (rows["a"].n_common, rows["a"].n_materials, rows["b"].n_materials) == (2, 3, 2)
    fig = pareto_figure(tuple(rows.values()))
    assert "the 2 materials every model has" in fig.get_suptitle()


# --------------------------------------------------------------------------- families


@pytest.mark.parametrize(
    ("name", "family"),
    [
        ("acrylic_felt_green_rgb", "fabric"),  # a felt of acrylic fibres, not a plastic
        ("vch_silver_sticker_rgb", "other"),  # a vinyl film, not a metal
        ("ilm_l3_37_metallic_rgb", "other"),  # "metallic" is a look, not a material
        ("satin_gold", "other"),
        ("irid_flake_paint2_rgb", "paint"),
        ("aniso_brushed_aluminium_1", "metal"),
        ("gold-metallic-paint2", "metallic paint"),
        ("tungsten-carbide", "metal"),
    ],
)
def test_family_guess_takes_the_head_noun_and_does_not_guess_from_colours(name, family):
    assert family_of(name) == family


def test_families_file_overrides_the_guess_in_report_and_sweep(tmp_path, capsys, monkeypatch):
    import brdffit.sweep as sweep

    fams = tmp_path / "families.csv"
    fams.write_text("material,family\nsteel,coated metal\n# a comment\n\nred-plastic,plastic\n")
    assert read_families(fams) == {"steel": "coated metal", "red-plastic": "plastic"}
    src = make_sweep(tmp_path / "s")
    code, _, err = _run(capsys, "report", src, "--families", fams)
    assert code == 0, err
    text = (src / "report" / "report.md").read_text()
    assert "| steel | coated metal | a |" in text and "| red-plastic | plastic | b |" in text
    seen = {}

    def fake(out, materials, *args, **kw):
        seen["families"] = {m.name: m.family for m in materials}
        return sweep.SweepSummary(str(out), 0, 0, 0, 0, 0, 0.0)

    monkeypatch.setattr(sweep, "run_sweep", fake)
    guessed = {m.name: m.family for m in sweep.synthetic_materials(2)}
    first = next(iter(guessed))
    fams.write_text(f"{first},my family\n")
    argv = ["sweep", tmp_path / "o", "--synthetic", "2", "--models", "lambert", "--no-progress"]
    code, _, err = _run(capsys, *argv, "--families", fams)
    assert code == 0, err
    assert seen["families"] == {**guessed, first: "my family"}
    bad = tmp_path / "bad.csv"
    bad.write_text("steel,metal,extra\n")
    code, _, err = _run(capsys, *argv, "--families", bad)
    assert code == 2 and "bad.csv: line 1" in err and err.count("\n") == 1
    with pytest.raises(SweepError, match="gives steel the family"):
        bad.write_text("steel,metal\nsteel,paint\n")
        read_families(bad)


# --------------------------------------------------------------------------- figures


def _texts_outside(fig) -> list[str]:
    """Texts (tick labels in view, axis labels, titles, annotations, colour-bar label)
    that leave the canvas, and level tick labels of one axis that overlap each other
    (the boxes of slanted labels overlap whatever their spacing)."""
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    box, bad = fig.bbox, []

    def out(b) -> bool:
        return b.x0 < box.x0 - 1 or b.y0 < box.y0 - 1 or b.x1 > box.x1 + 1 or b.y1 > box.y1 + 1

    for ax in fig.axes:
        texts = [ax.title, ax.xaxis.label, ax.yaxis.label, *ax.texts]
        bad += [t.get_text() for t in texts if t.get_text() and out(t.get_window_extent(r))]
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            ticks = [
                t
                for t in axis.get_major_ticks() + axis.get_minor_ticks()
                if lo <= t.get_loc() <= hi and t.label1.get_visible() and t.label1.get_text()
            ]
            boxes = [t.label1.get_window_extent(r) for t in ticks]
            bad += [t.label1.get_text() for t, b in zip(ticks, boxes, strict=True) if out(b)]
            level = [b for t, b in zip(ticks, boxes, strict=True) if t.label1.get_rotation() == 0]
            bad += [
                f"tick labels overlap: {a.extents} {b.extents}"
                for i, a in enumerate(level)
                for b in level[i + 1 :]
                if a.overlaps(b)
            ]
    return bad


@pytest.fixture
def long_labels(tmp_path):
    """Three materials, six models with long labels, fit times over a decade."""
    models_ = ["lambert", "walter", "disney[subsurface=false,clearcoat=false]"]
    models_ += ["lafortune[n_lobes=2]", "cook_torrance", "ashikhmin_shirley[anisotropic=true]"]
    names = ["acrylic_felt_green_rgb", "cc_nothern_aurora_rgb", "vch_silver_sticker_rgb"]
    table = {
        n: {
            m: (1.0 + i + 0.6 * j, 0.5 + 1.0 * j, 10.0 * (j + 1), True)
            for j, m in enumerate(models_)
        }
        for i, n in enumerate(names)
    }
    return load_sweep(make_sweep(tmp_path, table=table))


def test_rank_matrix_labels_stay_inside_the_canvas(long_labels):
    fig = rank_matrix_figure(matrices(long_labels, "low_e2"))
    assert _texts_outside(fig) == []
    cbar = fig.axes[1]
    label = cbar.yaxis.label.get_window_extent(fig.canvas.get_renderer())
    assert label.height <= cbar.bbox.height  # the colour bar holds its label


def test_pareto_labels_stay_inside_the_canvas_and_apart(long_labels):
    assert _texts_outside(pareto_figure(error_vs_time(long_labels, "low_e2"))) == []


def test_every_scalar_that_moves_along_a_null_direction_is_named():
    # J's columns 0-2 are dependent along v; column 3 is free of it. Scalar 2 moves little
    # along v (8% of the unit vector, under the old rule's 0.3), yet the data fix it no
    # better than the others: all of its variance lies on that direction.
    rng = np.random.default_rng(3)
    v = np.array([1.0, 0.3, 0.08, 0.0])
    v /= np.linalg.norm(v)
    a = rng.normal(size=(60, 4))
    a -= np.outer(a @ v, v)  # J v = 0
    cond, reason, weak = conditioning(a.T @ a)
    assert reason is not None and cond > 1e15
    assert weak.tolist() == [True, True, True, False]
