"""Careless input to the command line ends in one stderr line and exit 2, never a
traceback, and before any work is done: option values, output paths, unreadable tables,
sweep settings. (Unknown models, options and bad MERL files: ``test_cli.py``.)"""

from __future__ import annotations

import pytest

from tests.helpers import fails_cleanly

# --------------------------------------------------------------------------- options


def test_freeze_with_a_value_that_is_not_a_number(capsys, good_csv):
    fails_cleanly(
        capsys, ["fit", good_csv, "--model", "walter", "--freeze", "alpha=abc"], "--freeze", "abc"
    )


@pytest.mark.parametrize(
    ("extra", "needle"),
    [(["--steps", "0"], "--steps"), (["--walkers", "1"], "--walkers")],
)
def test_sample_rejects_steps_and_walkers_it_cannot_run(capsys, good_csv, extra, needle):
    argv = ["sample", good_csv, "--model", "lambert", "--subsample", "100", "--no-progress"]
    fails_cleanly(capsys, [*argv, *extra], needle)


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
    err = fails_cleanly(capsys, argv, option)
    assert ".tmp" not in err
    assert not list(tmp_path.rglob("*.tmp"))


def test_sample_corner_path_is_checked_before_the_fit(capsys, good_csv, tmp_path):
    argv = ["sample", good_csv, "--model", "lambert", "--corner", tmp_path / "x" / "c.png"]
    fails_cleanly(capsys, argv, "--corner")


# --------------------------------------------------------------------------- files


def test_csv_text_in_a_number_column_names_the_line_and_column(capsys, good_csv, tmp_path):
    lines = good_csv.read_text().splitlines()
    lines[4] = "abc" + lines[4][lines[4].index(",") :]  # file line 5, first column
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    fails_cleanly(capsys, ["info", bad], "line 5", "wi_x", "'abc'")


def test_garbage_npz_gets_our_message(capsys, tmp_path):
    bad = tmp_path / "g.npz"
    bad.write_bytes(bytes(range(256)) * 3)
    err = fails_cleanly(capsys, ["info", bad], "g.npz")
    assert "pickle" not in err and "not a .npz archive" in err


# --------------------------------------------------------------------------- sweeps


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
    fails_cleanly(capsys, [*argv, "--no-progress"], needle)
    assert not list(out.glob("*/*.json"))
