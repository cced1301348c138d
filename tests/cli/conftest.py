"""Small CSV tables of synthetic samples for the command-line tests: quick to read and fit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from brdffit import models, synthesize

TRUTH = {"kd": [0.1, 0.2, 0.3], "f0": [0.9, 0.6, 0.3], "alpha": 0.15}


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
    return _write_csv(tmp_path_factory.mktemp("csv") / "good.csv", data)


@pytest.fixture(scope="module")
def lambert_csv(tmp_path_factory) -> Path:
    """Noise-free Lambert samples: the LM fit is exact, its residuals ~0."""
    data = synthesize(models.get("lambert"), {"kd": [0.1, 0.2, 0.3]}, stride=(15, 15, 15))
    return _write_csv(tmp_path_factory.mktemp("csv") / "lambert.csv", data)
