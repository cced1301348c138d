"""The demo (README's main command) runs end to end and writes what it says it writes."""

from __future__ import annotations

import json
from html.parser import HTMLParser

import pytest

from brdffit.cli.demo import TRUTH, run_demo

# 36-43 s on 2 cores: in the slow tier (bash benchmarks/slow_checks.sh). Its parts stay
# in the default suite: fit, sample, rank, report and export through the command line
# (tests/cli/test_cli.py, test_html_report.py, test_export.py).
pytestmark = pytest.mark.slow


def test_demo_writes_fits_posterior_report_and_exports(tmp_path):
    lines: list[str] = []
    files = run_demo(
        tmp_path, stride=(9, 9, 15), n_steps=60, n_subsample=200, progress=False, log=lines.append
    )
    roles = ("material", "fit_walter", "ranking", "posterior", "corner", "traces", "predictive")
    for role in (*roles, "slices", "html"):
        assert files[role].is_file() and files[role].stat().st_size > 0, role
    # The truth is walter: it must win the ranking, and its fit land near the truth.
    fit = json.loads(files["fit_walter"].read_text())
    first = next(x for x in files["ranking"].read_text().splitlines() if x.startswith("| 1 |"))
    assert first.split("|")[2].strip() == "walter", first
    assert abs(fit["params"]["alpha"] - TRUTH["alpha"]) < 0.01
    HTMLParser().feed(files["html"].read_text())  # parses
    exports = [p for role, p in files.items() if role.startswith("export_")]
    suffixes = {p.name.split(".", 2)[-1] for p in exports}
    assert {"mitsuba.xml", "mitsuba.json", "gltf"} <= suffixes, suffixes
    gltf = json.loads(next(p for p in exports if p.suffix == ".gltf").read_text())
    assert gltf["materials"][0]["pbrMetallicRoughness"]
    assert sum(line.startswith("export ") for line in lines) == 2
