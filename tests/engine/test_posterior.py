"""A posterior shown in Jupyter and at a prompt: ``_repr_html_`` is one table row per
sampled scalar with the numbers and flags of ``summary()``, escaped; ``str`` is the
summary, ``repr`` one line, IPython's text form the summary. Built from small arrays, no
sampler run."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit import Posterior
from brdffit.engine.posterior import SUMMARY_HEAD
from tests.html_tables import tables, text

LABELS = ("kd[r]", "kd[g]", "alpha", "log_sigma")


@pytest.fixture(scope="module")
def posterior() -> Posterior:
    rng = np.random.default_rng(0)
    steps, walkers = 60, 8
    centre = np.array([0.2, 0.3, 0.002, -3.0])
    return Posterior(
        model="walter",
        options={"distribution": "ggx"},
        metric="low_e2",
        noise="mult",
        labels=LABELS,
        chain=centre + rng.normal(size=(steps, walkers, 4)) * [0.01, 0.01, 0.001, 0.05],
        log_prob=rng.normal(size=(steps, walkers)),
        acceptance_fraction=rng.uniform(0.2, 0.4, walkers),
        autocorr_time=np.array([3.0, 4.5, 2.0, 5.5]),
        burn=10,
        n_subsample=500,
        stuck_walkers=(),
        at_bound=(("alpha", 0.0),),
        wall_time=1.25,
        warnings=("chain <short> & thin", "alpha piled on 0"),
    )


def test_one_html_row_per_scalar_with_the_numbers_of_the_summary(posterior):
    markup = posterior._repr_html_()
    (t,) = tables(markup)
    assert t.head == [*SUMMARY_HEAD, "flags"]
    assert [row[0] for row in t.body] == list(LABELS)  # one row per label, in order
    summary = posterior.summary().splitlines()
    q = posterior.quantiles()
    for row, (cells, flags) in zip(t.body, posterior.summary_rows(), strict=True):
        assert row == [*cells, ", ".join(flags)]
        assert float(row[1]) == pytest.approx(q[row[0]][1], rel=1e-5)  # the median
        assert float(row[2]) == pytest.approx(q[row[0]][0], rel=1e-5)  # 2.5%
        # the summary's line of this scalar holds the same texts, in the same order
        (line,) = [x for x in summary if x.split()[:1] == [row[0]]]
        assert line.split()[:7] == row[:7]
    assert t.row("alpha")[7] == "at bound 0" and "at bound 0" in posterior.summary()
    assert [r[7] for r in t.body if r[0] != "alpha"] == ["", "", ""]
    assert all(r[1:7] == [True] * 6 for r in t.right)  # numbers right-aligned


def test_html_title_and_warnings_are_escaped(posterior):
    markup = posterior._repr_html_()
    shown = text(markup)
    assert "Posterior: walter (low_e2, noise mult), 8 walkers x 60 steps, burn 10" in shown
    assert "500 samples in the likelihood" in shown and "wall time 1.2 s" in shown
    acc = posterior.acceptance_fraction
    assert f"acceptance fraction {np.mean(acc):.3f} (min {np.min(acc):.3f})" in shown
    assert "Warning: chain <short> & thin" in shown and "Warning: alpha piled on 0" in shown
    assert "chain &lt;short&gt; &amp; thin" in markup and "<short>" not in markup


def test_summary_keeps_its_columns(posterior):
    lines = posterior.summary().splitlines()
    assert lines[0].startswith("[[Posterior]] walter (low_e2, noise mult), 8 walkers x 60 steps")
    assert lines[2] == (
        "    scalar               median         2.5%        97.5%      tau      ESS   R-hat"
    )
    cells, _ = posterior.summary_rows()[0]
    assert lines[3] == (
        f"    {cells[0]:<14} {cells[1]:>12} {cells[2]:>12} {cells[3]:>12} "
        f"{cells[4]:>8} {cells[5]:>8} {cells[6]:>7}"
    )
    assert lines[5].endswith("  at bound 0") and lines[-1] == "[[Warning]] alpha piled on 0"


def test_str_is_the_summary_repr_one_line_and_ipython_shows_the_summary(posterior):
    assert str(posterior) == posterior.summary()
    assert repr(posterior) == (
        "<Posterior walter low_e2, noise mult, 4 scalars, 8 walkers x 60 steps, 2 warnings>"
    )
    pretty = pytest.importorskip("IPython.lib.pretty")
    assert pretty.pretty(posterior) == posterior.summary()
