"""Issue 29: every careless input ends in one stderr line and exit 2, never a traceback;
the command line says its version, explains every option, and reports progress."""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from brdffit import models, synthesize
from brdffit.cli import build_parser, main
from brdffit.errors import BrdffitError, MissingDependencyError, ParameterError, SweepError

ROOT = Path(__file__).resolve().parents[1]
TRUTH = {"kd": [0.1, 0.2, 0.3], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}
SMALL = ["--stride", "15", "15", "15"]


def _write_csv(path: Path, data) -> Path:
    """The valid samples of ``data`` as a CSV table (wi, wo, rgb)."""
    ok = np.asarray(data.valid)
    ok = ok if ok.ndim == 1 else ok.any(axis=1)
    cols = [np.asarray(data.wi)[ok], np.asarray(data.wo)[ok], np.asarray(data.values)[ok]]
    rows = np.concatenate(cols, axis=1)
    head = "wi_x,wi_y,wi_z,wo_x,wo_y,wo_z,r,g,b"
    np.savetxt(path, rows, delimiter=",", header=head, comments="", fmt="%.9g")
    return path


@pytest.fixture(scope="module")
def good_csv(tmp_path_factory) -> Path:
    """Noise-free walter samples on a coarse MERL sub-grid (a few hundred rows)."""
    data = synthesize(models.get("walter"), TRUTH, stride=(15, 15, 15))
    return _write_csv(tmp_path_factory.mktemp("e29") / "good.csv", data)


@pytest.fixture(scope="module")
def lambert_csv(tmp_path_factory) -> Path:
    """Noise-free Lambert samples: the LM fit is exact, its residuals ~0."""
    data = synthesize(models.get("lambert"), {"kd": [0.1, 0.2, 0.3]}, stride=(15, 15, 15))
    return _write_csv(tmp_path_factory.mktemp("e29") / "lambert.csv", data)


def _fails_cleanly(capsys, argv, *needles) -> str:
    """Run the CLI in-process: exit code 2, one stderr line holding every needle."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:  # argparse's own errors
        code = e.code
    out, err = capsys.readouterr()
    assert code == 2, (code, out, err)
    assert len(err.strip().splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err
    return err


# --------------------------------------------------------------------------- options


def test_freeze_with_a_value_that_is_not_a_number(capsys, good_csv):
    _fails_cleanly(
        capsys, ["fit", good_csv, "--model", "walter", "--freeze", "alpha=abc"], "--freeze", "abc"
    )


@pytest.mark.parametrize(
    ("extra", "needle"),
    [(["--steps", "0"], "--steps"), (["--walkers", "1"], "--walkers")],
)
def test_sample_rejects_steps_and_walkers_it_cannot_run(capsys, good_csv, extra, needle):
    argv = ["sample", good_csv, "--model", "lambert", "--subsample", "100", "--no-progress"]
    _fails_cleanly(capsys, [*argv, *extra], needle)


def test_sample_library_names_the_argument():
    data = synthesize(models.get("lambert"), {"kd": [0.2, 0.2, 0.2]}, stride=(15, 15, 15))
    from brdffit.engine.sample import sample

    with pytest.raises(ParameterError, match="n_steps"):
        sample(models.get("lambert"), data, n_steps=0, progress=False)
    with pytest.raises(ParameterError, match="n_walkers"):
        sample(models.get("lambert"), data, n_walkers=1, progress=False)


def test_sample_on_noise_free_data_starts_from_a_non_degenerate_ball(capsys, lambert_csv):
    # emcee refused the start ball ("large condition number"): every LM error was ~0
    argv = ["sample", lambert_csv, "--model", "lambert", "--steps", "20", "--subsample", "100"]
    code = main([*map(str, argv), "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "[[Posterior]]" in out


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("--json", "{missing}/out.json"),
        ("--export-prefix", "{missing}/p"),
        ("--report", "{missing}/r.html"),
        ("--json", "{folder}"),
    ],
)
def test_fit_output_paths_are_checked_before_the_fit(capsys, good_csv, tmp_path, option, value):
    value = value.format(missing=tmp_path / "no" / "such", folder=tmp_path)
    argv = ["fit", good_csv, "--model", "walter", option, value]
    if option == "--export-prefix":
        argv += ["--export", "gltf"]
    err = _fails_cleanly(capsys, argv, option)
    assert ".tmp" not in err
    assert not list(tmp_path.rglob("*.tmp"))


def test_sample_corner_path_is_checked_before_the_fit(capsys, good_csv, tmp_path):
    argv = ["sample", good_csv, "--model", "lambert", "--corner", tmp_path / "x" / "c.png"]
    _fails_cleanly(capsys, argv, "--corner")


def test_version(capsys):
    from brdffit import __version__

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert __version__ in capsys.readouterr().out


def test_every_option_has_help_text():
    parser = build_parser()
    subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    missing = [
        f"{name} {'/'.join(a.option_strings) or a.dest}"
        for name, sp in subs.choices.items()
        for a in sp._actions
        if not isinstance(a, argparse._HelpAction) and not a.help
    ]
    assert not missing, missing


def test_fit_header_names_the_stride(capsys, tmp_path):
    from brdffit import write_merl

    path = tmp_path / "g.binary"
    write_merl(path, synthesize(models.get("lambert"), {"kd": [0.2, 0.2, 0.2]}))
    assert main(["fit", str(path), "--model", "lambert", *SMALL]) == 0
    header = capsys.readouterr().out.splitlines()[0]
    assert "stride (15, 15, 15)" in header, header


# --------------------------------------------------------------------------- files


def test_csv_text_in_a_number_column_names_the_line_and_column(capsys, good_csv, tmp_path):
    lines = good_csv.read_text().splitlines()
    lines[4] = "abc" + lines[4][lines[4].index(",") :]  # file line 5, first column
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    _fails_cleanly(capsys, ["info", bad], "line 5", "wi_x", "'abc'")


def test_garbage_npz_gets_our_message(capsys, tmp_path):
    bad = tmp_path / "g.npz"
    bad.write_bytes(bytes(range(256)) * 3)
    err = _fails_cleanly(capsys, ["info", bad], "g.npz")
    assert "pickle" not in err and "not a .npz archive" in err


def test_nbrdf_without_h5py_raises_missing_dependency(tmp_path, monkeypatch, capsys):
    pytest.importorskip("h5py")
    from brdffit.io.nbrdf import read_nbrdf
    from tests.io.test_nbrdf import _architecture, _random_weights, _write_keras

    stem = _write_keras(tmp_path / "toy", _random_weights(), _architecture())
    monkeypatch.setitem(sys.modules, "h5py", None)
    with pytest.raises(MissingDependencyError, match=r"brdffit\[nbrdf\]"):
        read_nbrdf(stem)
    _fails_cleanly(capsys, ["info", stem.with_suffix(".json")], "h5py")


def test_readme_names_readers_that_return_measurements():
    """Each row of the README's Input-files table names readers returning Measurements."""
    import importlib
    import inspect

    import brdffit

    text = (ROOT / "README.md").read_text()
    table = text.split("## Input files", 1)[1].split("\n\n", 2)[1]
    rows = [r for r in table.splitlines() if r.startswith("|") and "---" not in r][1:]
    assert rows
    for row in rows:
        names = re.findall(r"`([\w.]+)`", row.split("|")[2])
        assert names, row
        for name in names:
            mod, _, attr = name.rpartition(".")
            f = getattr(importlib.import_module(mod) if mod else brdffit, attr)
            ret = inspect.signature(f).return_annotation
            assert ret in ("Measurements", brdffit.Measurements), (name, ret)


# --------------------------------------------------------------------------- sweeps


def test_report_skips_unreadable_result_files_and_lists_them(capsys, tmp_path):
    from tests.sweep_fixtures import make_sweep

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


def test_sweep_folder_lock(tmp_path):
    from brdffit.sweep import sweep_lock

    with sweep_lock(tmp_path):
        with pytest.raises(SweepError, match="another sweep"):
            with sweep_lock(tmp_path):
                pass
    # a stale lock left by a dead process is taken over
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / ".sweep.lock").write_text(f"{dead.pid}\n")
    with sweep_lock(tmp_path):
        assert (tmp_path / ".sweep.lock").read_text().split()[0] == str(os.getpid())
    assert not (tmp_path / ".sweep.lock").exists()


def test_second_sweep_into_a_running_folder_exits_2(capsys, tmp_path):
    out = tmp_path / "sw"
    out.mkdir()
    (out / ".sweep.lock").write_text(f"{os.getppid()}\n")  # a live process holds it
    argv = ["sweep", out, "--synthetic", "1", "--models", "lambert", "--jobs", "1", *SMALL]
    _fails_cleanly(capsys, [*argv, "--no-progress"], "another sweep", str(os.getppid()))


# --------------------------------------------------------------------------- progress


def test_rank_prints_progress_per_model(capsys, good_csv):
    # two cheap models (a walter fit here cost 13 s of compilation and showed nothing more)
    argv = ["rank", good_csv, "--models", "lambert,lambert[grey=kd]"]
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    # a finished fit's line (the bar is redrawn around it with carriage returns)
    done = re.findall(r"rank: (\S+)  \d+\.\d s  low_e2 [\d.e+-]+ \((\w+)\)", err)
    assert [name for name, _ in done] == ["lambert", "lambert[grey=kd]"], err


def test_simplify_prints_progress_per_move(capsys, good_csv, tmp_path):
    argv = ["simplify", good_csv, "--model", "lambert", "--criterion", "bic"]  # few variants: fast
    code = main([str(a) for a in [*argv, "--json", tmp_path / "s.json"]])
    out, err = capsys.readouterr()
    assert code == 0, err
    lines = re.findall(r"simplify: step (\d+)  ([^\n]+?)  k=\d+  low_e2 ", err)
    assert lines[0] == ("0", "start"), err
    assert ("1", "grey kd") in lines, err  # every move of a step gets its line
    path = json.loads((tmp_path / "s.json").read_text())["path"]
    taken = {r["change"] for r in path if r["decision"] in ("removed", "chosen")}
    assert not [r for r in path if r["decision"] == "kept" and r["change"] in taken]


def test_simplify_table_defers_a_change_taken_later():
    """A move refused at step 1 and taken at step 2 reads 'deferred', not 'kept'."""
    from brdffit.selection.reduction import DECISIONS, PathRow
    from brdffit.selection.simplify import _mark_deferred

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


def test_errors_are_brdffit_errors():
    assert issubclass(MissingDependencyError, BrdffitError)


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--stride", "2", "2", "2"], "stride for theta_h is 2"),
        (["--restarts", "-1"], "--restarts"),
        (["--screen", "-5"], "--screen"),
        (["--seed", "-1"], "--seed"),
        (["--cut", "inf"], "--cut"),
    ],
)
def test_sweep_settings_fail_before_any_fit(capsys, tmp_path, extra, needle):
    # these were recorded as an error per task, exit 0
    out = tmp_path / "sw"
    argv = ["sweep", out, "--synthetic", "1", "--models", "lambert", "--jobs", "1", *extra]
    _fails_cleanly(capsys, [*argv, "--no-progress"], needle)
    assert not list(out.glob("*/*.json"))
