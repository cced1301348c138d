"""Random strings to the command line's options, run in-process: exit code 0 or 2 with
one stderr line, never an uncaught exception (issue 29). Tiny data, few examples."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from brdffit import models, synthesize
from brdffit.cli import main

FUZZ = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,  # the same strings every run: a failure is reproducible
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

# values a careless user types: numbers out of range, non-numbers, empty, separators
TRICKY = ["0", "-1", "1", "2", "nan", "inf", "-inf", "1e308", "1e-308", "abc", "", "1,2", "=",
          "alpha=", "alpha=1,2", "kd=nan", "kd=-1", "walter[", "lambert]", "[]", ","]  # fmt: skip
VALUES = st.sampled_from(TRICKY) | st.text(max_size=10)

# (subcommand with its fixed arguments, the option under test); {csv} is the data file
BASE = {
    "fit": ["fit", "{csv}", "--model", "lambert", "--screen", "0"],
    "sample": [
        "sample",
        "{csv}",
        "--model",
        "lambert",
        "--steps",
        "8",
        "--subsample",
        "50",
        "--no-progress",
    ],  # fmt: skip
    "rank": ["rank", "{csv}", "--no-progress"],
    "simplify": ["simplify", "{csv}", "--model", "lambert", "--criterion", "bic", "--no-progress"],
    "info": ["info"],
    "report": ["report"],
    "sweep": [
        "sweep",
        "sw",
        "--models",
        "lambert",
        "--stride",
        "15",
        "15",
        "15",
        "--jobs",
        "1",
        "--no-progress",
    ],  # fmt: skip
}
OPTIONS = [
    ("fit", "--cut"), ("fit", "--freeze"), ("fit", "--seed"), ("fit", "--restarts"),
    ("fit", "--screen"), ("fit", "--robust-scale"), ("fit", "--model"), ("fit", "--option"),
    ("fit", "--metric"), ("fit", "--errors"), ("fit", "--stride"), ("fit", "--export"),
    ("sample", "--steps"), ("sample", "--walkers"), ("sample", "--subsample"),
    ("sample", "--noise"), ("sample", "--freeze"), ("rank", "--models"), ("rank", "--by"),
    ("simplify", "--folds"), ("simplify", "--n-se"), ("simplify", "--min-gain"),
    ("info", None), ("report", None), ("sweep", "--synthetic"), ("sweep", "--metrics"),
    ("sweep", "--materials"), ("sweep", "--batch"), ("sweep", "--cut"),
]  # fmt: skip


@pytest.fixture(scope="module")
def csv(tmp_path_factory) -> Path:
    data = synthesize(models.get("lambert"), {"kd": [0.2, 0.3, 0.4]}, grid="random", n=60, seed=1)
    rows = np.concatenate([data.wi, data.wo, data.values], axis=1)
    path = tmp_path_factory.mktemp("fuzzcli") / "d.csv"
    np.savetxt(path, rows, delimiter=",", fmt="%.9g", comments="",
               header="wi_x,wi_y,wi_z,wo_x,wo_y,wo_z,r,g,b")  # fmt: skip
    return path


def _argv(csv: Path, command: str, option: str | None, value: str) -> list[str]:
    argv = [a.replace("{csv}", str(csv)) for a in BASE[command]]
    if option is None:  # a positional: the data file's name itself
        return [*argv, value or "x"]
    if option == "--stride":
        return [*argv, option, value, value, value]
    if option == "--robust-scale":
        return [*argv, "--robust", "huber", option, value]
    if command == "sweep" and option != "--synthetic":
        argv += ["--synthetic", "1"]
    if option == "--models" or command == "rank":
        return [*argv, option, value] + ([] if option == "--models" else ["--models", "lambert"])
    return [*argv, f"{option}={value}"]  # = keeps a value that starts with '-' a value


@FUZZ
@given(case=st.sampled_from(OPTIONS), value=VALUES)
@example(case=("fit", "--seed"), value="-1")  # numpy's ValueError escaped (found by a probe)
@example(case=("fit", "--cut"), value="inf")  # a RuntimeWarning line beside the error
@example(case=("sample", "--steps"), value="0")
@example(case=("fit", "--freeze"), value="kd=abc")
@example(case=("report", None), value="sw")  # a folder that is not a sweep's
@example(case=("sweep", "--synthetic"), value="2")
def test_random_option_values_end_in_0_or_2(capsys, csv, tmp_path, monkeypatch, case, value):
    monkeypatch.chdir(tmp_path)  # exports and other default outputs land here
    command, option = case
    argv = _argv(csv, command, option, value)
    try:
        code = main(argv)
    except SystemExit as e:  # argparse: --help, bad choices, missing values
        code = e.code
    out, err = capsys.readouterr()
    assert code in (0, 2), (argv, code, err)
    if code == 2:
        assert len(err.strip().splitlines()) == 1, (argv, err)
