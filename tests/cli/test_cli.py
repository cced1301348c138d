"""The command line: every subcommand once, its version, help text for every option,
progress lines, and bad input as one stderr line with exit 2 (more careless input:
``test_bad_input.py``)."""

from __future__ import annotations

import argparse
import json
import re

import numpy as np
import pytest

from brdffit import __version__, models, synthesize, write_merl
from brdffit.cli import build_parser, main

TRUTH = {"kd": [0.1, 0.2, 0.3], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}
SMALL = ["--stride", "9", "9", "9"]


@pytest.fixture(scope="module")
def merl_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "ggx.binary"
    write_merl(path, synthesize(models.get("walter"), TRUTH, noise_mult=0.03, seed=5))
    return path


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_models_lists_every_model_with_parameters(capsys):
    code, out, _ = _run(capsys, "models")
    assert code == 0
    for name in models.available():
        assert name in out
    assert "alpha" in out and "options:" in out


def test_info_and_fit_with_json(capsys, merl_file, tmp_path):
    code, out, _ = _run(capsys, "info", merl_file)
    assert code == 0 and "1458000" in out
    js = tmp_path / "fit.json"
    code, out, _ = _run(capsys, "fit", merl_file, "--model", "walter", "--json", js, *SMALL)
    assert code == 0 and "[[Parameters]]" in out and "low_e2" in out
    d = json.loads(js.read_text())
    assert {"model", "metric", "params", "stderr", "loss", "converged"} <= set(d)
    assert d["converged"] and np.allclose(d["params"]["alpha"], 0.15, rtol=0.02)
    code, out, _ = _run(capsys, "fit", merl_file, "--model", "walter", "--robust", "huber", *SMALL)
    assert code == 0 and "huber loss, scale" in out
    code, out, _ = _run(capsys, "fit", merl_file, "--model", "walter", "--errors", "blocks", *SMALL)
    assert code == 0 and "errors by cluster sandwich (CR2) over" in out and "Student-t" in out


def test_fit_with_options_and_freeze(capsys, merl_file):
    code, out, _ = _run(
        capsys,
        "fit",
        merl_file,
        "--model",
        "walter",
        "--option",
        "distribution=beckmann",
        "--freeze",
        "alpha=0.2",
        "--metric",
        "ngan",
        *SMALL,
    )
    assert code == 0 and "distribution='beckmann'" in out and "(frozen)" in out


def test_fit_with_a_spec_and_an_option(capsys, merl_file):
    code, out, _ = _run(
        capsys,
        "fit",
        merl_file,
        "--model",
        "walter[distribution=beckmann]",
        "--option",
        "anisotropic=false",
        # the settings of the test above, whose model this spec names: one compiled fit
        "--freeze",
        "alpha=0.2",
        "--metric",
        "ngan",
        *SMALL,
    )
    assert code == 0 and "walter(distribution='beckmann', " in out


def test_rank(capsys, merl_file):
    code, out, _ = _run(
        capsys, "rank", merl_file, "--models", "lambert,walter", "--format", "markdown", *SMALL
    )
    assert code == 0
    assert out.index("| 1 | walter") < out.index("| 2 | lambert")


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["info", "missing.binary"], "missing.binary"),
        (["fit", "{bad}", "--model", "walter"], "header"),
        (["fit", "{good}", "--model", "nope"], "unknown model 'nope'"),
        (["fit", "{good}", "--model", "walter", "--option", "colour=red"], "no option"),
        (["fit", "{good}", "--model", "walter", "--metric", "l2"], "invalid choice"),
        (["fit", "{good}", "--model", "walter", "--freeze", "beta=1"], "cannot freeze"),
        (["rank", "{good}", "--models", "walter,nope"], "unknown model 'nope'"),
        (["fit", "{good}", "--model", "walter", "--stride", "2", "2", "2"], "stride"),
        (["fit", "{good}", "--model", "walter[colour=red]"], "no option(s) ['colour']"),
        (["fit", "{good}", "--model", "lafortune[n_lobes=2]", "--option", "n_lobes=x"], "n_lobes"),
        (["rank", "{good}", "--models", "walter,lafortune[n_lobes=two]"], "is not of type int"),
        (["rank", "{good}", "--models", "walter,lafortune[n_lobes=2"], "unbalanced brackets"),
        (["rank", "{good}", "--models", "nope[n_lobes=2],walter"], "'nope[n_lobes=2]'"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(capsys, merl_file, tmp_path, argv, needle):
    bad = tmp_path / "bad.binary"
    bad.write_bytes(b"\x00" * 64)
    argv = [a.replace("{bad}", str(bad)).replace("{good}", str(merl_file)) for a in argv]
    with pytest.raises(SystemExit) as exit_info:
        raise SystemExit(main(argv))
    out, err = capsys.readouterr()
    assert exit_info.value.code == 2
    assert len(err.strip().splitlines()) == 1 and needle in err, err


@pytest.mark.slow
@pytest.mark.parametrize("name", models.available())
def test_fit_command_works_for_every_model(capsys, merl_file, tmp_path, name):
    js = tmp_path / f"{name}.json"
    code, out, err = _run(
        capsys,
        "fit",
        merl_file,
        "--model",
        name,
        "--restarts",
        "0",
        "--json",
        js,
        "--stride",
        "15",
        "15",
        "15",
    )
    assert code == 0, err
    d = json.loads(js.read_text())
    assert d["model"] == name and set(d["params"]) == {p.name for p in models.get(name).parameters}
    assert np.isfinite(d["loss"])


@pytest.mark.slow  # 23 s; test_simplify_prints_progress_per_move runs it fast
def test_simplify_prints_the_path_and_the_chosen_label(capsys, merl_file, tmp_path):
    # the fixture's kd and f0 are coloured and its diffuse term is on: nothing goes
    js, start = tmp_path / "simplify.json", "walter[specular_weight=false]"
    code, out, err = _run(
        capsys, "simplify", merl_file, "--model", start, "--criterion", "bic", "--json", js, *SMALL
    )
    assert code == 0, err
    assert "Simplify walter[specular_weight=false]" in out and "BIC" in out
    assert "grey f0" in out and "diffuse=false" in out
    assert out.strip().splitlines()[-1] == start
    d = json.loads(js.read_text())
    assert d["chosen"] == start and d["path"][0]["decision"] == "chosen"
    with pytest.raises(SystemExit) as exit_info:
        raise SystemExit(
            main(["simplify", str(merl_file), "--model", "walter", "--criterion", "aic"])
        )
    err = capsys.readouterr()[1]
    assert exit_info.value.code == 2 and len(err.strip().splitlines()) == 1 and "aic" in err


def test_sample_says_what_it_does_and_shows_each_warning_once(capsys, merl_file):
    argv = ["sample", merl_file, "--model", "lambert", "--stride", "15", "15", "15"]
    # 30 steps are far too short: the chain-too-short warning must come, once, cleanly
    # (pytest turns a Python warning into an error, so one escaping the CLI fails here)
    code, out, err = _run(capsys, *argv, "--steps", "30", "--subsample", "200", "--no-progress")
    assert code == 0, err
    lines = err.splitlines()
    assert lines[0].startswith("fitting lambert to") and "Levenberg-Marquardt" in lines[0]
    assert out.index("[[Fit]] lambert") < out.index("[[Parameters]]") < out.index("[[Posterior]]")
    needle = "autocorrelation times"
    assert (out + err).count(needle) == 1, (out, err)
    warning = next(x for x in lines if needle in x)
    assert warning.startswith("brdffit sample: warning: chain of")
    assert "Warning" not in err and "cli.py" not in err  # no raw Python warning


def test_sample_on_noise_free_data_starts_from_a_non_degenerate_ball(capsys, lambert_csv):
    # emcee refused the start ball ("large condition number"): every LM error was ~0
    argv = ["sample", lambert_csv, "--model", "lambert", "--steps", "20", "--subsample", "100"]
    code = main([*map(str, argv), "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "[[Posterior]]" in out


def test_fit_header_names_the_stride(capsys, tmp_path):
    path = tmp_path / "g.binary"
    write_merl(path, synthesize(models.get("lambert"), {"kd": [0.2, 0.2, 0.2]}))
    assert main(["fit", str(path), "--model", "lambert", "--stride", "15", "15", "15"]) == 0
    header = capsys.readouterr().out.splitlines()[0]
    assert "stride (15, 15, 15)" in header, header


# --------------------------------------------------------------------------- version and help


def test_version(capsys):
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
