"""Test set-up: float64 on, strict dtype promotion, warnings as errors (pyproject).

The persistent compilation cache is off for the tests and for every command they
start (``BRDFFIT_JAX_CACHE=off`` is inherited by subprocesses and Dask workers). XLA
can abort a process outright while loading a cached CPU executable, as it did once in
CI in ``test_lm``; an aborted pytest-xdist worker then left the run hanging until the
CI's time limit. The suite must not depend on, or write into, a folder outside the
checkout either.

The tests compile XLA's CPU code at backend optimisation level 0 with LLVM's cheap
passes only (:data:`TEST_XLA_FLAGS`, added to any ``XLA_FLAGS`` set, inherited the same
way). The suite is compile-bound: measured on ``tests/engine/test_lm.py`` and
``tests/selection`` (80 tests, one process), XLA's backend compilation took 72 s of 89 s
for 469 programs; with these flags 30 s of 53 s. The whole suite on this project's
2-core box, 2026-12-07 (one run each, so the box's own swings are in these): 1,060 s
with XLA's defaults, 737 s with the cheap LLVM passes only, 580 s with both flags. The
tests check answers, not the speed of the machine code, and the flags change no result
the tests look at (the whole suite passes either way). Speed is measured by
``benchmarks/`` with XLA's defaults.
"""

import os

TEST_XLA_FLAGS = "--xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true"

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ["BRDFFIT_JAX_CACHE"] = "off"
os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {TEST_XLA_FLAGS}".strip()

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
