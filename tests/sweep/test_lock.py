"""A sweep folder's lock: one sweep at a time, a stale lock left by a dead process taken
over, and a second sweep into a running folder refused with one line and exit 2."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from brdffit.errors import SweepError
from brdffit.sweep import sweep_lock
from tests.helpers import fails_cleanly

SMALL = ["--stride", "15", "15", "15"]


def test_sweep_folder_lock(tmp_path):
    with sweep_lock(tmp_path):
        with pytest.raises(SweepError, match="another sweep"):
            with sweep_lock(tmp_path):
                pass
    # a stale lock left by a dead process is taken over
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / ".sweep.lock").write_text(f"{dead.pid}\n")
    with sweep_lock(tmp_path):
        assert (tmp_path / ".sweep.lock").read_text().split()[0] == str(os.getpid())
    assert not (tmp_path / ".sweep.lock").exists()


def test_second_sweep_into_a_running_folder_exits_2(capsys, tmp_path):
    out = tmp_path / "sw"
    out.mkdir()
    (out / ".sweep.lock").write_text(f"{os.getppid()}\n")  # a live process holds it
    argv = ["sweep", out, "--synthetic", "1", "--models", "lambert", "--jobs", "1", *SMALL]
    fails_cleanly(capsys, [*argv, "--no-progress"], "another sweep", str(os.getppid()))
