"""Ranking across materials and the error-against-time study (Pareto medians over the
materials every model has), on a hand-made sweep folder. Their figures:
``tests/report/test_selection_figures.py``."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.errors import SweepError
from brdffit.selection.crossrank import (
    aggregate,
    aggregate_table,
    family_table,
    material_order,
    matrices,
    per_material_table,
)
from brdffit.selection.pareto import error_vs_time, pareto_front, pareto_table
from brdffit.selection.sweep_results import load_sweep
from tests.sweep_fixtures import TABLE, make_sweep


def test_per_material_ranks_and_relative_error(tmp_path):
    mx = matrices(load_sweep(make_sweep(tmp_path)), "low_e2")
    assert mx.models == ("a", "b")
    by = dict(zip(mx.materials, mx.rank.tolist(), strict=True))
    assert by["gold-metallic-paint"] == [1, 2]
    assert by["red-plastic"] == [2, 1]
    assert by["blue-fabric"] == [1, 2]  # b did not converge: ranked by its loss 9 > 2
    i = mx.materials.index("red-plastic")
    assert mx.rel[i, 0] == pytest.approx(3.0 / 1.5 - 1)
    assert mx.rel[i, 1] == 0
    i = mx.materials.index("blue-fabric")
    assert mx.loss[i, 1] == 9.0 and not mx.converged[i, 1] and mx.converged[i, 0]


def test_aggregate_with_bootstrap(tmp_path):
    mx = matrices(load_sweep(make_sweep(tmp_path)), "low_e2")
    rows = aggregate(mx, n_boot=500, seed=1)
    a = next(r for r in rows if r.model == "a")
    assert rows[0].model == "a"
    assert a.mean_rank == pytest.approx(1.25) and a.wins == 3
    assert a.median_rel_err == pytest.approx(0.0)  # rel errors 0, 1, 0, 0
    for r in rows:
        assert r.mean_rank_ci[0] <= r.mean_rank <= r.mean_rank_ci[1]
        assert r.wins_ci[0] <= r.wins <= r.wins_ci[1]
    assert aggregate(mx, n_boot=500, seed=1) == rows  # seeded
    md, csv = aggregate_table(rows), aggregate_table(rows, "csv")
    assert md.count("\n") == 2 + len(rows) and "mean rank" in md
    assert csv.splitlines()[0].startswith("model,mean_rank,")


def test_tables_and_material_order(tmp_path):
    mx = matrices(load_sweep(make_sweep(tmp_path)), "low_e2")
    n = len(TABLE) * 2
    assert len(per_material_table(mx, "csv").splitlines()) == 1 + n
    assert per_material_table(mx).count("| steel | metal |") == 2
    fam = [mx.families[i] for i in material_order(mx)]
    assert fam == ["metallic paint", "plastic/phenolic", "fabric", "metal"]
    with pytest.raises(SweepError, match="ngan"):
        matrices(load_sweep(tmp_path), "ngan")


def test_pareto_front_function():
    x = np.array([1.0, 2.0, 3.0, 2.0, np.nan, 1.0])
    y = np.array([5.0, 2.0, 1.0, 3.0, 0.1, 5.0])
    assert pareto_front(x, y).tolist() == [True, True, True, False, False, True]


def test_error_vs_time(tmp_path):
    # b stopped unconverged on blue-fabric at loss 1.0: counted with it, as in the ranking
    table = {**TABLE, "blue-fabric": {"a": (2.0, 0.5, 10.0, True), "b": (1.0, 0.2, 5.0, False)}}
    rows = error_vs_time(load_sweep(make_sweep(tmp_path, table=table)), "low_e2")
    by = {r.model: r for r in rows}
    assert by["a"].median_loss == pytest.approx(np.median([1.0, 3.0, 0.5, 2.0]))
    assert by["b"].median_loss == pytest.approx(np.median([2.0, 1.5, 0.6, 1.0]))
    assert by["b"].n_materials == 4 and by["b"].n_common == 4
    assert by["b"].median_wall_time == pytest.approx(0.2)
    assert by["a"].median_eval_ns == 10.0
    # b: lower median error (1.25 < 1.5), faster and cheaper: a is dominated on both fronts
    assert by["b"].front_time and by["b"].front_eval
    assert not by["a"].front_time and not by["a"].front_eval
    assert pareto_table(rows).count("*") == 2
    assert len(pareto_table(rows, "csv").splitlines()) == 3


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


def test_not_a_sweep_folder(tmp_path):
    with pytest.raises(SweepError, match="sweep.json"):
        load_sweep(tmp_path)


def test_near_equal_losses_tie_and_a_shared_first_is_a_win_for_each(tmp_path):
    # steel: b is a nested model stopped 3e-6 relative above a (inside LOSS_RTOL = 1e-5);
    # gray-rubber: neither converged; both ranked by the equal losses they reached, a
    # shared first place and a win for each.
    table = dict(TABLE)
    table["steel"] = {"a": (0.5, 0.4, 10.0, True), "b": (0.5 * (1 + 3e-6), 0.3, 5.0, True)}
    table["gray-rubber"] = {"a": (1.0, 0.4, 10.0, False), "b": (1.0, 0.3, 5.0, False)}
    mx = matrices(load_sweep(make_sweep(tmp_path, table=table)), "low_e2")
    by = dict(zip(mx.materials, mx.rank.tolist(), strict=True))
    assert by["steel"] == [1.5, 1.5] and by["gray-rubber"] == [1.5, 1.5]
    assert by["gold-metallic-paint"] == [1, 2] and by["red-plastic"] == [2, 1]
    i = mx.materials.index("steel")
    assert mx.rank_aic[i].tolist() == [1, 2]  # AIC ties only when equal; b has 4 more params
    rows = {r.model: r for r in aggregate(mx, n_boot=200)}
    assert (rows["a"].wins, rows["b"].wins) == (4, 3)  # steel and gray-rubber count for both
    assert (rows["a"].n_unconverged, rows["b"].n_unconverged) == (1, 2)
    assert rows["a"].mean_rank == pytest.approx((1 + 2 + 1.5 + 1 + 1.5) / 5)
    assert rows["b"].mean_rank == pytest.approx((2 + 1 + 1.5 + 2 + 1.5) / 5)
    csv = [line.split(",") for line in per_material_table(mx, "csv").splitlines()]
    assert [row[7] for row in csv if row[0] == "steel"] == ["1.5", "1.5"]  # rank column


# material -> losses of models a, b, c, d (the losses are also the ranks)
CLUSTER_TABLE = {
    "red-plastic": (4, 3, 2, 1),
    "steel-1": (1, 2, 3, 4),
    "steel-2": (4, 3, 2, 1),
    "steel-3": (1, 2, 3, 4),  # ranks the models like steel-1
    "steel-4": (4, 3, 1, 2),  # close to steel-2
    "steel-5": (2, 1, 4, 3),  # close to steel-1 and -3
    "blue-plastic": (1, 2, 3, 4),
}


def test_materials_are_clustered_by_rank_vector_within_a_family(tmp_path):
    table = {
        m: {k: (float(x), 0.1, 1.0, True) for k, x in zip("abcd", v, strict=True)}
        for m, v in CLUSTER_TABLE.items()
    }
    mx = matrices(load_sweep(make_sweep(tmp_path / "s", table=table)), "low_e2")
    order = [mx.materials[i] for i in material_order(mx)]
    # plastics first (family order) and, only two of them, in manifest order; the steels
    # in two clusters {1, 3, 5} and {2, 4} whose nearest members (5 and 2) meet, starting
    # at the end that holds the first steel of the manifest
    assert order == ["red-plastic", "blue-plastic"] + [f"steel-{k}" for k in (1, 3, 5, 2, 4)]
    copy = make_sweep(tmp_path / "copy", table=table)
    assert material_order(matrices(load_sweep(copy), "low_e2")).tolist() == (
        material_order(mx).tolist()
    )


def test_family_table_lists_each_familys_best_models_by_mean_rank(tmp_path):
    mx = matrices(load_sweep(make_sweep(tmp_path / "s")), "low_e2")
    text = family_table(mx, top=2)
    # one material per family in the fixture: its ranks are the family's mean ranks
    assert "| metallic paint | 1 | a (1.00) | b (2.00) |" in text
    assert "| plastic/phenolic | 1 | b (1.00) | a (2.00) |" in text
    assert "| fabric | 1 | a (1.00) | b (2.00) |" in text  # b did not converge: last
    assert (
        family_table(mx, "csv", top=2).splitlines()[0] == "family,n,#1 (mean rank),#2 (mean rank)"
    )
