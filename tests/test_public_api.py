"""The names users are shown exist: everything in ``brdffit.__all__`` (and the public
subpackages' ``__all__``), every ``brdffit.x.y`` named in README.md and in the
notebooks (text and code), every ``from brdffit... import ...`` there, and the console
command of pyproject.toml's ``[project.scripts]``. A failure lists each missing name
with where it is named. The readers the README lists return Measurements, and the
error types are BrdffitErrors."""

from __future__ import annotations

import ast
import importlib
import inspect
import json
import re
import tomllib
from pathlib import Path

import pytest

import brdffit
from brdffit import BrdffitError, MissingDependencyError

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
PUBLIC_PACKAGES = (
    "brdffit",
    "brdffit.models",
    "brdffit.export",
    "brdffit.report",
    "brdffit.selection",
    "brdffit.sweep",
)

DOTTED = re.compile(r"(?<![\w.])brdffit(?:\.[A-Za-z_]\w*)+")
FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```", re.M | re.S)


def _resolve(dotted: str) -> bool:
    """Whether ``dotted`` names a module or an attribute reachable from one. The longest
    importable prefix is imported; an import error inside an existing module raises."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        name = ".".join(parts[:k])
        try:
            obj = importlib.import_module(name)
        except ModuleNotFoundError as e:
            if e.name is not None and not name.startswith(e.name):
                raise  # the module exists but one of its own imports does not
            continue
        for attr in parts[k:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def _code_names(tree: ast.AST) -> set[str]:
    """Dotted ``brdffit...`` names a piece of code uses: ``from brdffit.x import y``
    pairs, ``import brdffit.x`` modules, and attribute chains on ``brdffit`` or on a
    name imported from it (``from brdffit import models; models.get`` ->
    ``brdffit.models.get``)."""
    alias: dict[str, str] = {}
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "brdffit":
                    out.add(a.name)
                    alias[a.asname or "brdffit"] = a.name if a.asname else "brdffit"
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "brdffit":
            for a in node.names:
                out.add(f"{node.module}.{a.name}")
                alias[a.asname or a.name] = f"{node.module}.{a.name}"
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and not isinstance(node.ctx, ast.Store):
            parts = []
            n = node
            while isinstance(n, ast.Attribute):
                parts.append(n.attr)
                n = n.value
            if isinstance(n, ast.Name) and n.id in alias:
                out.add(".".join([alias[n.id], *reversed(parts)]))
    return out


def _readme_sources() -> list[tuple[str, str, str]]:
    """(where, kind, text) pieces of README.md: the whole text and each Python block."""
    text = README.read_text()
    out = [("README.md", "text", text)]
    for m in FENCE.finditer(text):
        if m.group(1) in ("python", "py"):
            line = text.count("\n", 0, m.start()) + 1
            out.append((f"README.md:{line}", "code", m.group(2)))
    return out


def _notebook_sources() -> list[tuple[str, str, str]]:
    """(where, kind, text) pieces of the notebooks: each markdown cell, and each
    notebook's code cells as one program (a name imported in one cell is used in later
    ones), IPython magics and shell lines left out."""
    out = []
    for path in NOTEBOOKS:
        code = []
        for i, cell in enumerate(json.loads(path.read_text())["cells"]):
            src = cell["source"]
            src = "".join(src) if isinstance(src, list) else src
            if cell["cell_type"] == "code":
                lines = src.splitlines()
                code += ["" if ln.lstrip().startswith(("%", "!")) else ln for ln in lines]
            else:
                out.append((f"notebooks/{path.name} cell {i}", "text", src))
        out.append((f"notebooks/{path.name} (code)", "code", "\n".join(code)))
    return out


def _named(sources: list[tuple[str, str, str]]) -> dict[str, list[str]]:
    """Each dotted brdffit name, with where it is named."""
    named: dict[str, list[str]] = {}
    for where, kind, src in sources:
        if kind == "code":
            names = _code_names(ast.parse(src, filename=where))
        else:
            names = set(DOTTED.findall(src))
        for n in names:
            named.setdefault(n, []).append(where)
    return named


def _missing(named: dict[str, list[str]]) -> list[str]:
    return [f"{n} (named in {', '.join(sorted(set(w)))})" for n, w in sorted(named.items())]


@pytest.mark.parametrize("package", PUBLIC_PACKAGES)
def test_all_names_resolve(package):
    mod = importlib.import_module(package)
    names = getattr(mod, "__all__", None)
    if package == "brdffit":
        assert names, "brdffit has no __all__"
    names = list(names or ())
    dup = sorted({n for n in names if names.count(n) > 1})
    assert not dup, f"{package}.__all__ lists twice: {dup}"
    missing = [n for n in names if not hasattr(mod, n)]
    assert not missing, f"{package}.__all__ names what {package} lacks: {missing}"


def test_readme_names_resolve():
    named = _named(_readme_sources())
    assert "brdffit.fit" in named, "the README's names were not found (parser broken?)"
    missing = _missing({n: w for n, w in named.items() if not _resolve(n)})
    assert not missing, "README.md names what brdffit lacks:\n  " + "\n  ".join(missing)


def test_notebook_names_resolve():
    assert NOTEBOOKS, "no notebooks found"
    named = _named(_notebook_sources())
    assert "brdffit.fit" in named, "the notebooks' names were not found (parser broken?)"
    missing = _missing({n: w for n, w in named.items() if not _resolve(n)})
    assert not missing, "the notebooks name what brdffit lacks:\n  " + "\n  ".join(missing)


def _public(dotted: str) -> bool:
    """Whether ``dotted`` is a public name: ``package.name`` with ``name`` in the
    ``__all__`` of one of :data:`PUBLIC_PACKAGES` (or that package itself), followed by
    attributes of it (``brdffit.models.get``, ``brdffit.Posterior.samples``)."""
    for package in PUBLIC_PACKAGES:
        if dotted == package:
            return True
        if dotted.startswith(package + "."):
            head = dotted[len(package) + 1 :].split(".")[0]
            if head in getattr(importlib.import_module(package), "__all__", ()):
                return True
    return False


def test_notebooks_use_public_names_only():
    """What a notebook imports or calls from brdffit is in a public package's ``__all__``:
    a user copies notebook code, so it must not lean on internal modules."""
    named = {n: w for n, w in _named(_notebook_sources()).items() if n.startswith("brdffit")}
    inner = _missing({n: w for n, w in named.items() if not _public(n)})
    assert not inner, "the notebooks use internal names:\n  " + "\n  ".join(inner)


def test_console_scripts_resolve_to_callables():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert "brdffit" in scripts
    for command, target in scripts.items():
        module, _, attr = target.partition(":")
        obj = importlib.import_module(module)
        for part in attr.split("."):
            assert hasattr(obj, part), f"[project.scripts] {command} = {target!r}: no {part}"
            obj = getattr(obj, part)
        assert callable(obj), f"[project.scripts] {command} = {target!r} is not callable"


def test_parser_finds_names():
    """The name finder itself: aliases, dotted chains, and text."""
    code = (
        "import brdffit\nfrom brdffit import models\nfrom brdffit.io import merl as m\n"
        "brdffit.fit(models.get('x'))\nm.read_merl\n"
    )
    got = _code_names(ast.parse(code))
    assert {"brdffit.fit", "brdffit.models.get", "brdffit.io.merl.read_merl"} <= got
    assert DOTTED.findall("see `brdffit.io.nbrdf.read_nbrdf`, and brdffit.fit.") == [
        "brdffit.io.nbrdf.read_nbrdf",
        "brdffit.fit",
    ]
    assert _resolve("brdffit.fit") and not _resolve("brdffit.no_such_name")
    assert not _resolve("brdffit.no_such_module.x")


def test_readme_names_readers_that_return_measurements():
    """Each row of the README's Input-files table names readers returning Measurements."""
    text = README.read_text()
    table = text.split("## Input files", 1)[1].split("\n\n", 2)[1]
    rows = [r for r in table.splitlines() if r.startswith("|") and "---" not in r][1:]
    assert rows
    for row in rows:
        names = re.findall(r"`([\w.]+)`", row.split("|")[2])
        assert names, row
        for name in names:
            mod, _, attr = name.rpartition(".")
            f = getattr(importlib.import_module(mod) if mod else brdffit, attr)
            ret = inspect.signature(f).return_annotation
            assert ret in ("Measurements", brdffit.Measurements), (name, ret)


def test_errors_are_brdffit_errors():
    assert issubclass(MissingDependencyError, BrdffitError)
