"""The analytic BRDF models, one file each; every file's model class is registered.

``available()`` lists the registry names, ``get(name, **options)`` builds a model with
its static options. Adding a model means adding one file that defines a final
subclass of :class:`~brdffit.abstract_model.AbstractModel` with a ``name``.
"""

from __future__ import annotations

import dataclasses
import importlib
import pkgutil

from brdffit.abstract_model import AbstractModel
from brdffit.errors import ParameterError


def _registry() -> dict[str, type[AbstractModel]]:
    found: dict[str, type[AbstractModel]] = {}
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        for obj in vars(module).values():
            if (
                isinstance(obj, type)
                and issubclass(obj, AbstractModel)
                and obj.__module__ == module.__name__
                and "name" in vars(obj)
            ):
                found[obj.name] = obj
    return dict(sorted(found.items()))


_REGISTRY = _registry()


def available() -> list[str]:
    """Registry names of every model, sorted."""
    return list(_REGISTRY)


def get(name: str, **options: object) -> AbstractModel:
    """Build the model ``name`` with static ``options`` (see each model's fields).

    Raises :class:`~brdffit.errors.ParameterError` naming the unknown model or option
    and listing what is accepted.
    """
    if name not in _REGISTRY:
        raise ParameterError(f"unknown model {name!r}; available: {', '.join(_REGISTRY)}")
    cls = _REGISTRY[name]
    accepted = [f.name for f in dataclasses.fields(cls)]
    bad = sorted(set(options) - set(accepted))
    if bad:
        raise ParameterError(
            f"model {name!r} has no option(s) {bad}; options: {accepted or 'none'}"
        )
    try:
        return cls(**options)
    except (TypeError, ValueError) as err:
        raise ParameterError(f"model {name!r}: {err}") from None


__all__ = ["available", "get"]
