"""The model contract every file in ``brdffit/models/`` follows.

A model is a frozen equinox Module whose fields are its *static options* (lobe
count, Fresnel variant, optional lobes): chosen when the model is built, so a
feature that is off has no parameter and no operation in the compiled function.
Its parameter table is :attr:`AbstractModel.parameters`, which may depend on the
options. The physics lives in :meth:`AbstractModel.core`, which takes the natural
parameter dict and a :class:`~brdffit.core.geometry.ShadingGeometry` computed once per
data set; :meth:`AbstractModel.eval` derives the geometry from directions.

Values are linear RGB BRDF in 1/sr, without the cosine factor, zero below the
horizon, shape (N, 3).
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Mapping
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from brdffit.core.geometry import ShadingGeometry, shading_geometry
from brdffit.core.parameters import Parameter, Params
from brdffit.errors import ParameterError


class AbstractModel(eqx.Module):
    """Interface of an analytic BRDF model; concrete models are final classes.

    Class attributes each model sets: ``name`` (registry key), ``reference`` (the
    paper), ``reciprocal`` (f(wi, wo) == f(wo, wi)), ``energy_conserving`` (directional
    albedo <= 1 for every valid parameter value), ``channel_separable`` (below).
    ``isotropic`` follows an ``anisotropic`` option where the model has one.
    """

    name: ClassVar[str]
    reference: ClassVar[str]
    reciprocal: ClassVar[bool] = True
    energy_conserving: ClassVar[bool] = True
    channel_separable: ClassVar[bool] = False
    """True when channel ``c`` of the value depends on an RGB parameter through its
    element ``c`` alone (an albedo, an F0), on no other channel's: the solver then
    computes the Jacobian with one forward pass per parameter, not per scalar
    (:mod:`brdffit.engine.jacobian`). False (every column its own pass) is always correct;
    a model that mixes channels (a tint divided by a luminance, a maximum over channels)
    must leave it False for the options that mix them (a property then). Checked for
    every row of the test cases, both ways."""

    @property
    def isotropic(self) -> bool:
        """False when the model was built with its ``anisotropic`` option on."""
        return not getattr(self, "anisotropic", False)

    @property
    @abc.abstractmethod
    def parameters(self) -> tuple[Parameter, ...]:
        """The parameter table for the chosen options."""

    @abc.abstractmethod
    def core(self, params: Params, g: ShadingGeometry) -> Float[Array, "n 3"]:
        """BRDF values (N, 3) in 1/sr for samples above the horizon.

        Arguments:
        - ``params``: natural parameter dict, every name of :attr:`parameters`.
        - ``g``: shading geometry; below-horizon samples hold safe placeholders.
        """

    def evaluate(self, params: Params, g: ShadingGeometry) -> Float[Array, "n 3"]:
        """:meth:`core` with samples below the horizon set to zero (``params`` may hold
        NumPy arrays, as the host's bookkeeping makes them)."""
        f = self.core({k: jnp.asarray(v) for k, v in params.items()}, g)
        f = jnp.broadcast_to(f, g.cos_i.shape + (3,))
        return jnp.where(g.above[:, None], f, jnp.zeros((), f.dtype))

    def eval(
        self, params: Mapping[str, object], wi: Float[ArrayLike, "n 3"], wo: Float[ArrayLike, "n 3"]
    ) -> Float[Array, "n 3"]:
        """BRDF f(wi, wo) in 1/sr, (N, 3), at unit directions in the shading frame.

        ``params`` maps every parameter name to an array of its shape (natural units).
        Jittable and differentiable; the dtype follows ``wi``.
        """
        wi = jnp.asarray(wi)
        dtype = wi.dtype if jnp.issubdtype(wi.dtype, jnp.floating) else jnp.float64
        g = shading_geometry(wi.astype(dtype), jnp.asarray(wo, dtype))
        return self.evaluate(self.cast(params, dtype), g)

    def defaults(self) -> Params:
        """Default natural values, name -> array of the parameter's shape."""
        return {p.name: p.default_array() for p in self.parameters}

    def parameter(self, name: str) -> Parameter:
        """The table row called ``name``; :class:`ParameterError` if there is none."""
        for p in self.parameters:
            if p.name == name:
                return p
        raise ParameterError(
            f"model {self.name!r} has no parameter {name!r}; it has "
            f"{[p.name for p in self.parameters]}"
        )

    def cast(self, params: Mapping[str, object], dtype: jnp.dtype) -> Params:
        """Check names and shapes, fill nothing in, cast every value to ``dtype``."""
        names = [p.name for p in self.parameters]
        missing = [n for n in names if n not in params]
        extra = [n for n in params if n not in names]
        if missing or extra:
            raise ParameterError(
                f"model {self.name!r}: parameters missing {missing}, unknown {extra}; "
                f"expected {names}"
            )
        out = {}
        for p in self.parameters:
            v = jnp.asarray(params[p.name], dtype)
            if v.shape != p.shape:
                raise ParameterError(
                    f"model {self.name!r}: parameter {p.name!r} has shape {v.shape}, "
                    f"expected {p.shape}"
                )
            out[p.name] = v
        return out

    def options(self) -> dict[str, object]:
        """The static options this model was built with."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def describe(self) -> str:
        """Name, options and parameter table as text (``brdffit models``)."""
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options().items()) or "none"
        lines = [f"{self.name}  ({self.reference})", f"  options: {opts}"]
        for p in self.parameters:
            shape = "rgb" if p.shape == (3,) else "scalar"
            neutral = "" if p.neutral is None else f"; neutral {p.neutral:.3g}"
            lines.append(
                f"  {p.name:<14} {shape:<6} [{p.bounds[0]:.3g}, {p.bounds[1]:.3g}] "
                f"default {p.default:<8.3g} {p.transform:<8} {p.doc}{neutral}"
            )
        return "\n".join(lines)


@eqx.filter_jit
def eval_compiled(
    model: AbstractModel, params: Mapping[str, object], wi: ArrayLike, wo: ArrayLike
) -> Float[Array, "n 3"]:
    """``model.eval(params, wi, wo)`` compiled once per model (its options), dtype and
    direction count, then reused for every parameter value; f in 1/sr, (N, 3).

    Eagerly, every operation of the model compiles on its own the first time it meets a
    shape (about 30 small programs for walter, together about 1 s on a CPU), and the
    runtime type checks of every term, where they are on, cost more than the evaluation.
    """
    return model.eval(params, wi, wo)


def linear_split(
    model: AbstractModel, params: Params, g: ShadingGeometry, names: tuple[str, ...]
) -> tuple[jax.Array, jax.Array]:
    """Affine decomposition ``f = f0 + sum_k x_k b_k`` in the ``linear`` parameters ``names``.

    Returns ``f0`` (N, 3), the value with those parameters at zero, and ``basis``
    (N, 3, K), the exact derivative of ``f`` with respect to each of their K scalars.
    Exact because the model is affine in them (``Parameter.linear``).
    """
    zero = {k: jnp.zeros_like(v) if k in names else v for k, v in params.items()}
    flat0 = jnp.concatenate([jnp.ravel(zero[n]) for n in names])

    def f_of(flat: jax.Array) -> jax.Array:
        p, i = dict(zero), 0
        for n in names:
            p[n] = flat[i : i + zero[n].size].reshape(zero[n].shape)
            i += zero[n].size
        return model.evaluate(p, g)

    f0, basis = jax.jvp(f_of, (flat0,), (jnp.zeros_like(flat0),))[0], jax.jacfwd(f_of)(flat0)
    return f0, basis
