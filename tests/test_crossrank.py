"""Ranking across materials and the error-against-time study, on a hand-made sweep folder."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.crossrank import (
    aggregate,
    aggregate_table,
    load_sweep,
    material_order,
    matrices,
    per_material_table,
    rank_matrix_figure,
)
from brdffit.errors import SweepError
from brdffit.families import family_of
from brdffit.pareto import error_vs_time, pareto_figure, pareto_front, pareto_table
from tests.sweep_fixtures import TABLE, make_sweep


@pytest.mark.parametrize(
    "name, family",
    [
        ("gold-metallic-paint", "metallic paint"),
        ("gold-paint", "paint"),
        ("black-oxidized-steel", "metal"),
        ("alum-bronze", "metal"),
        ("specular-black-phenolic", "plastic/phenolic"),
        ("pink-felt", "fabric"),
        ("fruitwood-241", "wood"),
        ("alumina-oxide", "stone"),
        ("violet-rubber", "rubber"),
        ("white-diffuse-bball", "other"),
    ],
)
def test_family_keywords(name, family):
    assert family_of(name) == family


def test_per_material_ranks_and_relative_error(tmp_path):
    mx = matrices(load_sweep(make_sweep(tmp_path)), "low_e2")
    assert mx.models == ("a", "b")
    by = dict(zip(mx.materials, mx.rank.tolist(), strict=True))
    assert by["gold-metallic-paint"] == [1, 2]
    assert by["red-plastic"] == [2, 1]
    assert by["blue-fabric"] == [1, 2]  # b did not converge: ranked last, no loss
    i = mx.materials.index("red-plastic")
    assert mx.rel[i, 0] == pytest.approx(3.0 / 1.5 - 1)
    assert mx.rel[i, 1] == 0
    assert np.isnan(mx.loss[mx.materials.index("blue-fabric"), 1])


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


def test_tables_and_figure(tmp_path):
    mx = matrices(load_sweep(make_sweep(tmp_path)), "low_e2")
    n = len(TABLE) * 2
    assert len(per_material_table(mx, "csv").splitlines()) == 1 + n
    assert per_material_table(mx).count("| steel | metal |") == 2
    fam = [mx.families[i] for i in material_order(mx)]
    assert fam == ["metallic paint", "plastic/phenolic", "fabric", "metal"]
    fig = rank_matrix_figure(mx)
    assert len(fig.axes) == 2  # image and colour bar
    with pytest.raises(SweepError, match="ngan"):
        matrices(load_sweep(tmp_path), "ngan")


def test_pareto_front_function():
    x = np.array([1.0, 2.0, 3.0, 2.0, np.nan, 1.0])
    y = np.array([5.0, 2.0, 1.0, 3.0, 0.1, 5.0])
    assert pareto_front(x, y).tolist() == [True, True, True, False, False, True]


def test_error_vs_time(tmp_path):
    rows = error_vs_time(load_sweep(make_sweep(tmp_path)), "low_e2")
    by = {r.model: r for r in rows}
    assert by["a"].median_loss == pytest.approx(np.median([1.0, 3.0, 0.5, 2.0]))
    assert by["b"].n_materials == 3  # one unconverged fit left out
    assert by["b"].median_wall_time == pytest.approx(0.2)
    assert by["a"].median_eval_ns == 10.0
    # equal median error (1.5), b faster and cheaper: a is dominated on both fronts
    assert by["b"].median_loss == pytest.approx(by["a"].median_loss)
    assert by["b"].front_time and by["b"].front_eval
    assert not by["a"].front_time and not by["a"].front_eval
    assert pareto_table(rows).count("*") == 2
    assert len(pareto_table(rows, "csv").splitlines()) == 3
    assert len(pareto_figure(rows).axes) == 2


def test_not_a_sweep_folder(tmp_path):
    with pytest.raises(SweepError, match="sweep.json"):
        load_sweep(tmp_path)
