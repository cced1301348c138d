"""Grey variants of any model: chosen RGB parameters tied to one value for R, G and B.

``Grey(base, names)`` is ``base`` with each RGB parameter in ``names`` replaced by a
scalar of the same bounds, default, transform and affine flag, broadcast to the three
channels before ``base`` evaluates:

    f_grey(wi, wo; ..., x, ...) = f_base(wi, wo; ..., (x, x, x), ...)

so ``walter`` with grey ``ks`` and ``f0`` has an achromatic specular lobe (a dielectric
coating) and 5 fewer free scalars. The values of ``base`` stay exact: a grey variant
is the base model restricted to equal channels, nothing is approximated.

The spec language writes it as the option ``grey``: the names joined by ``+`` in the
base's table order, after the base's own options: ``walter[grey=ks+f0]``,
``walter[diffuse=false,grey=f0]``. :func:`brdffit.models.get` reads the option,
:func:`brdffit.models.label` writes it, so ``from_spec(label(m))`` rebuilds ``m`` and
``brdffit fit``, ``rank`` and ``sweep`` accept the spec. A :class:`~brdffit.FitResult`
stores it among its options (``{"diffuse": False, "grey": "ks+f0"}``) under the base's
name.

The wrapper lives in a file starting with ``_`` so the registry does not list it as a
model of its own: it is a variant of every model, not a model.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from typing import final

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from brdffit.abstract_model import AbstractModel
from brdffit.errors import ParameterError
from brdffit.geometry import ShadingGeometry
from brdffit.parameters import Parameter, Params

OPTION = "grey"
"""The spec option naming the grey parameters (``name[grey=a+b]``)."""


@final
class Grey(AbstractModel):
    """``base`` with the RGB parameters ``names`` tied across channels (module docstring).

    Fields: ``base`` the model (never itself a :class:`Grey`); ``names`` the grey
    parameters, in ``base``'s table order. Build with :func:`make_grey`.
    """

    base: AbstractModel
    names: tuple[str, ...] = eqx.field(static=True)

    @property
    def name(self) -> str:  # type: ignore[override]
        """The base model's registry name: a grey variant is an option, not a model."""
        return self.base.name

    @property
    def reference(self) -> str:  # type: ignore[override]
        return self.base.reference

    @property
    def reciprocal(self) -> bool:  # type: ignore[override]
        return self.base.reciprocal

    @property
    def energy_conserving(self) -> bool:  # type: ignore[override]
        return self.base.energy_conserving

    @property
    def isotropic(self) -> bool:
        return self.base.isotropic

    @property
    def grey_text(self) -> str:
        """The ``grey`` option's value as the spec writes it: ``ks+f0``."""
        return "+".join(self.names)

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return tuple(
            dataclasses.replace(p, shape=(), doc=f"{p.doc.replace(', RGB', '')}, grey (R = G = B)")
            if p.name in self.names
            else p
            for p in self.base.parameters
        )

    def expand(self, params: Params) -> Params:
        """The base model's parameters: each grey scalar broadcast to RGB."""
        return {k: jnp.broadcast_to(v, (3,)) if k in self.names else v for k, v in params.items()}

    def core(self, params: Params, g: ShadingGeometry) -> Float[Array, "n 3"]:
        return self.base.core(self.expand(params), g)

    def evaluate(self, params: Params, g: ShadingGeometry) -> Float[Array, "n 3"]:
        return self.base.evaluate(self.expand(params), g)

    def options(self) -> dict[str, object]:
        """The base model's options plus ``grey`` (its spec text, JSON-safe)."""
        return {**self.base.options(), OPTION: self.grey_text}


def grey_names(value: object) -> list[str]:
    """The names of a ``grey`` option: ``"ks+f0"`` or a sequence of names."""
    if isinstance(value, str):
        return [n.strip() for n in value.split("+") if n.strip()]
    if isinstance(value, Iterable):
        return [str(n) for n in value]
    raise ParameterError(f"option grey={value!r}: give parameter names joined by '+'")


def make_grey(model: AbstractModel, names: object) -> AbstractModel:
    """``model`` with the RGB parameters ``names`` grey (added to those already grey).

    ``names`` is ``"ks+f0"`` or a sequence of names; none returns ``model`` itself
    (a grey model with nothing grey is its base). Raises
    :class:`~brdffit.errors.ParameterError` naming a parameter the model lacks or one
    that is not RGB, and listing the RGB parameters it has.
    """
    base, old = (model.base, model.names) if isinstance(model, Grey) else (model, ())
    wanted = set(old) | set(grey_names(names))
    rgb = [p.name for p in base.parameters if p.shape == (3,)]
    bad = sorted(wanted - set(rgb))
    if bad:
        raise ParameterError(
            f"model {base.name!r}: grey={'+'.join(bad)} names no RGB parameter; "
            f"its RGB parameters: {'+'.join(rgb) or 'none'}"
        )
    if not wanted:
        return base
    return Grey(base, tuple(n for n in rgb if n in wanted))
