"""Test set-up: float64 on, strict dtype promotion, warnings as errors (pyproject).

The persistent compilation cache is off for the tests and for every command they
start (``BRDFFIT_JAX_CACHE=off`` is inherited by subprocesses and Dask workers). XLA
can abort a process outright while loading a cached CPU executable, as it did once in
CI in ``test_lm``; an aborted pytest-xdist worker then left the run hanging until the
CI's time limit. The suite must not depend on, or write into, a folder outside the
checkout either.
"""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ["BRDFFIT_JAX_CACHE"] = "off"

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "merl_nbrdf"


@pytest.fixture
def nbrdf_dir() -> Path:
    """The NBRDF folder beside the checkout; skip the test cleanly where it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared NBRDF data not found at {SHARED_DATA}")
    return SHARED_DATA
