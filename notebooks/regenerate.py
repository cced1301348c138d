"""Run the notebooks top to bottom and store them with their outputs.

    python notebooks/regenerate.py              # every notebook in this folder
    python notebooks/regenerate.py quickstart   # the ones named (with or without .ipynb)

Each notebook is executed by a fresh Jupyter kernel (``python3``) in this folder, as a
user would run it, and written back (atomically) with its outputs, so that it reads on a
repository page without being run. Every code cell is stamped with the SHA-256 of its
source (``metadata.brdffit.source_sha256``): the test suite
(``tests/test_notebooks.py``) checks that the stored outputs come from the code as it
is now, that every cell that draws shows a picture, and (slow tier) that a fresh run
gives the same outputs. Run this after editing a notebook.

The outputs are deterministic up to timings: the notebooks fix their seeds and figure
sizes. A cell whose text depends on timings carries the tag ``varies``; the fresh-run
check compares only the kinds and sizes of its outputs.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import re
import sys
import tempfile
import time
from pathlib import Path

import nbclient
import nbformat

HERE = Path(__file__).resolve().parent
KEY = "brdffit"
TIMEOUT_S = 900
"""Longest a cell may run (s); the slowest cell today takes under a minute on 2 cores."""

DRAWS = re.compile(r"_figure\(|plot_slices\(|\.plot\(|plt\.|\.subplots\(")
"""Code that makes a figure: a cell that matches must show a picture."""


def source_hash(cell: nbformat.NotebookNode) -> str:
    """SHA-256 (hex) of a cell's source text."""
    return hashlib.sha256(cell.source.encode()).hexdigest()


def code_cells(nb: nbformat.NotebookNode) -> list[nbformat.NotebookNode]:
    """The notebook's code cells, in order."""
    return [c for c in nb.cells if c.cell_type == "code"]


def images(cell: nbformat.NotebookNode) -> list[str]:
    """The base64 PNG images a code cell shows, in order."""
    outputs = cell.get("outputs", [])
    return [o.data["image/png"] for o in outputs if "image/png" in o.get("data", {})]


def execute(path: Path) -> tuple[nbformat.NotebookNode, float]:
    """The notebook at ``path`` run top to bottom by a fresh kernel, and the seconds it took."""
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb,
        timeout=TIMEOUT_S,
        kernel_name="python3",
        record_timing=False,
        resources={"metadata": {"path": str(path.parent)}},
    )
    t0 = time.perf_counter()
    client.execute()
    return nb, time.perf_counter() - t0


def stamp(nb: nbformat.NotebookNode) -> None:
    """Record each code cell's source hash beside its outputs."""
    for cell in code_cells(nb):
        cell.metadata[KEY] = {"source_sha256": source_hash(cell)}


def write(nb: nbformat.NotebookNode, path: Path) -> None:
    """Write ``nb`` to ``path`` atomically (a temporary file in the same folder, renamed)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            nbformat.write(nb, f)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def notebooks(names: list[str]) -> list[Path]:
    """The notebooks named (stems or file names), or all of them."""
    if not names:
        return sorted(HERE.glob("*.ipynb"))
    paths = [HERE / (n if n.endswith(".ipynb") else f"{n}.ipynb") for n in names]
    missing = [p.name for p in paths if not p.is_file()]
    if missing:
        raise SystemExit(f"regenerate.py: no such notebook in {HERE}: {', '.join(missing)}")
    return paths


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("names", nargs="*", help="notebooks to run (default: all)")
    args = parser.parse_args(argv)
    for path in notebooks(args.names):
        nb, seconds = execute(path)
        stamp(nb)
        write(nb, path)
        n_images = sum(len(images(c)) for c in code_cells(nb))
        size = path.stat().st_size / 1e3
        print(f"{path.name}: {n_images} figures, {seconds:.0f} s, {size:.0f} kB", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
