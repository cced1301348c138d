"""Test set-up: float64 on, strict dtype promotion, warnings as errors (pyproject)."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

import brdffit  # noqa: E402

brdffit.enable_compilation_cache()

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "merl_nbrdf"


@pytest.fixture
def nbrdf_dir() -> Path:
    """The NBRDF folder beside the checkout; skip the test cleanly where it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared NBRDF data not found at {SHARED_DATA}")
    return SHARED_DATA
