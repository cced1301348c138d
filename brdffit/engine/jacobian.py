"""Jacobians of the residuals by column compression (Curtis, Powell & Reid 1974).

The residuals are sample-major, ``(N, 3).ravel()``: row ``3 i + c`` is channel ``c`` of
sample ``i``. In most models a colour parameter acts on its own channel only: ``kd[g]``
changes green and nothing else
(:attr:`brdffit.core.abstract_model.AbstractModel.channel_separable`). Then the three
columns ``kd[r]``, ``kd[g]``, ``kd[b]`` have disjoint rows, and Curtis, Powell and
Reid's observation applies: columns with disjoint rows can share one directional
derivative. One forward-mode pass along ``e_kd[r] + e_kd[g] + e_kd[b]`` gives all three
(each row holds one of them, the others being zero there). So the Jacobian costs one
tangent per *parameter*, not per scalar: 4 instead of 10 for walter (kd, ks, f0 RGB and
a scalar alpha). Walter's linearisation at 303,470 samples took 0.20-0.27 s instead of
0.41-0.61 s (this project's 2-core box, with other work running beside it).

:class:`Colouring` says which columns share a tangent (their *colour*) and on which
channel each acts. The compressed Jacobian ``B`` is ``(N, 3, colours)``: ``B[i, c, p]``
is the derivative of row ``3 i + c`` along colour ``p``'s tangent, and
``J[3 i + c, j] = B[i, c, colour(j)]`` where column ``j`` acts on channel ``c`` (or on
every channel), else 0. Nothing needs ``J`` itself: the Gauss-Newton matrix
``J^T W J`` is the sum over channels of ``B_c^T W_c B_c`` (``colours x colours``, 16
products for walter's 4 colours, against 100 for its 10 scalars), spread over the
columns by :class:`Colouring`.

A model that mixes channels (a tint divided by the luminance of the base colour) gets
one colour per column and every column on every channel: the plain forward-mode
Jacobian, by the same code.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from brdffit.core.parameters import Parameter

CHANNELS = 3
"""Residuals per sample (R, G, B)."""


@dataclass(frozen=True)
class Colouring:
    """Which columns of the Jacobian share a tangent.

    Fields: ``colour`` per column, the index of its tangent; ``channel`` per column, the
    channel it acts on, or -1 for every channel.
    """

    colour: tuple[int, ...]
    channel: tuple[int, ...]

    @classmethod
    def of(cls, free: tuple[Parameter, ...], separable: bool) -> Colouring:
        """The colouring of the flat vector of ``free`` (a layout's free parameters):
        one colour per parameter when the model is ``separable`` by channel, else one
        per scalar."""
        colour, channel, n = [], [], 0
        for p in free:
            per_channel = separable and p.shape == (CHANNELS,)
            for c in range(p.size):
                if not (per_channel and c):  # a new tangent, unless channels share it
                    n += 1
                colour.append(n - 1)
                channel.append(c if per_channel else -1)
        return cls(tuple(colour), tuple(channel))

    @property
    def size(self) -> int:
        """Number of tangents (colours)."""
        return len(set(self.colour))

    def seeds(self, dtype) -> np.ndarray:
        """``(colours, k)``: the tangent of each colour, the sum of its columns' unit vectors."""
        out = np.zeros((self.size, len(self.colour)), dtype)
        out[np.asarray(self.colour, int), np.arange(len(self.colour))] = 1.0
        return out

    def mask(self, dtype) -> np.ndarray:
        """``(3, k)``: 1 where column ``j`` acts on channel ``c`` (row ``c``, column ``j``)."""
        channel = np.asarray(self.channel, int)
        rows = np.arange(CHANNELS)[:, None]
        return ((channel[None, :] == -1) | (channel[None, :] == rows)).astype(dtype)

    def spread_vector(self, per_channel: Float[Array, "... 3 p"]) -> Float[Array, "... k"]:
        """``J^T v`` from its per-channel, per-colour sums ``B_c^T v_c``: each column takes
        its colour's sum on the channels it acts on."""
        m = self.mask(per_channel.dtype)
        return jnp.einsum("cj,...cj->...j", m, per_channel[..., np.asarray(self.colour, int)])

    def spread_matrix(self, per_channel: Float[Array, "... 3 p p"]) -> Float[Array, "... k k"]:
        """``J^T W J`` from its per-channel Gram matrices over colours ``B_c^T W_c B_c``:
        entry ``(j, l)`` sums colour pair ``(colour(j), colour(l))`` over the channels
        both columns act on."""
        colour = np.asarray(self.colour, int)
        m = self.mask(per_channel.dtype)
        full = per_channel[..., colour, :][..., colour]
        return jnp.einsum("cj,cl,...cjl->...jl", m, m, full)

    def dense(self, b: Float[Array, "n 3 p"]) -> Float[Array, "m k"]:
        """The Jacobian ``J`` ``(3 N, k)`` from its compressed form ``b``."""
        full = b[:, :, np.asarray(self.colour, int)] * self.mask(b.dtype)[None]
        return full.reshape(-1, len(self.colour))


def compressed(
    f: Callable[[Array], tuple[Array, Any]], x: Array, colouring: Colouring
) -> tuple[Array, Any, Float[Array, "n 3 p"]]:
    """``(y, aux, B)``: ``f(x) = (y, aux)`` with ``y`` the residuals (length ``3 N``) and
    ``B`` their compressed Jacobian (module docstring), one forward-mode pass per colour."""
    if not colouring.size:  # every parameter frozen
        y, aux = f(x)
        return y, aux, jnp.zeros((y.size // CHANNELS, CHANNELS, 0), y.dtype)
    seeds = jnp.asarray(colouring.seeds(x.dtype))

    def along(t: Array) -> tuple[Array, Any, Array]:
        (y, aux), (dy, _) = jax.jvp(f, (x,), (t,))
        return y, aux, dy

    y, aux, dy = jax.vmap(along, out_axes=(None, None, -1))(seeds)
    return y, aux, dy.reshape(-1, CHANNELS, colouring.size)


def channel_grams(a: Float[Array, "n 3 p"], b: Float[Array, "n 3 q"]) -> Float[Array, "3 p q"]:
    """Per channel ``c``, ``a_c^T b_c`` over the samples.

    One matrix product of the ``(N, 3 p)`` and ``(N, 3 q)`` views, whose diagonal blocks
    are the channels' products (the off-diagonal ones, across channels, are dropped):
    three times the multiplications of a product per channel, but a plain GEMM over
    contiguous rows. The normal equations of :func:`normal` (Gram matrix and gradient)
    at 909,696 samples and ``p = 4`` took 0.063 s this way on this project's CPU, against
    0.150 s with the batched contraction over channels, whose operands XLA transposes
    first."""
    n, c, p = a.shape
    q = b.shape[2]
    full = a.reshape(n, c * p).T @ b.reshape(n, c * q)
    return jnp.stack([full[i * p : (i + 1) * p, i * q : (i + 1) * q] for i in range(c)])


def normal(
    b: Float[Array, "n 3 p"], w: Float[Array, " m"], r: Float[Array, " m"], colouring: Colouring
) -> tuple[Float[Array, " k"], Float[Array, "k k"]]:
    """``(J^T W r, J^T W J)`` from the compressed ``b``, weights ``w`` and residuals ``r``."""
    wb = b * w.reshape(-1, CHANNELS)[:, :, None]
    gram = channel_grams(wb, b)
    grad = channel_grams(wb, r.reshape(-1, CHANNELS, 1))[:, :, 0]
    return colouring.spread_vector(grad), colouring.spread_matrix(gram)
