"""Material families: the guess from a material's name (its head noun, never its colour),
and a families file (``--families``) overriding the guess in the sweep report and in a
sweep, with one line and exit 2 for a bad file."""

from __future__ import annotations

import pytest

import brdffit.sweep as sweep
from brdffit.cli import main
from brdffit.errors import SweepError
from brdffit.selection.families import family_of, read_families
from tests.sweep_fixtures import make_sweep


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


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


@pytest.mark.parametrize(
    ("name", "family"),
    [
        ("acrylic_felt_green_rgb", "fabric"),  # a felt of acrylic fibres, not a plastic
        ("vch_silver_sticker_rgb", "other"),  # a vinyl film, not a metal
        ("ilm_l3_37_metallic_rgb", "other"),  # "metallic" is a look, not a material
        ("satin_gold", "other"),
        ("irid_flake_paint2_rgb", "paint"),
        ("aniso_brushed_aluminium_1", "metal"),
        ("gold-metallic-paint2", "metallic paint"),
        ("tungsten-carbide", "metal"),
    ],
)
def test_family_guess_takes_the_head_noun_and_does_not_guess_from_colours(name, family):
    assert family_of(name) == family


def test_families_file_overrides_the_guess_in_report_and_sweep(tmp_path, capsys, monkeypatch):
    fams = tmp_path / "families.csv"
    fams.write_text("material,family\nsteel,coated metal\n# a comment\n\nred-plastic,plastic\n")
    assert read_families(fams) == {"steel": "coated metal", "red-plastic": "plastic"}
    src = make_sweep(tmp_path / "s")
    code, _, err = _run(capsys, "report", src, "--families", fams)
    assert code == 0, err
    text = (src / "report" / "report.md").read_text()
    assert "| steel | coated metal | a |" in text and "| red-plastic | plastic | b |" in text
    seen = {}

    def fake(out, materials, *args, **kw):
        seen["families"] = {m.name: m.family for m in materials}
        return sweep.SweepSummary(str(out), 0, 0, 0, 0, 0, 0.0)

    monkeypatch.setattr(sweep, "run_sweep", fake)
    guessed = {m.name: m.family for m in sweep.synthetic_materials(2)}
    first = next(iter(guessed))
    fams.write_text(f"{first},my family\n")
    argv = ["sweep", tmp_path / "o", "--synthetic", "2", "--models", "lambert", "--no-progress"]
    code, _, err = _run(capsys, *argv, "--families", fams)
    assert code == 0, err
    assert seen["families"] == {**guessed, first: "my family"}
    bad = tmp_path / "bad.csv"
    bad.write_text("steel,metal,extra\n")
    code, _, err = _run(capsys, *argv, "--families", bad)
    assert code == 2 and "bad.csv: line 1" in err and err.count("\n") == 1
    with pytest.raises(SweepError, match="gives steel the family"):
        bad.write_text("steel,metal\nsteel,paint\n")
        read_families(bad)
