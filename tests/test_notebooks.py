"""The notebooks are stored with their figures, and the figures are what the code makes.

Fast checks on the stored files: every code cell's outputs come from its current source
(the hash ``notebooks/regenerate.py`` stamps), the cells ran once, top to bottom,
without an error; every cell that draws shows a picture (never a ``<Figure size ...>``
line in its place); pictures are of modest size; the first cells say how to point the
notebook at a measured file. Slow tier (``bash benchmarks/slow_checks.sh``): a fresh
kernel runs each notebook and its outputs match the stored ones, numbers aside (they
hold timings), and, for cells tagged ``varies``, in kind and image size only.
That the code names only public brdffit functions is checked by
``tests/test_public_api.py``.
"""

from __future__ import annotations

import base64
import importlib.util
import re
import struct
from pathlib import Path

import nbformat
import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("regenerate", ROOT / "notebooks" / "regenerate.py")
regenerate = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(regenerate)

NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
IDS = [p.stem for p in NOTEBOOKS]
MAX_BYTES = 1_500_000
"""Largest stored notebook: a page loads fast and the repository stays small."""
MAX_WIDTH_PX = 1100
"""Widest picture: 9-inch figures at the notebooks' 80 dpi are 720 px, the widest report
figure (theta_h x theta_d images, 12.6 in) 1008 px; Jupyter shrinks wider pictures to
the cell's width (about 1100 px on a laptop), and their text with them."""
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _read(path: Path) -> nbformat.NotebookNode:
    return nbformat.read(path, as_version=4)


def _where(path: Path, nb: nbformat.NotebookNode, cell: nbformat.NotebookNode) -> str:
    return f"{path.name} cell {nb.cells.index(cell)}"


def _png_size(b64: str) -> tuple[int, int]:
    """(width, height) in pixels from a base64 PNG's IHDR chunk."""
    head = base64.b64decode(b64[:48])
    assert head[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    return struct.unpack(">II", head[16:24])


def test_notebooks_exist():
    assert {"quickstart", "compare_models", "error_vs_time", "simplify"} <= set(IDS)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_stored_outputs_come_from_the_current_code(path):
    nb = _read(path)
    cells = regenerate.code_cells(nb)
    stale = [
        _where(path, nb, c)
        for c in cells
        if c.metadata.get(regenerate.KEY, {}).get("source_sha256") != regenerate.source_hash(c)
    ]
    assert not stale, (
        f"outputs not from the current code in {stale}: run python notebooks/regenerate.py "
        f"{path.stem}"
    )
    counts = [c.execution_count for c in cells]
    assert counts == list(range(1, len(cells) + 1)), f"{path.name}: not one run, top to bottom"
    errors = [_where(path, nb, c) for c in cells for o in c.outputs if o.output_type == "error"]
    assert not errors, f"errors stored in {errors}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_every_cell_that_draws_shows_its_picture(path):
    nb = _read(path)
    drawing = [c for c in regenerate.code_cells(nb) if regenerate.DRAWS.search(c.source)]
    assert drawing, f"{path.name} draws nothing"
    blank = [_where(path, nb, c) for c in drawing if not regenerate.images(c)]
    assert not blank, f"cells that draw but show no picture: {blank}"
    as_text = [
        _where(path, nb, c)
        for c in regenerate.code_cells(nb)
        for o in c.outputs
        if re.search(r"<(Figure|Axes)\b", str(o.get("data", {}).get("text/plain", "")))
        and "image/png" not in o.get("data", {})
    ]
    assert not as_text, f"a figure printed as text instead of shown: {as_text}"
    agg = [_where(path, nb, c) for c in nb.cells if "matplotlib.use(" in c.source]
    assert not agg, f"matplotlib.use(...) turns off the inline backend: {agg}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_stored_notebooks_stay_small(path):
    assert path.stat().st_size < MAX_BYTES, f"{path.name}: {path.stat().st_size} bytes"
    nb = _read(path)
    for c in regenerate.code_cells(nb):
        for png in regenerate.images(c):
            w, h = _png_size(png)
            assert w <= MAX_WIDTH_PX and h <= 1.5 * MAX_WIDTH_PX, (_where(path, nb, c), w, h)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_first_cells_say_how_to_use_a_measured_file(path):
    nb = _read(path)
    assert nb.cells[0].cell_type == "markdown" and "MEASURED" in nb.cells[0].source
    first_code = regenerate.code_cells(nb)[0]
    assert re.search(r"^MEASURED\s*=", first_code.source, re.M), "MEASURED not set up front"


def _normalised(cell: nbformat.NotebookNode) -> list[tuple]:
    """A cell's outputs as (kind, mime types, text with numbers masked, image sizes)."""
    out: list[tuple] = []
    for o in cell.outputs:
        if o.output_type == "stream" and out and out[-1][:2] == ("stream", (o.name,)):
            o = {"output_type": "stream", "text": out.pop()[4] + o.text}  # one stream, split
        data = o.get("data", {})
        text = o.get("text", "") + "".join(
            str(data[m]) for m in ("text/plain", "text/markdown", "text/html") if m in data
        )
        text = " ".join(NUMBER.sub("#", text).split())
        sizes = tuple(_png_size(v) for k, v in data.items() if k == "image/png")
        kinds = (o.get("name", ""),) if o["output_type"] == "stream" else tuple(sorted(data))
        out.append((o["output_type"], kinds, text, sizes, o.get("text", "")))
    return [x[:4] for x in out]


@pytest.mark.slow  # the four notebooks take 3 to 4 minutes on 2 cores
@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_a_fresh_run_gives_the_stored_outputs(path):
    fresh, _ = regenerate.execute(path)
    stored = _read(path)
    pairs = list(zip(regenerate.code_cells(stored), regenerate.code_cells(fresh), strict=True))
    for old, new in pairs:
        where = _where(path, stored, old)
        assert not [o for o in new.outputs if o.output_type == "error"], where
        a, b = _normalised(old), _normalised(new)
        if "varies" in old.metadata.get("tags", []):
            a, b = ([(k, m, "", s) for k, m, _, s in x] for x in (a, b))
        assert a == b, f"{where}: a fresh run differs from the stored outputs"
