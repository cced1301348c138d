"""The model registry: every model file's class by name, and model specs as text.

See :mod:`brdffit.models` for what a spec is.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import pkgutil
import re
from collections.abc import Mapping
from pathlib import Path

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.result import FitResult
from brdffit.errors import ParameterError
from brdffit.models import _restrict


@functools.cache
def _registry() -> dict[str, type[AbstractModel]]:
    """Every model class by name, from the files beside this one (imported on first use,
    so that a model file may import this package's helpers while it loads)."""
    found: dict[str, type[AbstractModel]] = {}
    for info in pkgutil.iter_modules([str(Path(__file__).parent)]):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__package__}.{info.name}")
        for obj in vars(module).values():
            if (
                isinstance(obj, type)
                and issubclass(obj, AbstractModel)
                and obj.__module__ == module.__name__
                and "name" in vars(obj)
            ):
                found[obj.name] = obj
    return dict(sorted(found.items()))


def available() -> list[str]:
    """Registry names of every model, sorted."""
    return list(_registry())


def get(name: str, **options: object) -> AbstractModel:
    """Build the model ``name`` with static ``options`` (see each model's fields).

    ``grey`` (names joined by ``+``, or a sequence) ties those RGB parameters across
    channels, ``neutral`` pins those parameters at their neutral values
    (:func:`brdffit.models._restrict.restrict`). Raises
    :class:`~brdffit.errors.ParameterError` naming the unknown model or option and
    listing what is accepted.
    """
    if name not in _registry():
        raise ParameterError(f"unknown model {name!r}; available: {', '.join(_registry())}")
    if any(k in options for k in _restrict.OPTIONS):
        grey, neutral = (options.pop(k, ()) for k in _restrict.OPTIONS)
        return _restrict.restrict(get(name, **options), grey=grey, neutral=neutral)
    cls = _registry()[name]
    accepted = [f.name for f in dataclasses.fields(cls)] + list(_restrict.OPTIONS)
    bad = sorted(set(options) - set(accepted))
    if bad:
        raise ParameterError(
            f"model {name!r} has no option(s) {bad}; options: {accepted or 'none'}"
        )
    try:
        return cls(**options)
    except (TypeError, ValueError) as err:
        raise ParameterError(f"model {name!r}: {err}") from None


_VALUE = re.compile(r"[A-Za-z0-9_.+-]+")


def _value(key: str, text: str) -> object:
    """``true``/``false`` -> bool, then int, then float, else the word itself."""
    if not _VALUE.fullmatch(text):
        raise ParameterError(
            f"option {key} has value {text!r}; use true/false, a number or a word of "
            "letters, digits and _.+-"
        )
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return text


def _typed(cls: type[AbstractModel], key: str, value: object) -> object:
    """``value`` checked against the type of the option's default (an int is a float)."""
    default = {f.name: f.default for f in dataclasses.fields(cls)}.get(key, dataclasses.MISSING)
    if default is dataclasses.MISSING:  # unknown option (get says so) or no default
        return value
    kind = type(default)
    if kind is float and type(value) is int:
        return float(value)
    if type(value) is not kind:
        raise ParameterError(
            f"option {key}={value!r} is not of type {kind.__name__} (default {default!r})"
        )
    return value


def parse_spec(text: str) -> tuple[str, dict[str, object]]:
    """The model name and options of a spec ``name`` or ``name[k=v,...]`` (module docstring).

    The model is built once to check the options, so every error shows here: raises
    :class:`~brdffit.errors.ParameterError` naming the spec and the unknown model or
    option, the bad value or the unbalanced bracket.
    """
    spec = text.strip()
    try:
        opens, closes = spec.count("["), spec.count("]")
        if (opens, closes) not in ((0, 0), (1, 1)) or (opens and not spec.endswith("]")):
            raise ParameterError("unbalanced brackets or text after ']'; write name[k=v,...]")
        name, _, inner = spec[:-1].partition("[") if opens else (spec, "", "")
        name = name.strip()
        if name not in _registry():
            get(name)  # raises, listing the registry
        options: dict[str, object] = {}
        for item in inner.split(",") if opens else ():
            key, eq, value = (part.strip() for part in item.partition("="))
            if not eq or not key:
                raise ParameterError(f"{item.strip()!r} is not k=v; write name[k=v,...]")
            if key in options:
                raise ParameterError(f"option {key} given twice")
            options[key] = _typed(_registry()[name], key, _value(key, value))
        get(name, **options)
    except ParameterError as err:
        raise ParameterError(f"model spec {text!r}: {err}") from None
    return name, options


def from_spec(text: str) -> AbstractModel:
    """The model a spec names, built with its options (:func:`parse_spec`, same errors)."""
    name, options = parse_spec(text)
    return get(name, **options)


def split_specs(text: str) -> list[str]:
    """A comma-separated list of specs, split at the commas outside brackets; blanks dropped.

    Raises :class:`~brdffit.errors.ParameterError` on unbalanced brackets.
    """
    out, depth, start = [], 0, 0
    for i, ch in enumerate(text + ","):
        depth += {"[": 1, "]": -1}.get(ch, 0)
        if depth < 0 or depth > 1:
            raise ParameterError(f"model list {text!r}: unbalanced brackets at column {i + 1}")
        if ch == "," and depth == 0:
            out.append(text[start:i].strip())
            start = i + 1
    if depth:
        raise ParameterError(f"model list {text!r}: unbalanced brackets (a '[' is not closed)")
    return [s for s in out if s]


def _text(value: object) -> str:
    """An option value as :func:`parse_spec` reads it back."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def changed_options(model: AbstractModel) -> dict[str, object]:
    """The static options of ``model`` that differ from its class's defaults, in field order
    (then ``grey`` and ``neutral`` for a restricted variant)."""
    if isinstance(model, _restrict.Restricted):
        return {**changed_options(model.base), **_restrict.restriction_options(model)}
    return {
        f.name: getattr(model, f.name)
        for f in dataclasses.fields(model)
        if f.default is dataclasses.MISSING or getattr(model, f.name) != f.default
    }


def label(model: AbstractModel | str, options: Mapping[str, object] | None = None) -> str:
    """The canonical spec ``name`` or ``name[k=v,...]`` of a model (module docstring).

    ``model`` is a built model, or a registry name with its ``options`` (as a
    :class:`~brdffit.FitResult` stores them; a name no longer registered then shows every
    option given).
    """
    if isinstance(model, str):
        try:
            changed = changed_options(get(model, **(options or {})))
        except ParameterError:
            changed = dict(options or {})
        name = model
    else:
        changed, name = changed_options(model), model.name
    if not changed:
        return name
    return f"{name}[{','.join(f'{k}={_text(v)}' for k, v in changed.items())}]"


def model_of(result: FitResult) -> AbstractModel:
    """The model ``result`` was fitted with, rebuilt from its name and options (grey and
    neutral variants included), for evaluating or exporting the fit."""
    return get(result.model, **dict(result.options))
