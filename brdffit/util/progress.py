"""The progress bar of every long command (``sweep``, ``rank``, ``simplify``), on stderr."""

from __future__ import annotations

import sys
import warnings

from tqdm import TqdmWarning

with warnings.catch_warnings():
    # In a Jupyter kernel without ipywidgets, tqdm.auto warns on import ("IProgress not
    # found") and falls back to the text bar, which is the bar we want there anyway.
    warnings.simplefilter("ignore", TqdmWarning)
    from tqdm.auto import tqdm


def progress_bar(total: int | None, desc: str, unit: str, enabled: bool = True):
    """The tqdm bar of a long command on stderr (``sweep``, ``rank``, ``simplify``):
    ``total`` steps of ``unit`` (``None``: count only); ``enabled=False`` shows nothing.
    Write a finished step's line above it with :func:`progress_line`."""
    return tqdm(
        total=total, desc=desc, unit=unit, disable=not enabled, dynamic_ncols=True,
        file=sys.stderr,
    )  # fmt: skip


def progress_line(bar, text: str) -> None:
    """``text`` as one line on stderr above ``bar`` (nothing when the bar is disabled)."""
    if not bar.disable:
        bar.write(text, file=sys.stderr)
