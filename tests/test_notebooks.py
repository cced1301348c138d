"""Every notebook in notebooks/ runs top to bottom without an error (slow tier), and
every notebook's code parses and names only brdffit functions that exist (fast)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


def _code(path: Path) -> str:
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    return "\n".join(c.source for c in nb.cells if c.cell_type == "code")


def _brdffit_names(tree: ast.AST) -> set[str]:
    """Dotted names ``brdffit.a.b`` the code uses, and ``from brdffit.x import y`` pairs."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            parts = []
            n = node
            while isinstance(n, ast.Attribute):
                parts.append(n.attr)
                n = n.value
            if isinstance(n, ast.Name) and n.id == "brdffit":
                out.add(".".join(["brdffit", *reversed(parts)]))
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("brdffit"):
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return out


def _exists(dotted: str) -> bool:
    import importlib

    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for attr in parts[k:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_code_parses_and_names_existing_api(path):
    tree = ast.parse(_code(path))
    names = _brdffit_names(tree)
    assert names, "a notebook that uses no brdffit name"
    missing = sorted(n for n in names if not _exists(n))
    assert not missing, f"{path.name} names what brdffit lacks: {missing}"


@pytest.mark.slow  # 26-72 s each on 2 cores: bash benchmarks/slow_checks.sh runs them
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.read(path, as_version=4)
    nbclient.NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    ).execute()
    errors = [
        o
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.get("outputs", [])
        if o.get("output_type") == "error"
    ]
    assert not errors
