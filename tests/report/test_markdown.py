"""The sweep report: written from the JSON files alone, reproducible, unconverged fits shown
and ranked by their loss, unreadable result files skipped and listed, and the CLI around it."""

from __future__ import annotations

import json
import re
import shutil

import matplotlib
import pytest

from brdffit.cli import main
from brdffit.report import write_report
from brdffit.selection.crossrank import matrices
from brdffit.selection.sweep_results import load_sweep
from tests.sweep_fixtures import TABLE, make_sweep

# four steels (one family, so clustered) with a tie for first on steel-2 and steel-4
STEELS = {
    f"steel-{i}": {"a": (a, 0.1, 1.0, True), "b": (b, 0.2, 2.0, True), "c": (3.0, 0.3, 3.0, True)}
    for i, (a, b) in enumerate([(1.0, 2.0), (1.0, 1.0 + 1e-6), (2.0, 1.0), (1.0, 1.0 + 1e-6)], 1)
}


def _outputs(path):
    return {p.name: p.read_bytes() for p in sorted(path.parent.iterdir()) if p.suffix != ".png"}


def test_report_files_and_content(tmp_path):
    path = write_report(make_sweep(tmp_path / "sweep"))
    assert path == tmp_path / "sweep" / "report" / "report.md"
    text = path.read_text()
    for part in ("# Sweep report", "## Metric `low_e2`", "mean rank [95% CI]", "Pareto"):
        assert part in text
    for image in re.findall(r"!\[[^]]*\]\(([^)]+)\)", text):
        assert (path.parent / image).stat().st_size > 1000
    for name in ("aggregate", "per_material", "pareto"):
        assert (path.parent / f"{name}_low_e2.csv").exists()
    assert "1 not converged" in text
    assert str(tmp_path) not in text
    assert "Losses within a relative 1e-05 of each other tie and share their average rank" in text
    assert "a tie for first counts as a win for each tied model" in text


@pytest.mark.parametrize("table", [TABLE, STEELS], ids=["families", "ties-and-clusters"])
def test_report_reproducible_from_json_alone(tmp_path, table):
    src = make_sweep(tmp_path / "a", table=table)
    first = _outputs(write_report(src))
    assert _outputs(write_report(src)) == first  # same files, same report
    copy = tmp_path / "b"
    for p in src.rglob("*.json"):
        if "report" not in p.parts:
            (copy / p.relative_to(src)).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(p, copy / p.relative_to(src))
    assert _outputs(write_report(copy)) == first


def test_report_cli(tmp_path, capsys):
    src = make_sweep(tmp_path / "s")
    assert main(["report", str(src)]) == 0
    assert capsys.readouterr().out.strip().endswith("report.md")
    assert main(["report", str(tmp_path / "missing")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "sweep.json" in err


def test_report_names_mixed_code_versions_and_devices(tmp_path):
    src = make_sweep(tmp_path / "s")
    text = write_report(src).read_text()
    assert "computed by: unrecorded" in text and "warning" not in text
    one = next(src.glob("steel/a__*.json"))
    d = json.loads(one.read_text())
    d["provenance"] = {"brdffit": "0.1.0", "git": "abc1234", "jax": "0.11.2",
                       "backend": "gpu", "device": "NVIDIA H100 80GB HBM3"}  # fmt: skip
    one.write_text(json.dumps(d))
    text = write_report(src).read_text()
    assert "on gpu (NVIDIA H100 80GB HBM3) (1 results)" in text
    assert "more than one code version or device" in text


def test_report_counts_a_shared_first_place_for_each_model(tmp_path):
    text = write_report(make_sweep(tmp_path / "s", table=STEELS)).read_text()
    # a: ranks 1, 1.5, 2, 1.5, wins on steel-1, -2, -4; b: 2, 1.5, 1, 1.5, wins on -2, -3, -4:
    # 6 wins on 4 materials, as each shared first place is a win for both
    assert re.search(r"\| a \| 1\.50 \[[^|]*\| 3 \[", text), text
    assert re.search(r"\| b \| 1\.50 \[[^|]*\| 3 \[", text), text
    assert re.search(r"\| c \| 3\.00 \[[^|]*\| 0 \[", text), text


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


def test_report_skips_unreadable_result_files_and_lists_them(capsys, tmp_path):
    root = make_sweep(tmp_path / "sw")
    first = sorted(root.glob("*/*.json"))[0]
    first.write_text(first.read_text()[:40])  # truncated
    (root / "steel" / "x__low_e2.json").write_text(json.dumps({"hello": 1}))  # foreign
    (root / "steel" / "y__low_e2.json").write_text("[1, 2]")  # not an object
    code = main(["report", str(root)])
    out, err = capsys.readouterr()
    assert code == 0, err
    for name in (first.name, "x__low_e2.json", "y__low_e2.json"):
        assert name in err and name in (root / "report" / "report.md").read_text()


def _only_result_unreadable(root):
    """A sweep folder of one task whose result file is truncated (issue 39, item 6)."""
    root = make_sweep(root, table={"steel": {"a": (0.5, 0.4, 10.0, True)}})
    (path,) = root.glob("*/*.json")
    path.write_text(path.read_text()[:40])
    return root, path


def test_report_on_a_folder_with_nothing_readable_exits_2_in_one_line(tmp_path, capsys):
    root, path = _only_result_unreadable(tmp_path / "sw")
    assert main(["report", str(root)]) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and out == ""
    assert str(root) in lines[0] and "no result file could be read" in lines[0]
    assert path.name in lines[0]


def test_report_with_too_few_results_for_a_figure_says_so(tmp_path, capsys):
    root, path = _only_result_unreadable(tmp_path / "sw")
    error = {"material": "steel", "model": "a", "metric": "low_e2", "error": "FitError"}
    (root / "steel" / "a__low_e2.error.json").write_text(json.dumps(error))
    assert main(["report", str(root)]) == 0
    assert path.name in capsys.readouterr().err  # listed as left out
    text = (root / "report" / "report.md").read_text()
    assert "No rank matrix: no model has a finite low_e2." in text
    assert "No Pareto plot: no model has a finite median error" in text
    assert "| steel | a | low_e2 | FitError:  |" in text
    assert not list((root / "report").glob("*.png"))
    page = (root / "report.html").read_text()
    assert "No rank matrix" in page and "No Pareto plot" in page


def test_writing_a_report_leaves_matplotlibs_backend_alone(tmp_path):
    """In Jupyter the backend is the kernel's inline one; a report written there must not
    switch it (it once forced Agg, and no later figure showed)."""
    before = matplotlib.get_backend()
    matplotlib.use("pdf")  # stands for the kernel's backend
    try:
        write_report(make_sweep(tmp_path / "s"), n_boot=20)
        assert matplotlib.get_backend() == "pdf"
    finally:
        matplotlib.use(before)
