"""Restrictions of any model: RGB parameters made grey, parameters pinned at a neutral value.

``Restricted(base, grey, neutral)`` is ``base`` on a subspace of its parameters:

* each RGB parameter in ``grey`` is replaced by a scalar of the same bounds, default,
  transform and affine flag, broadcast to the three channels;
* each parameter in ``neutral`` leaves the table and takes its
  :attr:`~brdffit.core.parameters.Parameter.neutral` value, the value at which it adds
  nothing to a simpler published form of the model (Disney's ``specular`` at 0.5, the
  common dielectric; the Student-t ``gamma`` at 2, which is GGX).

    f_restricted(wi, wo; ..., x, ...) = f_base(wi, wo; ..., (x, x, x), ..., neutral values)

so ``walter`` with grey ``ks`` and ``f0`` has an achromatic specular lobe (a dielectric
coating) and 5 fewer free scalars, and ``disney`` with a neutral ``specular`` has the
4% dielectric reflectance of the paper's default. The values of ``base`` stay exact:
nothing is approximated, the base is only evaluated on a subspace.

The spec language writes them as the options ``grey`` and ``neutral``: the names joined
by ``+`` in the base's table order, after the base's own options:
``walter[grey=ks+f0]``, ``walter[diffuse=false,grey=f0]``, ``disney[neutral=specular]``.
:func:`brdffit.models.get` reads the options, :func:`brdffit.models.label` writes them,
so ``from_spec(label(m))`` rebuilds ``m`` and ``brdffit fit``, ``rank`` and ``sweep``
accept the spec. A :class:`~brdffit.FitResult` stores them among its options
(``{"diffuse": False, "grey": "ks+f0"}``) under the base's name.

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

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.geometry import ShadingGeometry
from brdffit.core.parameters import Parameter, Params
from brdffit.errors import ParameterError

GREY = "grey"
"""The spec option naming the grey parameters (``name[grey=a+b]``)."""
NEUTRAL = "neutral"
"""The spec option naming the parameters pinned at their neutral value (``name[neutral=a]``)."""
OPTIONS = (GREY, NEUTRAL)


@final
class Restricted(AbstractModel):
    """``base`` with the RGB parameters ``grey`` tied across channels and the parameters
    ``neutral`` pinned at their neutral values (module docstring).

    Fields: ``base`` the model (never itself restricted); ``grey`` and ``neutral``, names
    in ``base``'s table order, disjoint. Build with :func:`make_grey` and
    :func:`make_neutral`.
    """

    base: AbstractModel
    grey: tuple[str, ...] = eqx.field(static=True, default=())
    neutral: tuple[str, ...] = eqx.field(static=True, default=())

    @property
    def name(self) -> str:  # type: ignore[override]
        """The base model's registry name: a restriction is an option, not a model."""
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
    def parameters(self) -> tuple[Parameter, ...]:
        return tuple(
            dataclasses.replace(p, shape=(), doc=f"{p.doc.replace(', RGB', '')}, grey (R = G = B)")
            if p.name in self.grey
            else p
            for p in self.base.parameters
            if p.name not in self.neutral
        )

    def expand(self, params: Params) -> Params:
        """The base model's parameters: each grey scalar broadcast to RGB, each neutral
        parameter at its neutral value."""
        out = {k: jnp.broadcast_to(v, (3,)) if k in self.grey else v for k, v in params.items()}
        for p in self.base.parameters:
            if p.name in self.neutral:
                out[p.name] = jnp.broadcast_to(p.neutral, p.shape)  # weak: takes its dtype
        return out

    def core(self, params: Params, g: ShadingGeometry) -> Float[Array, "n 3"]:
        return self.base.core(self.expand(params), g)

    def evaluate(self, params: Params, g: ShadingGeometry) -> Float[Array, "n 3"]:
        return self.base.evaluate(self.expand(params), g)

    def options(self) -> dict[str, object]:
        """The base model's options plus ``grey`` and ``neutral`` (spec text, JSON-safe)."""
        return {**self.base.options(), **restriction_options(self)}


def restriction_options(model: AbstractModel) -> dict[str, str]:
    """The ``grey`` and ``neutral`` options of ``model`` as the spec writes them (names
    joined by ``+``; an option with no names is left out; ``{}`` for a plain model)."""
    if not isinstance(model, Restricted):
        return {}
    out = {GREY: "+".join(model.grey), NEUTRAL: "+".join(model.neutral)}
    return {k: v for k, v in out.items() if v}


def base_of(model: AbstractModel) -> AbstractModel:
    """The unrestricted model: ``model.base`` for a :class:`Restricted`, else ``model``."""
    return model.base if isinstance(model, Restricted) else model


def option_names(option: str, value: object) -> list[str]:
    """The names of a ``grey`` or ``neutral`` option: ``"ks+f0"`` or a sequence of names."""
    if isinstance(value, str):
        return [n.strip() for n in value.split("+") if n.strip()]
    if isinstance(value, Iterable):
        return [str(n) for n in value]
    raise ParameterError(f"option {option}={value!r}: give parameter names joined by '+'")


def _build(base: AbstractModel, grey: set[str], neutral: set[str]) -> AbstractModel:
    grey = grey - neutral  # a pinned parameter has no channels left to tie
    if not grey and not neutral:
        return base
    order = [p.name for p in base.parameters]
    return Restricted(base, tuple(n for n in order if n in grey),
                      tuple(n for n in order if n in neutral))  # fmt: skip


def make_grey(model: AbstractModel, names: object) -> AbstractModel:
    """``model`` with the RGB parameters ``names`` grey (added to those already grey).

    ``names`` is ``"ks+f0"`` or a sequence of names; none returns ``model`` unchanged
    (a restriction with nothing restricted is its base). Raises
    :class:`~brdffit.errors.ParameterError` naming a parameter the model lacks, one that
    is not RGB or one already pinned at its neutral value, and listing the RGB
    parameters it has.
    """
    base = base_of(model)
    grey, neutral = _names(model)
    wanted = set(option_names(GREY, names))
    rgb = [p.name for p in base.parameters if p.shape == (3,)]
    bad = sorted((wanted - set(rgb)) | (wanted & neutral))
    if bad:
        raise ParameterError(
            f"model {base.name!r}: grey={'+'.join(bad)} names no free RGB parameter; "
            f"its RGB parameters: {'+'.join(n for n in rgb if n not in neutral) or 'none'}"
        )
    return _build(base, grey | wanted, neutral)


def make_neutral(model: AbstractModel, names: object) -> AbstractModel:
    """``model`` with the parameters ``names`` pinned at their neutral values (added to
    those already pinned; a grey parameter pinned stops being grey).

    ``names`` is ``"specular+sheen_tint"`` or a sequence of names; none returns ``model``
    unchanged. Raises :class:`~brdffit.errors.ParameterError` naming a parameter the
    model lacks or one without a neutral value, and listing those that have one.
    """
    base = base_of(model)
    grey, neutral = _names(model)
    wanted = set(option_names(NEUTRAL, names))
    has = [p.name for p in base.parameters if p.neutral is not None]
    bad = sorted(wanted - set(has))
    if bad:
        raise ParameterError(
            f"model {base.name!r}: neutral={'+'.join(bad)} names no parameter with a "
            f"neutral value; those with one: {'+'.join(has) or 'none'}"
        )
    return _build(base, grey, neutral | wanted)


def restrict(model: AbstractModel, grey: object = (), neutral: object = ()) -> AbstractModel:
    """``model`` with the ``neutral`` parameters pinned, then the ``grey`` ones tied
    (:func:`make_neutral`, :func:`make_grey`: the same errors)."""
    return make_grey(make_neutral(model, neutral), grey)


def restrictions(model: AbstractModel) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The grey and the neutral parameter names of ``model`` (empty for a plain model)."""
    return (model.grey, model.neutral) if isinstance(model, Restricted) else ((), ())


def _names(model: AbstractModel) -> tuple[set[str], set[str]]:
    grey, neutral = restrictions(model)
    return set(grey), set(neutral)
