"""Sweeps: killed halfway and resumed without losing or redoing work; failures recorded;
model variants given as specs (``lafortune[n_lobes=2]``) fitted and ranked on their own."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import signal
import subprocess
import sys
import time
import typing
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from brdffit import ParameterError, models
from brdffit.cli import main
from brdffit.errors import SweepError
from brdffit.selection.crossrank import matrices
from brdffit.selection.sweep_results import load_sweep
from brdffit.sweep import Material, run_sweep, synthetic_materials
from brdffit.sweep.tasks import checkout_commit, file_stem

ROOT = Path(__file__).resolve().parents[2]
ARGS = dict(stride=(15, 15, 15), n_restarts=0, eval_n=4096)


def _results(out: Path) -> list[Path]:
    return sorted(p for p in out.glob("*/*.json") if not p.name.endswith(".error.json"))


def test_killed_sweep_resumes_without_redoing_work(tmp_path):
    out = tmp_path / "sweep"
    # one model on six materials, in the command's own process (--jobs 1): run_sweep's
    # `record` writes every result with or without Dask, and a lost Dask worker is
    # test_cluster's; a LocalCluster here only added two workers' start and compilation.
    # Lambert: the cheapest model to compile (walter took 49 s here, nearly all of it
    # compiling twice); each fit still writes its JSON and times its evaluation
    cmd = [sys.executable, "-m", "brdffit.cli", "sweep", str(out), "--synthetic", "6"]
    cmd += ["--models", "lambert", "--metrics", "low_e2", "--stride", "15", "15", "15"]
    cmd += ["--restarts", "0", "--jobs", "1", "--no-progress"]
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
    assert 0 < len(before) < 6, "the kill must land between the first and the last result"
    for p in out.rglob("*.json"):
        json.loads(p.read_text())  # nothing partial or corrupt
    stats = {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in before}

    s = run_sweep(
        out,
        synthetic_materials(6),
        ["lambert"],
        ["low_e2"],
        stride=(15, 15, 15),
        n_restarts=0,
        jobs=1,
        progress=False,
    )
    assert s.n_tasks == 6 and s.n_skipped == len(before) and s.n_errors == 0
    after = _results(out)
    assert len(after) == 6 and not list(out.rglob("*.tmp"))
    assert {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in before} == stats
    d = json.loads(after[0].read_text())
    assert d["eval_ns_per_sample"] > 0 and d["family"] and d["material"] == after[0].parent.name
    assert d["provenance"]["backend"] == "cpu" and d["provenance"]["brdffit"]
    man = json.loads((out / "sweep.json").read_text())
    assert len(man["materials"]) == 6 and list(man["models"]) == ["lambert"]


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
    bad = "walter,lafortune[n_lobes=2,anisotropic=maybe]"
    assert main(["sweep", str(tmp_path), "--synthetic", "2", "--models", bad]) == 2
    assert (
        main(["sweep", str(tmp_path), "--synthetic", "2", "--models", "lafortune[n_lobes=2"]) == 2
    )
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 4 and "nope" in err[0] and "not a folder" in err[1]
    assert "'lafortune[n_lobes=2,anisotropic=maybe]'" in err[2] and "anisotropic='maybe'" in err[2]
    assert "unbalanced brackets" in err[3]
    assert not list(tmp_path.glob("*/*.json"))  # refused before any fit


def _option_strategies(name: str) -> dict[str, st.SearchStrategy]:
    """Every static option of a registered model, values drawn from its annotation."""
    cls = type(models.get(name))
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if typing.get_origin(hint) is typing.Literal:
            out[f.name] = st.sampled_from(typing.get_args(hint))
        elif hint is bool:
            out[f.name] = st.booleans()
        elif hint is int:
            out[f.name] = st.integers(1, 5)
        else:
            raise AssertionError(f"{name}.{f.name}: no strategy for {hint}")
    return out


def _variant(name: str) -> st.SearchStrategy:
    """(name, some of its options) with drawn values."""
    return st.tuples(st.just(name), st.fixed_dictionaries({}, optional=_option_strategies(name)))


VARIANTS = st.sampled_from(models.available()).flatmap(_variant)


@given(VARIANTS)
@settings(max_examples=300, deadline=None)
def test_label_round_trips_through_parse_spec(variant):
    name, opts = variant
    try:
        model = models.get(name, **opts)
    except ParameterError:
        assume(False)  # a combination the model refuses (filament cloth + clearcoat)
    defaults = models.get(name).options()
    changed = {k: v for k, v in opts.items() if v != defaults[k]}
    text = models.label(model)
    assert models.parse_spec(text) == (name, changed)
    assert models.from_spec(text) == model
    assert models.label(name, model.options()) == text  # from a FitResult's name and options
    stem = file_stem(text)
    assert re.fullmatch(r"[a-z0-9_.+=@-]+", stem) and (stem == name) == (not changed)


def test_spec_examples():
    assert models.parse_spec("lafortune[n_lobes=2]") == ("lafortune", {"n_lobes": 2})
    spec = " walter[ anisotropic = TRUE , distribution=beckmann ] "
    model = models.from_spec(spec)
    assert models.label(model) == "walter[distribution=beckmann,anisotropic=true]"  # field order
    assert file_stem(models.label(model)) == "walter@distribution=beckmann@anisotropic=true"
    assert models.label(models.get("walter", anisotropic=False)) == "walter"  # a default
    assert models.split_specs("walter, lafortune[n_lobes=2,anisotropic=true],,lambert") == [
        "walter",
        "lafortune[n_lobes=2,anisotropic=true]",
        "lambert",
    ]


@pytest.mark.parametrize(
    ("spec", "needle"),
    [
        ("nope", "unknown model 'nope'"),
        ("nope[n_lobes=2]", "unknown model 'nope'"),
        ("walter[colour=red]", "no option(s) ['colour']"),
        ("lafortune[n_lobes=two]", "n_lobes='two' is not of type int"),
        ("lafortune[n_lobes=2.5]", "n_lobes=2.5 is not of type int"),
        ("lafortune[n_lobes=0]", "not an integer >= 1"),
        ("walter[anisotropic=yes]", "anisotropic='yes' is not of type bool"),
        ("walter[distribution=a/b]", "value 'a/b'"),
        ("walter[smith=rational]", "for distribution='beckmann' only"),
        ("lafortune[n_lobes=2", "unbalanced brackets"),
        ("lafortune]n_lobes=2[", "unbalanced brackets"),
        ("lafortune[n_lobes=2]x", "text after ']'"),
        ("walter[anisotropic]", "'anisotropic' is not k=v"),
        ("walter[]", "'' is not k=v"),
        ("walter[diffuse=true,diffuse=false]", "option diffuse given twice"),
    ],
)
def test_bad_specs_name_the_spec_and_the_problem(spec, needle):
    with pytest.raises(ParameterError) as info:
        models.parse_spec(spec)
    assert f"model spec {spec!r}" in str(info.value) and needle in str(info.value)


@pytest.mark.parametrize("text", ["a[b,c", "a],b", "a[b[c]]"])
def test_unbalanced_model_lists_are_refused(text):
    with pytest.raises(ParameterError, match="unbalanced brackets"):
        models.split_specs(text)


@pytest.mark.slow  # 16 s; resuming: test_killed_sweep_resumes_without_redoing_work
def test_a_variant_is_fitted_resumed_and_ranked_as_its_own_model(tmp_path):
    mats = synthetic_materials(1)
    kw = dict(ARGS, jobs=1, progress=False)
    # the third spec is the second with a default option spelt out: the same model
    specs = ["lafortune", "lafortune[n_lobes=2]", "lafortune[anisotropic=false, n_lobes=2]"]
    s = run_sweep(tmp_path, mats, specs, ["low_e2"], **kw)
    assert (s.n_tasks, s.n_done, s.n_errors) == (2, 2, 0)
    folder = tmp_path / mats[0].name
    assert sorted(p.name for p in folder.iterdir()) == [
        "lafortune@n_lobes=2__low_e2.json",
        "lafortune__low_e2.json",
    ]
    d = json.loads((folder / "lafortune@n_lobes=2__low_e2.json").read_text())
    assert (d["model"], d["label"], d["options"]["n_lobes"]) == (
        "lafortune",
        "lafortune[n_lobes=2]",
        2,
    )
    assert (
        "rho_2" in d["params"]
        and "rho_2" not in json.loads((folder / "lafortune__low_e2.json").read_text())["params"]
    )
    man = json.loads((tmp_path / "sweep.json").read_text())
    assert man["models"] == {
        "lafortune": {"n_lobes": "1", "anisotropic": "False"},
        "lafortune[n_lobes=2]": {"n_lobes": "2", "anisotropic": "False"},
    }
    stamp = (folder / "lafortune@n_lobes=2__low_e2.json").stat().st_mtime_ns
    again = run_sweep(tmp_path, mats, ["lafortune[n_lobes=2]"], ["low_e2"], **kw)
    assert (again.n_tasks, again.n_skipped, again.n_done) == (1, 1, 0)
    assert (folder / "lafortune@n_lobes=2__low_e2.json").stat().st_mtime_ns == stamp
    res = load_sweep(tmp_path)
    assert sorted(r.model for r in res.records) == ["lafortune", "lafortune[n_lobes=2]"]
    mx = matrices(res, "low_e2")
    assert mx.models == ("lafortune", "lafortune[n_lobes=2]")
    assert sorted(mx.rank[0].tolist()) in ([1.0, 2.0], [1.5, 1.5])  # two models, two places
    assert np.isfinite(mx.loss).sum() == sum(r.converged for r in res.records)


def test_sweep_cli_splits_models_outside_brackets(tmp_path, monkeypatch, capsys):
    import brdffit.sweep as sweep

    seen = {}

    def fake(out, materials, model_specs, metrics, **kw):
        seen["models"] = model_specs
        return sweep.SweepSummary(str(out), 0, 0, 0, 0, 0, 0.0)

    monkeypatch.setattr(sweep, "run_sweep", fake)
    argv = ["sweep", str(tmp_path), "--synthetic", "1", "--no-progress"]
    assert main([*argv, "--models", "walter,lafortune[n_lobes=2,anisotropic=true]"]) == 0
    assert seen["models"] == ["walter", "lafortune[n_lobes=2,anisotropic=true]"]
    capsys.readouterr()


def test_checkout_commit_reports_only_the_packages_own_checkout(tmp_path):
    def git(*args):
        subprocess.run(["git", "-C", str(tmp_path), *args], check=True, capture_output=True)

    (tmp_path / "brdffit").mkdir()
    (tmp_path / "brdffit" / "__init__.py").write_text("")
    (tmp_path / "site" / "brdffit").mkdir(parents=True)
    git("init", "-q")
    git("add", "-A")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "x")
    own = checkout_commit(tmp_path / "brdffit")
    assert own is not None and len(own) >= 7
    assert checkout_commit(tmp_path / "site" / "brdffit") is None  # a copy inside a repo
    (tmp_path / "brdffit" / "__init__.py").write_text("changed = 1\n")
    assert checkout_commit(tmp_path / "brdffit") == own + "-dirty"


# 38-43 s; the engine's own worker-loss test (tests/sweep/test_dask_runner.py) is fast
@pytest.mark.slow
def test_sweep_on_dask_survives_a_killed_worker(tmp_path):
    """A worker process killed while the sweep runs: Dask runs its task again on another
    worker and every result is written once (issue 31)."""
    import threading

    import psutil

    out = tmp_path / "dask"
    mats = synthetic_materials(4)
    killed: list[int] = []

    def kill_one_worker() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not killed:
            workers = []  # Dask's spawned worker processes (not multiprocessing's tracker)
            for c in psutil.Process().children(recursive=True):
                try:
                    cmd = " ".join(c.cmdline())
                except psutil.Error:  # gone, or a zombie
                    continue
                if "spawn_main" in cmd:
                    workers.append(c)
            if workers and _results(out):
                workers[0].kill()
                killed.append(workers[0].pid)
            time.sleep(0.05)

    watcher = threading.Thread(target=kill_one_worker, daemon=True)
    watcher.start()
    s = run_sweep(
        out, mats, ["lambert", "walter"], ["low_e2"], **ARGS, jobs=2, progress=False,
        announce=lambda line: None,
    )  # fmt: skip
    watcher.join(timeout=5)
    assert killed, "no worker was killed while the sweep ran"
    assert s.n_errors == 0 and s.n_done == 8
    assert len(_results(out)) == 8 and not list(out.rglob("*.error.json"))


def test_batched_sweep_gives_the_single_fits_answers(tmp_path):
    """--batch: one fit_many call per chunk of materials, the same results as one fit
    each (the same start policy), and each file says its batch size. Lambert: the
    sweep's chunking is the subject (walter's batched fit is test_fit_many's)."""
    mats = synthetic_materials(3)
    kw = dict(ARGS, jobs=1, progress=False)
    run_sweep(tmp_path / "one", mats, ["lambert"], ["low_e2"], **kw)
    run_sweep(tmp_path / "many", mats, ["lambert"], ["low_e2"], **kw, batch=2)
    one, many = _results(tmp_path / "one"), _results(tmp_path / "many")
    assert [p.relative_to(tmp_path / "one") for p in one] == [
        p.relative_to(tmp_path / "many") for p in many
    ]
    batches = []
    for a, b in zip(one, many, strict=True):
        ra, rb = json.loads(a.read_text()), json.loads(b.read_text())
        assert rb["loss"] == pytest.approx(ra["loss"], rel=1e-9)
        for k, v in ra["params"].items():
            np.testing.assert_allclose(rb["params"][k], v, rtol=1e-7, atol=1e-12)
        batches.append(rb["batch"])
    assert sorted(batches) == [1, 2, 2]
    with pytest.raises(SweepError, match="batch=0"):
        run_sweep(tmp_path / "bad", mats, ["lambert"], ["low_e2"], **kw, batch=0)
