"""Model parameters: the table row, the optimiser transforms and flat packing.

Every parameter has a name, a shape (``()`` scalar or ``(3,)`` RGB), bounds
``(low, high)``, a default and the transform the optimiser works through:

* ``"identity"``: ``x = u`` (bounds are then only the prior's support);
* ``"logit"``: ``x = low + (high - low) sigmoid(u)``, for finite bounds;
* ``"log"``: ``x = exp(u)`` when ``low == 0`` and ``high == inf``; ``low + exp(u)``
  when ``low > 0`` and ``high == inf``; and ``x = low (high/low)^sigmoid(u)`` (a logit
  in log space) when both bounds are finite and positive.

Random starts and MCMC walkers live in the unconstrained ``u`` space. The
least-squares solver works in a third, bounded space (:attr:`Parameter.solver_log`):
``ln x`` for a positive scale with a positive lower bound (roughness, exponents),
the natural ``x`` for everything else, with the bounds as a box. A parameter whose table
row names a partner in :attr:`Parameter.product_with` is solved jointly with it, as
``(ln(partner x), 1/x)`` (see there). Reports are in the natural ``x`` space.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import jax
import jax.numpy as jnp
import numpy as np
from scipy.special import expit

from brdffit.errors import ParameterError

Transform = Literal["identity", "logit", "log"]
AnyArray = jax.Array | np.ndarray | np.generic
"""A JAX array (traced code) or a NumPy array (the host's bookkeeping, :func:`namespace`)."""

Params = dict[str, AnyArray]
"""Parameter name -> value: JAX arrays in traced code, NumPy arrays on the host."""


@dataclass(frozen=True)
class Parameter:
    """One row of a model's parameter table.

    Fields: ``name``; ``shape`` ``()`` or ``(3,)``; ``bounds`` (low, high) in natural
    units; ``default`` (a float, broadcast to the shape); ``transform``; ``doc`` the
    meaning with its unit; ``linear`` True when the BRDF is affine in the parameter
    (albedos, Fresnel F0), so a linear least-squares solve can start it; ``solver``
    the least-squares solver's space when the transform does not say it
    (:attr:`solver_log`); ``neutral`` the value at which the parameter adds nothing to
    a simpler published form of the model (Disney's ``specular`` 0.5, the common
    dielectric F0 0.04; the Student-t shape ``gamma`` 2, which is GGX) or ``None``:
    :func:`brdffit.simplify` may pin it there, the spec option ``neutral``
    (:mod:`brdffit.models._restrict`); ``product_with`` the name of a partner ``a``
    when the data pin down the product ``a x`` far better than either: while both are
    free, the solver works on ``(ln(a x), 1/x)`` (:meth:`ParameterLayout.to_solver`).

    ``product_with`` is for a curve ``(1 + a u)^-x`` such as Löw's ABC lobe: near its
    peak it is ``exp(-a x u + (a x u)^2 / (2 x) - ...)``, so ``a x`` sets the peak's
    width and ``x`` enters only through ``1/x``. In ``(ln a, ln x)`` the loss has a
    curved valley along ``a x = const`` whose floor is nearly linear in ``1/x``;
    Gauss-Newton steps along it are short (78 LM steps on blue-metallic-paint at stride
    5 5 9). In ``(ln(a x), 1/x)`` the valley is a coordinate line and the loss along it
    nearly linear: 21 steps to the same optimum (15 since the solver's secant term).
    """

    name: str
    shape: tuple[int, ...]
    bounds: tuple[float, float]
    default: float
    transform: Transform
    doc: str
    linear: bool = False
    solver: Literal["natural", "log"] | None = None
    neutral: float | None = None
    product_with: str | None = None

    def __post_init__(self) -> None:
        lo, hi = self.bounds
        if not lo < hi:
            raise ParameterError(f"parameter {self.name!r}: bounds {self.bounds} need low < high")
        if not lo <= self.default <= hi:
            raise ParameterError(
                f"parameter {self.name!r}: default {self.default} outside bounds {self.bounds}"
            )
        if self.neutral is not None and not lo <= self.neutral <= hi:
            raise ParameterError(
                f"parameter {self.name!r}: neutral {self.neutral} outside bounds {self.bounds}"
            )
        if self.transform == "logit" and not (math.isfinite(lo) and math.isfinite(hi)):
            raise ParameterError(f"parameter {self.name!r}: 'logit' needs finite bounds")
        if self.transform == "log" and (lo < 0 or (lo == 0 and math.isfinite(hi))):
            raise ParameterError(
                f"parameter {self.name!r}: 'log' needs low >= 0, and low > 0 when high is finite"
            )
        if self.solver == "log" and lo < 0:
            raise ParameterError(f"parameter {self.name!r}: solver 'log' needs low >= 0")
        if self.shape not in ((), (3,)):
            raise ParameterError(f"parameter {self.name!r}: shape {self.shape} not () or (3,)")
        if self.product_with is not None and (self.shape != () or not lo > 0):
            raise ParameterError(
                f"parameter {self.name!r}: product_with needs a scalar with low > 0"
            )

    @property
    def size(self) -> int:
        """Number of scalars in the parameter (1 or 3)."""
        return math.prod(self.shape)

    @property
    def saturates(self) -> bool:
        """True when the transform flattens onto a finite bound (logit, bounded log)."""
        return self.transform == "logit" or (
            self.transform == "log" and math.isfinite(self.bounds[1])
        )

    @property
    def solver_log(self) -> bool:
        """True when the least-squares solver works on ``ln x`` (bounds ``ln low, ln high``).

        A ``log`` parameter with ``low > 0`` is a scale that spans decades (roughness
        1e-4..2, Phong exponents to 1e5): LM's linear model holds over a wider range in
        ``ln x``. So is a width on ``[0, high]`` whose table says ``solver="log"``
        (Disney's perceptual roughness: its box in ``ln x`` is open below). Every other
        parameter is solved in natural units inside its box: a logit or bounded-log
        transform flattens towards its bounds, so a parameter whose optimum is on (or
        next to) a bound crawls there; a box lets it land on it.
        """
        if self.solver is not None:
            return self.solver == "log"
        return self.transform == "log" and self.bounds[0] > 0

    def default_array(self, dtype: jnp.dtype = jnp.float64) -> jax.Array:
        """The default broadcast to the parameter's shape."""
        return jnp.full(self.shape, self.default, dtype=dtype)

    def to_natural(self, u: AnyArray) -> AnyArray:
        """Unconstrained ``u`` -> natural value ``x`` (see module docstring); NumPy in,
        NumPy out (:func:`namespace`)."""
        lo, hi = self.bounds
        xp = namespace(u)
        sigmoid = jax.nn.sigmoid if xp is jnp else expit
        if self.transform == "identity":
            return u
        if self.transform == "logit":
            x = lo + (hi - lo) * sigmoid(u)
        elif math.isfinite(hi):
            x = lo * xp.exp(math.log(hi / lo) * sigmoid(u))
        else:
            return lo + xp.exp(u)
        # rounding can land a few ulp past a bound (10.000000000000009 on [0.001, 10]);
        # keep a value a user could pass back in (``where``: the gradient stays whole)
        return xp.where(x > hi, hi, xp.where(x < lo, lo, x))

    def to_unconstrained(self, x: AnyArray) -> AnyArray:
        """Natural ``x`` -> unconstrained ``u``; ``x`` is first nudged inside the bounds.
        NumPy in (or a number), NumPy out (:func:`namespace`)."""
        lo, hi = self.bounds
        xp = namespace(x)
        x = xp.asarray(x, dtype=float) if xp is np else x
        if self.transform == "identity":
            return x
        if self.transform == "logit":
            t = xp.clip((x - lo) / (hi - lo), 1e-12, 1 - 1e-12)
            return xp.log(t) - xp.log1p(-t)
        if math.isfinite(hi):
            t = xp.clip(xp.log(xp.maximum(x, lo) / lo) / math.log(hi / lo), 1e-12, 1 - 1e-12)
            return xp.log(t) - xp.log1p(-t)
        return xp.log(xp.maximum(x - lo, 1e-300))

    def check_value(self, value: object) -> np.ndarray:
        """Validate a user value: finite, broadcastable to the shape, inside the bounds."""
        arr = np.asarray(value, dtype=float)
        try:
            arr = np.broadcast_to(arr, self.shape)
        except ValueError:
            raise ParameterError(
                f"parameter {self.name!r}: value of shape {np.shape(value)} does not fit "
                f"shape {self.shape}"
            ) from None
        lo, hi = self.bounds
        if not np.all(np.isfinite(arr)) or np.any(arr < lo) or np.any(arr > hi):
            raise ParameterError(
                f"parameter {self.name!r}: value {arr.tolist()} outside bounds [{lo}, {hi}]"
            )
        return arr.copy()


@dataclass(frozen=True)
class ParameterLayout:
    """Packs the free parameters of a table into one flat vector and back.

    ``free`` lists the free parameters in table order, ``frozen`` maps the frozen
    ones to their fixed natural values.
    """

    free: tuple[Parameter, ...]
    frozen: Mapping[str, AnyArray]

    @classmethod
    def build(
        cls,
        table: Sequence[Parameter],
        freeze: Mapping[str, object] | None = None,
    ) -> ParameterLayout:
        """Split ``table`` into free and frozen parameters; ``freeze`` maps name -> value."""
        freeze = dict(freeze or {})
        names = {p.name for p in table}
        unknown = sorted(set(freeze) - names)
        if unknown:
            raise ParameterError(
                f"cannot freeze unknown parameter(s) {unknown}; the model has {sorted(names)}"
            )
        frozen = {p.name: p.check_value(freeze[p.name]) for p in table if p.name in freeze}
        return cls(free=tuple(p for p in table if p.name not in freeze), frozen=frozen)

    @property
    def size(self) -> int:
        """Length of the flat vector of free scalars."""
        return sum(p.size for p in self.free)

    def labels(self) -> list[str]:
        """One label per free scalar: ``name`` or ``name[c]`` for RGB channels."""
        out = []
        for p in self.free:
            out += [p.name] if p.shape == () else [f"{p.name}[{c}]" for c in "rgb"]
        return out

    def split(self, flat: AnyArray) -> Params:
        """Flat free vector -> dict of the free parameters (same space as ``flat``)."""
        out, i = {}, 0
        for p in self.free:
            out[p.name] = flat[i : i + p.size].reshape(p.shape)
            i += p.size
        return out

    def join(self, params: Mapping[str, AnyArray]) -> jax.Array:
        """Dict (free parameters, any space) -> flat vector."""
        if not self.free:
            return jnp.zeros((0,))
        return jnp.concatenate([jnp.ravel(jnp.asarray(params[p.name])) for p in self.free])

    def unconstrained(self, params: Mapping[str, AnyArray]) -> jax.Array:
        """Natural dict -> flat unconstrained vector of the free parameters."""
        if not self.free:
            return jnp.zeros((0,))
        return jnp.concatenate(
            [jnp.ravel(p.to_unconstrained(jnp.asarray(params[p.name]))) for p in self.free]
        )

    def params(
        self, flat: AnyArray, space: Literal["natural", "unconstrained", "solver"]
    ) -> Params:
        """Flat free vector in ``space`` -> natural dict of every parameter (frozen ones too).

        The one place a flat vector becomes the dict a model evaluates; ``solver`` is
        the space of :meth:`from_solver` (:attr:`Parameter.solver_log`, pairs).
        """
        out = dict(self.frozen)
        if space == "solver":
            flat = self.from_solver(flat)
        for p, v in zip(self.free, self.split(flat).values(), strict=True):
            out[p.name] = p.to_natural(v) if space == "unconstrained" else v
        return out

    def pairs(self) -> tuple[tuple[int, int], ...]:
        """``(i, j)`` flat indices of the jointly solved pairs: ``j`` a free parameter with
        :attr:`Parameter.product_with`, ``i`` its free partner (none when it is frozen)."""
        index, i = {}, 0
        for p in self.free:
            index[p.name] = i
            i += p.size
        out = []
        for p in self.free:
            partner = next((q for q in self.free if q.name == p.product_with), None)
            if partner is not None and partner.shape == ():
                out.append((index[partner.name], index[p.name]))
        return tuple(out)

    def to_solver(self, x: jax.Array) -> jax.Array:
        """Flat natural -> flat solver vector (traced): ``ln x`` where :attr:`solver_log`,
        ``(ln(x_i x_j), 1/x_j)`` for each pair of :meth:`pairs`, ``x`` elsewhere."""
        log = jnp.asarray(self.solver_log_mask())
        z = jnp.where(log, jnp.log(jnp.where(log, x, 1.0)), x)
        for i, j in self.pairs():
            z = z.at[i].set(jnp.log(x[i]) + jnp.log(x[j])).at[j].set(1.0 / x[j])
        return z

    def solver_jacobian(self, x: np.ndarray) -> np.ndarray:
        """``d z / d x`` (k, k) of :meth:`to_solver` at the flat natural ``x`` (NumPy):
        ``1 / x`` on the diagonal where :attr:`solver_log`, and for each pair ``(i, j)``
        the row ``z_i = ln x_i + ln x_j`` and ``z_j = 1 / x_j``. A Jacobian in the
        solver space times it is the Jacobian in natural units."""
        x = np.asarray(x, float)
        t = np.diag(np.where(self.solver_log_mask(), 1.0 / np.where(x != 0, x, 1.0), 1.0))
        for i, j in self.pairs():
            t[i, :] = 0.0
            t[j, :] = 0.0
            t[i, i], t[i, j], t[j, j] = 1.0 / x[i], 1.0 / x[j], -1.0 / x[j] ** 2
        return t

    def from_solver(self, z: AnyArray) -> AnyArray:
        """Flat solver -> flat natural vector, the inverse of :meth:`to_solver` (traced, or
        NumPy in and out on the host: :func:`namespace`).

        A pair's box is the product of its members' boxes, so ``x_i = e^(z_i) z_j`` can
        leave ``x_i``'s bounds: it is clipped there (its bound then holds it, as the box
        holds any other parameter).
        """
        if not self.free:
            return z
        xp = namespace(z)
        # exp per parameter, not over the flat vector: XLA's vector and scalar exp differ
        # in the last bit, and a fit's tie-breaks between starts follow that bit
        parts = self.split(z).values()
        x = xp.concatenate(
            [
                xp.ravel(xp.exp(v) if p.solver_log else v)
                for p, v in zip(self.free, parts, strict=True)
            ]
        )
        lo, hi = self.bounds_flat()
        for i, j in self.pairs():
            a = xp.clip(xp.exp(z[i]) * z[j], lo[i], hi[i])
            if xp is jnp:
                x = x.at[j].set(1.0 / z[j]).at[i].set(a)
            else:
                x[j], x[i] = 1.0 / z[j], a
        return x

    def solver_vector(self, params: Mapping[str, object]) -> np.ndarray:
        """Natural dict -> flat solver-space vector of the free parameters, clipped into
        the box (numpy: starts are made on the host)."""
        return self.solver_rows([params])[0]

    def solver_rows(self, params: Sequence[Mapping[str, object]]) -> np.ndarray:
        """Natural dicts -> (n, k) solver-space rows, each as :meth:`solver_vector`; the
        box, the log mask and the pairs looked up once for all rows (a fit's 30-odd
        candidate starts)."""
        nat = [self.natural_vector(p) for p in params]
        x = np.clip(np.stack(nat) if nat else np.zeros((0, self.size)), *self.bounds_flat())
        z = np.where(self.solver_log_mask(), np.log(np.maximum(x, 1e-300)), x)
        for i, j in self.pairs():
            z[:, i], z[:, j] = np.log(x[:, i]) + np.log(x[:, j]), 1.0 / x[:, j]
        return z

    def natural_vector(self, params: Mapping[str, object]) -> np.ndarray:
        """Natural dict -> flat natural vector of the free parameters, in the order of
        :meth:`labels` (numpy, on the host; :meth:`join` is the traced one)."""
        flat = [np.ravel(np.asarray(params[p.name], float)) for p in self.free]
        return np.concatenate(flat) if flat else np.zeros(0)

    def solver_log_mask(self) -> np.ndarray:
        """Per free scalar: True where the parameter is a scale the solver works on in
        ``ln x`` (:attr:`Parameter.solver_log`; the members of :meth:`pairs` have their
        own coordinates, :meth:`to_solver`)."""
        return np.concatenate(
            [np.full(p.size, p.solver_log) for p in self.free] or [np.zeros(0, bool)]
        )

    def solver_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The solver space's box: natural bounds, or their logs where :attr:`solver_log`
        (``ln 0 = -inf``: open below)."""
        lo, hi = self.bounds_flat()
        log = self.solver_log_mask()
        with np.errstate(divide="ignore"):
            log_lo, log_hi = np.log(np.where(log, lo, 1.0)), np.log(np.where(log, hi, 1.0))
        zlo, zhi = np.where(log, log_lo, lo), np.where(log, log_hi, hi)
        for i, j in self.pairs():
            # ln x_i + ln x_j, as solver_vector and to_solver form it: ln(x_i x_j) rounds
            # differently, and a point on the bounds then fell 1 ulp outside the box
            zlo[i], zhi[i] = np.log(lo[i]) + np.log(lo[j]), np.log(hi[i]) + np.log(hi[j])
            zlo[j], zhi[j] = 1.0 / hi[j], 1.0 / lo[j]
        return zlo, zhi

    def bounds_flat(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of each free scalar."""
        lo = np.concatenate([np.full(p.size, p.bounds[0]) for p in self.free] or [np.zeros(0)])
        hi = np.concatenate([np.full(p.size, p.bounds[1]) for p in self.free] or [np.zeros(0)])
        return lo, hi


def namespace(x: object):
    """``jax.numpy`` for a JAX array or tracer, ``numpy`` for anything else: the host's
    bookkeeping of parameter vectors (starts, results) runs in NumPy, because every
    eager JAX operation compiles a small program per shape (about 10 ms each in a fresh
    process, a hundred of them in a fit)."""
    return jnp if isinstance(x, jax.Array) else np
