"""One-file HTML reports: parse, embed every figure as a decodable PNG, link nothing outside,
and render in a real headless browser (skipped where no Chromium is installed)."""

from __future__ import annotations

import base64
import shutil
import struct
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

import brdffit
from brdffit import FitResult, models, synthesize, write_fit_html, write_sweep_html
from brdffit.cli import main
from brdffit.io.merl import MERL_SCALES
from tests.sweep_fixtures import make_sweep

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
KD = [0.2, 0.5, 0.8]


class _Collect(HTMLParser):
    """Tags, every URL-valued attribute, table cells and text of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[str] = []
        self.urls: list[tuple[str, str]] = []
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        for name, value in attrs:
            if name in ("src", "href", "srcset", "action", "poster", "data") and value:
                self.urls.append((tag, value))
            if name == "style" and value and "url(" in value:
                self.urls.append((tag, value))

    def handle_data(self, data):
        self.text.append(data)


def _parse(path: Path) -> _Collect:
    text = path.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>")
    p = _Collect()
    p.feed(text)
    p.close()
    # nothing outside the file: no link, script or style sheet fetched, no url() in CSS
    assert "link" not in p.tags and "script" not in p.tags and "iframe" not in p.tags
    assert "url(" not in text and "@import" not in text
    assert all(u.startswith("data:image/png;base64,") for _, u in p.urls), p.urls
    return p


def _pngs(p: _Collect) -> list[tuple[int, int]]:
    """Width and height of every embedded image, read from its decoded PNG header."""
    sizes = []
    for tag, url in p.urls:
        assert tag == "img"
        raw = base64.b64decode(url.split(",", 1)[1], validate=True)
        assert (
            raw[:8] == PNG_SIGNATURE and raw[12:16] == b"IHDR" and raw.endswith(b"IEND\xaeB`\x82")
        )
        sizes.append(struct.unpack(">II", raw[16:24]))
    return sizes


def _result(n_samples: int = 500) -> FitResult:
    """A Lambert result as a sweep file would hold it (no fit run)."""
    return FitResult.from_dict(
        {
            "model": "lambert",
            "options": {},
            "metric": "low_e2",
            "params": {"kd": KD},
            "init_params": {"kd": [0.5, 0.5, 0.5]},
            "stderr": {"kd": [1e-3, 2e-3, float("nan")]},
            "loss": 1.25e-3,
            "losses": {"low_e2": 1.25e-3, "ngan": 0.01},
            "status": "MAX_STEPS",
            "n_samples": n_samples,
            "n_data": 3 * n_samples,
            "n_free": 3,
            "source": "synthetic <lambert> & co",
            "warnings": ["kd[b] has no standard error"],
        }
    )


@pytest.fixture(scope="module")
def lambert_data():
    return synthesize(models.get("lambert"), {"kd": KD}, stride=9)


@pytest.fixture(scope="module")
def fit_page(tmp_path_factory, lambert_data) -> Path:
    path = tmp_path_factory.mktemp("html") / "fit.html"
    assert write_fit_html(path, _result(), lambert_data, sphere_size=48) == path
    plt.close("all")
    return path


def test_fit_page_tables_and_figures(fit_page):
    p = _parse(fit_page)
    text = " ".join(p.text)
    sizes = _pngs(p)
    assert len(sizes) == 3 and all(w > 300 and h > 200 for w, h in sizes)
    for part in ("metric low_e2", "0.00125", "not converged", "kd[r]", "kd[b]", "n/a", "ngan"):
        assert part in text, part
    assert "MAX_STEPS:" not in text  # the status once, in words
    assert "MERL grid at stride 9 9 9" in text  # not "scattered directions"
    assert "synthetic <lambert> & co" in text  # escaped in the file, read back intact
    assert "Warning: kd[b] has no standard error" in text


def test_fit_page_without_grid_data_says_why(tmp_path):
    rng = np.random.default_rng(0)
    wi, wo = rng.normal(size=(2, 50, 3))
    wi[:, 2], wo[:, 2] = abs(wi[:, 2]), abs(wo[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    data = synthesize(models.get("lambert"), {"kd": KD}, grid="directions", directions=(wi, wo))
    p = _parse(write_fit_html(tmp_path / "r.html", _result(), data))
    assert _pngs(p) == [] and "No figures" in " ".join(p.text)


def test_sweep_page(tmp_path):
    sweep = make_sweep(tmp_path / "s")
    path = write_sweep_html(sweep, n_boot=50)
    assert path == sweep / "report.html"
    p = _parse(path)
    assert len(_pngs(p)) == 2  # the rank matrix and the Pareto figure of the one metric
    text = " ".join(p.text)
    for part in ("mean rank [95% CI]", "median fit time (s)", "gold-metallic-paint", "low_e2"):
        assert part in text, part
    assert p.tags.count("table") == 4


def test_sweep_page_takes_the_families_file(tmp_path):
    sweep = make_sweep(tmp_path / "s")
    (tmp_path / "fam.csv").write_text("steel,ferrous\nblue-fabric,felt\n")
    text = " ".join(_parse(write_sweep_html(sweep, n_boot=20, families=tmp_path / "fam.csv")).text)
    assert "ferrous" in text and "felt" in text


def test_cli_report_writes_html_beside_markdown(tmp_path, capsys):
    sweep = make_sweep(tmp_path / "s")
    assert main(["report", str(sweep)]) == 0
    out = capsys.readouterr().out.split()
    assert out == [str(sweep / "report.html"), str(sweep / "report" / "report.md")]
    assert len(_pngs(_parse(sweep / "report.html"))) == 2


def test_cli_fit_report(tmp_path, capsys):
    # a MERL file of Lambert values with 2% noise, written directly in the format
    rng = np.random.default_rng(1)
    raw = np.asarray(KD)[:, None] / np.pi / MERL_SCALES[:, None] * np.ones((3, 1458000))
    raw *= np.exp(0.02 * rng.standard_normal(raw.shape))
    (tmp_path / "m.binary").write_bytes(np.int32([90, 90, 180]).tobytes() + raw.tobytes())
    out = tmp_path / "r.html"
    args = ["fit", str(tmp_path / "m.binary"), "--model", "lambert", "--stride", "15", "15", "15"]
    assert main([*args, "--screen", "0", "--report", str(out)]) == 0
    assert "[[Parameters]]" in capsys.readouterr().out
    assert len(_pngs(_parse(out))) == 3


def test_unwritable_report_names_the_file(tmp_path, lambert_data):
    path = tmp_path / "missing" / "r.html"
    with pytest.raises(OSError, match="r.html: cannot be written"):
        write_fit_html(path, _result(), lambert_data, sphere_size=16)
    with pytest.raises(OSError, match="r.html: cannot be written"):  # the folder is a file
        (tmp_path / "missing").write_text("")
        write_fit_html(path, _result(), lambert_data, sphere_size=16)


def _chromium() -> str | None:
    return next(
        (p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p),
        None,
    )


@pytest.mark.skipif(
    _chromium() is None,
    reason="no chromium binary on PATH (apt-get install chromium) to render the HTML report",
)
def test_report_renders_in_headless_chromium(fit_page, tmp_path):
    shot = tmp_path / "shot.png"
    cmd = [
        _chromium(),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={tmp_path / 'profile'}",
        f"--screenshot={shot}",
        "--window-size=1200,2000",
        fit_page.resolve().as_uri(),
    ]
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    img = plt.imread(shot)[..., :3]
    assert img.shape[:2] == (2000, 1200)
    colours = np.unique((img.reshape(-1, 3) * 255).round().astype(np.uint8), axis=0)
    assert len(colours) > 200  # text, tables and the embedded figures, not a blank page
    assert img.std() > 0.05
    # the spheres are drawn in colour: many pixels far from grey
    chroma = img.max(axis=-1) - img.min(axis=-1)
    assert (chroma > 0.2).sum() > 2000


def test_flags_column_names_scalars_at_a_bound(tmp_path, lambert_data):
    """The at-bound flag of the text report reaches the HTML flags column (it was empty:
    the check looked up the parameter's name where the result lists channel labels)."""
    res = _result()
    res = FitResult.from_dict(
        {**res.to_dict(), "params": {"kd": [0.2, 0.0, 0.8]}, "at_bound": ["kd[g]"]}
    )
    assert "kd[g]" in res.at_bound
    p = _parse(write_fit_html(tmp_path / "b.html", res, lambert_data, sphere_size=32))
    plt.close("all")
    cells = [t.strip() for t in p.text if t.strip()]
    row = cells[cells.index("kd[g]") : cells.index("kd[g]") + 6]
    assert row[-1].startswith("at bound"), row


def test_the_fit_page_names_the_exports_their_files_and_errors(tmp_path, lambert_data):
    """The exports written beside a fit are in its report: target, form, exactness,
    the three measured errors and the file names, as the export itself gives them."""
    result = brdffit.fit(models.get("lambert"), lambert_data, "ngan", n_restarts=0)
    written = brdffit.write_exports(result, ["mitsuba", "gltf"], tmp_path / "mat")
    p = _parse(write_fit_html(tmp_path / "r.html", result, lambert_data, sphere_size=16,
                              exports=written))  # fmt: skip
    text = " ".join(p.text)
    assert "Exports" in text
    for e, paths in written:
        for part in (e.target, e.target_model, f"{e.error:.3g}", f"{e.albedo_error:.3g}"):
            assert part in text, (e.target, part)
        assert ("exact" if e.exact else "approximate") in text
        for path in paths:
            assert path.name in text and path.is_file()
    assert "relative RMS of f cos(theta_i)" in text  # what the errors are
