"""Sweeps: killed halfway and resumed without losing or redoing work; failures recorded."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from brdffit.cli import main
from brdffit.errors import SweepError
from brdffit.sweep import Material, run_sweep, synthetic_materials

ROOT = Path(__file__).resolve().parents[1]
ARGS = dict(stride=(15, 15, 15), n_restarts=0, eval_n=4096)


def _results(out: Path) -> list[Path]:
    return sorted(p for p in out.glob("*/*.json") if not p.name.endswith(".error.json"))


def test_killed_sweep_resumes_without_redoing_work(tmp_path):
    out = tmp_path / "sweep"
    cmd = [sys.executable, "-m", "brdffit.cli", "sweep", str(out), "--synthetic", "6"]
    cmd += ["--models", "lambert,walter", "--metrics", "low_e2", "--stride", "15", "15", "15"]
    cmd += ["--restarts", "0", "--jobs", "2", "--no-progress"]
    # eval_n is not a CLI option; the in-process resume below must match the default
    proc = subprocess.Popen(cmd, cwd=ROOT, start_new_session=True, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 240
    try:
        while not _results(out) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.01)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    before = _results(out)
    assert 0 < len(before) < 12, "the kill must land between the first and the last result"
    for p in out.rglob("*.json"):
        json.loads(p.read_text())  # nothing partial or corrupt
    stats = {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in before}

    s = run_sweep(
        out,
        synthetic_materials(6),
        ["lambert", "walter"],
        ["low_e2"],
        stride=(15, 15, 15),
        n_restarts=0,
        jobs=1,
        progress=False,
    )
    assert s.n_tasks == 12 and s.n_skipped == len(before) and s.n_errors == 0
    after = _results(out)
    assert len(after) == 12 and not list(out.rglob("*.tmp"))
    assert {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in before} == stats
    d = json.loads(after[0].read_text())
    assert d["eval_ns_per_sample"] > 0 and d["family"] and d["material"] == after[0].parent.name
    assert d["provenance"]["backend"] == "cpu" and d["provenance"]["brdffit"]
    man = json.loads((out / "sweep.json").read_text())
    assert len(man["materials"]) == 6 and list(man["models"]) == ["lambert", "walter"]


def test_failures_are_recorded_and_the_sweep_goes_on(tmp_path):
    bad = Material("missing-file", "other", "merl", str(tmp_path / "nope.binary"))
    good = synthetic_materials(1)
    kw = dict(ARGS, max_steps=1, jobs=1, progress=False)
    s = run_sweep(tmp_path, [bad, *good], ["walter"], ["low_e2"], **kw)
    assert (s.n_done, s.n_errors, s.n_unconverged) == (1, 1, 1)
    err = json.loads((tmp_path / "missing-file" / "walter__low_e2.error.json").read_text())
    assert err["error"] == "MeasurementFileError" and "nope.binary" in err["message"]
    res = tmp_path / good[0].name / "walter__low_e2.json"
    d = json.loads(res.read_text())
    assert d["converged"] is False and d["status"] == "MAX_STEPS"
    stamp = res.stat().st_mtime_ns
    again = run_sweep(tmp_path, [bad, *good], ["walter"], ["low_e2"], **kw)
    assert (again.n_skipped, again.n_errors) == (1, 1)  # the error is tried again
    assert res.stat().st_mtime_ns == stamp


def test_resume_with_other_settings_is_refused(tmp_path):
    mats = synthetic_materials(1)
    (tmp_path / "sweep.json").write_text(
        json.dumps(
            {
                "materials": {},
                "models": {},
                "metrics": [],
                "settings": {"stride": [9, 9, 9], "cut_deg": 80.0, "n_restarts": 0, "seed": 0},
            }
        )
    )
    with pytest.raises(SweepError, match="stride"):
        run_sweep(tmp_path, mats, ["lambert"], ["low_e2"], **ARGS, jobs=1, progress=False)


def test_sweep_cli_bad_input(tmp_path, capsys):
    assert main(["sweep", str(tmp_path), "--synthetic", "2", "--models", "nope"]) == 2
    assert main(["sweep", str(tmp_path), "--merl-dir", str(tmp_path / "x"), "--models", "lambert"])
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and "nope" in err[0] and "not a folder" in err[1]
