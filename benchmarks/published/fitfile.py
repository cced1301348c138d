"""Read bsdfbenchmark (bbm) ``.fit`` files: the published MERL fits, one line per material.

A line reads ``material = Aggregate(Lambertian(albedo = [r, g, b]), NganWard(albedo = [...],
roughness = 0.0162))``: the right-hand side is the bbm constructor expression that
builds the BSDF (bbm's string importer reads it as it stands, so it is kept verbatim for
the C++ scorer), and its components are parsed here into class names and parameter
values for the mapping onto brdffit's models. The expression is Python syntax (calls
with keyword arguments, nested lists), so :mod:`ast` parses it; nothing is evaluated.

The files in ``benchmarks/published/fits/`` are bbm's ``fits/`` at commit 9807fb3
(https://github.com/bsdfbenchmark/bbm), BSD licence in ``fits/LICENSE``: Ngan et al. 2005
(7 models, 86 materials), Löw et al. 2012 (6 fit sets, 100 materials) and Bagher et al.
2012 (SGD, 100 materials).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

FITS = Path(__file__).parent / "fits"


@dataclass(frozen=True)
class Component:
    """One bbm model of a published fit: its class name and its parameters (floats or
    nested lists of floats, as printed)."""

    cls: str
    params: dict[str, object]


@dataclass(frozen=True)
class PublishedFit:
    """A published fit of one material: the bbm expression and its components in order."""

    material: str
    expression: str
    components: tuple[Component, ...]

    def component(self, cls: str) -> Component:
        """The component of class ``cls``; KeyError naming the classes present otherwise."""
        for c in self.components:
            if c.cls == cls:
                return c
        raise KeyError(f"{self.material}: no {cls} in {[c.cls for c in self.components]}")


def _value(node: ast.expr) -> object:
    """A literal number or (nested) list of numbers, with unary minus."""
    if isinstance(node, ast.Constant) and isinstance(node.value, int | float):
        return float(node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        v = _value(node.operand)
        return -v if isinstance(node.op, ast.USub) else v
    if isinstance(node, ast.List | ast.Tuple):
        return [_value(e) for e in node.elts]
    raise ValueError(f"not a number or list of numbers: {ast.unparse(node)}")


def _components(node: ast.expr) -> list[Component]:
    """Flatten ``Aggregate(a, b, ...)`` into its components; a call is one component."""
    if not isinstance(node, ast.Call) or not isinstance(node.func, ast.Name):
        raise ValueError(f"not a bbm constructor call: {ast.unparse(node)}")
    name = node.func.id
    if name == "Aggregate":
        return [c for arg in node.args for c in _components(arg)]
    if node.args:
        raise ValueError(f"{name}: positional arguments are not expected")
    return [Component(name, {k.arg: _value(k.value) for k in node.keywords})]


def parse_line(line: str) -> PublishedFit:
    """The fit on one ``material = expression`` line."""
    material, sep, expression = line.partition("=")
    if not sep:
        raise ValueError(f"no '=' in {line!r}")
    expression = expression.strip()
    tree = ast.parse(expression, mode="eval")
    return PublishedFit(material.strip(), expression, tuple(_components(tree.body)))


def read_fit_file(name: str | Path) -> dict[str, PublishedFit]:
    """Material name -> published fit for every line of the file (``#`` lines skipped).

    ``name`` is a path or a file name in :data:`FITS` (``"ngan_ward.fit"``). Raises
    ValueError naming the file and line on a line that does not parse.
    """
    path = Path(name) if Path(name).exists() else FITS / str(name)
    fits: dict[str, PublishedFit] = {}
    for number, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            fit = parse_line(line)
        except (ValueError, SyntaxError) as err:
            raise ValueError(f"{path}:{number}: {err}") from None
        fits[fit.material] = fit
    return fits
