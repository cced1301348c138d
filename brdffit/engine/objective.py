"""The least-squares objective: model, parameter layout, robust loss, frozen values.

One :class:`Objective` value is what the solver, the starts, the covariance, the
posterior and the stress benchmark all evaluate, on data prepared for a metric
(:class:`brdffit.engine.metrics.Prepared`, which holds the metric: its samples, weights and
transform); nothing passes those pieces around loose. It is an equinox Module: the
model, free parameters and robust kind are static, the frozen values and the robust
scale are arrays, and the metric's switches are arrays of the data, so one compiled
solve serves every data set of the same shape under every metric.

A point is a flat vector ``z`` in the solver space of
:meth:`brdffit.core.parameters.ParameterLayout.params` (``ln x`` for positive scales,
natural ``x`` otherwise). The objective minimised is

    C(z) = 0.5 sum_i rho(r_i(z)^2)

with ``r`` the residual vector of the data's metric (:func:`brdffit.engine.misfit.residuals`)
and ``rho`` the robust loss (identity without one; :func:`brdffit.engine.robust.robust_residuals`).
Levenberg-Marquardt sees it through :meth:`Objective.linearize`: the iteratively
reweighted Gauss-Newton model ``g = J^T W r``, ``H = J^T W J`` with ``W = rho'(r^2)``.
"""

from __future__ import annotations

from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.parameters import Parameter, ParameterLayout, Params
from brdffit.engine import misfit
from brdffit.engine import robust as robust_mod
from brdffit.engine.block_errors import BlockChunks
from brdffit.engine.jacobian import Colouring, channel_grams, compressed, normal
from brdffit.engine.metrics import Prepared
from brdffit.util.programs import program


class Objective(eqx.Module):
    """``0.5 sum rho(r^2)`` of one model on data prepared for a metric (module docstring).

    Fields: ``model``; ``free`` the free parameter rows in table order; ``frozen`` name ->
    fixed natural value; ``robust`` ``None``, ``"huber"`` or ``"cauchy"``;
    ``scale`` the robust loss's scale in residual units (1 without one; one per problem
    while :func:`brdffit.fit_many` batches problems).
    """

    model: AbstractModel
    free: tuple[Parameter, ...] = eqx.field(static=True)
    frozen: dict[str, Array | np.ndarray]
    robust: str | None = eqx.field(static=True, default=None)
    scale: Float[Array | np.ndarray, "*p"] = eqx.field(default_factory=lambda: np.asarray(1.0))

    @classmethod
    def build(
        cls,
        model: AbstractModel,
        freeze: Mapping[str, object] | None = None,
        robust: str | None = None,
        scale: float = 1.0,
    ) -> Objective:
        """The objective of ``model`` with ``freeze`` (name -> natural value)."""
        robust_mod.check_kind(robust)
        layout = ParameterLayout.build(model.parameters, freeze)
        frozen = {k: np.asarray(v, np.float64) for k, v in layout.frozen.items()}
        return cls(model, layout.free, frozen, robust, np.asarray(float(scale)))

    @property
    def layout(self) -> ParameterLayout:
        """The packing between parameter dicts and flat vectors."""
        return ParameterLayout(self.free, self.frozen)

    @property
    def size(self) -> int:
        """Number of free scalars."""
        return self.layout.size

    def with_robust(self, robust: str | None, scale: float | Array | np.ndarray) -> Objective:
        """The same objective under another robust loss and scale."""
        # a traced or device scale stays as it is; a host one is not sent through JAX
        scale = scale if isinstance(scale, jax.Array) else np.asarray(scale, np.float64)
        return Objective(self.model, self.free, self.frozen, robust, scale)

    def params(self, z: Float[Array | np.ndarray, " k"]) -> Params:
        """Natural parameter dict (frozen values included) at the solver-space ``z``."""
        return self.layout.params(z, "solver")

    def residuals(self, z: Float[Array, " k"], prep: Prepared) -> Float[Array, " m"]:
        """The plain residual vector (length 3N) of ``prep``'s metric at ``z``."""
        return misfit.residuals(self.model.evaluate(self.params(z), prep.g), prep)

    def cost(self, z: Float[Array, " k"], prep: Prepared) -> Float[Array, ""]:
        """``0.5 sum rho(r^2)`` at ``z``."""
        r = robust_mod.robust_residuals(self.residuals(z, prep), self.robust, self.scale)
        return 0.5 * jnp.sum(r * r)

    @property
    def colouring(self) -> Colouring:
        """Which Jacobian columns share a forward-mode pass (:mod:`brdffit.engine.jacobian`)."""
        return Colouring.of(self.free, self.model.channel_separable)

    def jacobian(
        self, z: Float[Array, " k"], prep: Prepared
    ) -> tuple[Float[Array, " m"], Float[Array, "m k"]]:
        """``(r, J)``: the plain residuals and their Jacobian in the solver space at ``z``.

        Forward mode, one pass per colour of :attr:`colouring`: per free parameter of a
        channel-separable model, per free scalar otherwise; the residuals outnumber
        them by five orders of magnitude on MERL data.
        """
        b, r = self._compressed(z, prep)
        return r, self.colouring.dense(b)

    def linearize(
        self, z: Float[Array, " k"], prep: Prepared
    ) -> tuple[Float[Array, ""], Float[Array, " k"], Float[Array, "k k"]]:
        """``(C, g, H)`` at ``z``: cost, gradient ``J^T W r`` and Gauss-Newton ``J^T W J``,
        from the compressed Jacobian (:func:`brdffit.engine.jacobian.normal`; ``J`` itself
        is never formed)."""
        b, r = self._compressed(z, prep)
        w = robust_mod.robust_weights(r, self.robust, self.scale)
        rr = robust_mod.robust_residuals(r, self.robust, self.scale)
        g, h = normal(b, w, r, self.colouring)
        return 0.5 * jnp.sum(rr * rr), g, h

    def natural_moments(
        self, z: Float[Array, " k"], prep: Prepared
    ) -> tuple[Float[Array, "k k"], Float[Array, "k k"], Float[Array, ""], Float[Array, ""], Array]:
        """``(J^T J, J^T diag(e^2) J, e.e, r.r, J^T e)`` for the covariance, in natural units.

        ``e`` are the robust residuals (``r`` without a robust loss) and ``J`` their
        Jacobian with respect to the free natural parameters (the Gauss-Newton form of
        the M-estimator sandwich); ``r.r`` is the plain residuals' sum of squares;
        ``J^T e`` the gradient of ``e.e / 2``.
        """
        b, e, r, _ = self._natural_compressed(z, prep)
        return self._moments(b, e, r)

    def block_moments(
        self, z: Float[Array, " k"], prep: Prepared, chunks: BlockChunks
    ) -> tuple[Float[Array, "b k"], Float[Array, "b k k"]]:
        """Per block: the summed scores ``sum J_i^T e_i`` (b, k) and ``J_b^T J_b`` (b, k, k).

        The last two of :meth:`natural_block_moments` (arguments there).
        """
        return self.natural_block_moments(z, prep, chunks)[2:]

    def natural_block_moments(
        self, z: Float[Array, " k"], prep: Prepared, chunks: BlockChunks
    ) -> tuple[Float[Array, "k k"], Float[Array, ""], Float[Array, "b k"], Float[Array, "b k k"]]:
        """``(J^T J, r.r, scores, grams)`` for the block covariance, from one Jacobian.

        ``J``, ``e`` and ``r`` as :meth:`natural_moments` (natural units); per block ``b``
        the score ``J_b^T e_b`` (b, k) and Gram matrix ``J_b^T J_b`` (b, k, k), whose sum
        over the blocks is ``J^T J``. ``chunks``: the samples grouped by block
        (:class:`brdffit.engine.block_errors.BlockChunks`; a sample's three residuals go
        to its block). Each chunk's sums are per-channel matrix products over its rows
        of the compressed Jacobian, and only the chunks' sums are added by block
        (scattering every sample's outer product instead took 0.85 s for Disney on a
        full MERL grid against 0.48 s; walter 0.23 against 0.20 s). Memory: the rows of
        the chunks mapped at once.
        """
        b, e, r, _ = self._natural_compressed(z, prep)
        return self._block_moments(b, e, r, chunks)

    def answer(
        self,
        z: Float[Array, " k"],
        prep: Prepared,
        chunks: BlockChunks | None,
        sides: dict[str, Prepared],
    ) -> tuple[tuple[Array, ...], dict[str, Float[Array, ""]]]:
        """What a result needs at the answer ``z``, from one pass over the data.

        Returns ``(moments, losses)``: ``moments`` those of :meth:`natural_moments`
        (``chunks`` None) or of :meth:`natural_block_moments`; ``losses`` every metric's
        loss (:func:`brdffit.engine.misfit.losses`) of the model values that the same
        Jacobian pass computes, name -> loss, on ``sides`` (metric name -> the data
        prepared for it, padded as ``prep`` is and sharing its geometry). One pass, not a
        Jacobian for the covariance and a second evaluation for the losses: at the
        full MERL grid each is a full pass over 2.7 million residuals.
        """
        b, e, r, f = self._natural_compressed(z, prep)
        moments = self._moments(b, e, r) if chunks is None else self._block_moments(b, e, r, chunks)
        return moments, misfit.losses(f, prep.cos_i, sides)

    def _moments(self, b: Array, e: Array, r: Array) -> tuple[Array, Array, Array, Array, Array]:
        """:meth:`natural_moments` from the compressed Jacobian ``b``, ``e`` and ``r``."""
        # one pass over [B, diag(e) B, e]: its per-channel Gram matrices hold J^T J,
        # J^T diag(e^2) J, J^T e (the first block's products with e) and e.e
        e3 = e.reshape(b.shape[:2])[:, :, None]
        both = jnp.concatenate([b, b * e3, e3], axis=2)
        gram, p = channel_grams(both, both), b.shape[2]
        col = self.colouring
        return (
            col.spread_matrix(gram[:, :p, :p]),
            col.spread_matrix(gram[:, p : 2 * p, p : 2 * p]),
            jnp.sum(gram[:, 2 * p, 2 * p]),
            r @ r,
            col.spread_vector(gram[:, :p, 2 * p]),
        )

    def _block_moments(
        self, b: Array, e: Array, r: Array, chunks: BlockChunks
    ) -> tuple[Array, Array, Array, Array]:
        """:meth:`natural_block_moments` from the compressed Jacobian ``b``, ``e`` and ``r``."""
        scores, grams = self._block_sums(b, e, chunks)
        return jnp.sum(grams, axis=0), r @ r, scores, grams

    def _block_sums(self, b: Array, e: Array, chunks: BlockChunks) -> tuple[Array, Array]:
        """Per block ``J_b^T e_b`` (b, k) and ``J_b^T J_b`` (b, k, k) from the compressed
        Jacobian ``b`` of the residuals ``e``, chunk by chunk (:class:`BlockChunks`)."""
        n, _, p = b.shape
        col = self.colouring
        b0 = jnp.concatenate([b, jnp.zeros((1, 3, p), b.dtype)])  # row n pads short chunks
        e0 = jnp.concatenate([e.reshape(n, 3), jnp.zeros((1, 3), e.dtype)])

        def sums(rows: Array) -> tuple[Array, Array]:
            bb, ee = b0[rows], e0[rows]  # (m, 3, p), (m, 3)
            return jnp.einsum("mcp,mc->cp", bb, ee), jnp.einsum("mcp,mcq->cpq", bb, bb)

        score_c, gram_c = jax.lax.map(sums, chunks.index, batch_size=8)
        scores = jax.ops.segment_sum(score_c, chunks.block, chunks.n_blocks)
        grams = col.spread_matrix(jax.ops.segment_sum(gram_c, chunks.block, chunks.n_blocks))
        return col.spread_vector(scores), grams

    def linearize_blocks(
        self, z: Float[Array, " k"], prep: Prepared, chunks: BlockChunks
    ) -> tuple[Array, Array, Array, tuple[Array, Array]]:
        """``(C, g, H, (scores, grams))`` at ``z`` in the solver space, without a robust
        loss: the normal equations as the sums over blocks of each block's score
        ``J_b^T r_b`` and Gram matrix ``J_b^T J_b``, which are kept. They cost what
        :meth:`linearize` does (walter at full resolution, best of 9: 117-149 against
        118-120 ms; Lambert 26-28 against 35 ms), and the block errors at the answer need
        no Jacobian pass of their own (:class:`WithBlockSums`)."""
        b, r = self._compressed(z, prep)
        scores, grams = self._block_sums(b, r, chunks)
        return 0.5 * (r @ r), jnp.sum(scores, axis=0), jnp.sum(grams, axis=0), (scores, grams)

    def _compressed(self, z: Array, prep: Prepared) -> tuple[Array, Array]:
        """``(B, r)``: the plain residuals' compressed Jacobian in the solver space
        (:func:`brdffit.engine.jacobian.compressed`) and ``r``."""
        r, _, b = compressed(lambda zz: (self.residuals(zz, prep), ()), z, self.colouring)
        return b, r

    def _natural_compressed(self, z: Array, prep: Prepared) -> tuple[Array, Array, Array, Array]:
        """``(B, e, r, f)``: the robust residuals' compressed Jacobian in natural units
        (:func:`brdffit.engine.jacobian.compressed`), ``e``, ``r`` and the model's
        values ``f`` (N, 3) at ``z``."""
        layout = self.layout

        def robust(xn: Array) -> tuple[Array, tuple[Array, Array]]:
            f = self.model.evaluate(self.params(layout.to_solver(xn)), prep.g)
            r = misfit.residuals(f, prep)
            return robust_mod.robust_residuals(r, self.robust, self.scale), (r, f)

        e, (r, f), b = compressed(robust, layout.from_solver(z), self.colouring)
        return b, e, r, f


class WithBlockSums(eqx.Module):
    """An objective without a robust loss whose every linearisation also keeps the
    blocks' scores and Gram matrices (:meth:`Objective.linearize_blocks`).

    The descent on all samples solves it when the fit reports block errors: its last
    linearisation then holds what :meth:`Objective.natural_block_moments` would compute
    again at the answer (:func:`moved_block_moments`), and the pass at the answer only
    computes the losses (:func:`losses_at`). ``linearize_extra`` is what
    :func:`brdffit.engine.lm.step` keeps of a linearisation: its point and the sums."""

    obj: Objective
    chunks: BlockChunks

    def __check_init__(self) -> None:
        if self.obj.robust is not None:  # its normal equations carry the IRLS weights
            raise ValueError(f"WithBlockSums takes no robust loss ({self.obj.robust!r})")

    def cost(self, z: Array, prep: Prepared) -> Array:
        return self.obj.cost(z, prep)

    def linearize(self, z: Array, prep: Prepared) -> tuple[Array, Array, Array]:
        return self.linearize_extra(z, prep)[:3]

    def linearize_extra(self, z: Array, prep: Prepared):
        c, g, h, (scores, grams) = self.obj.linearize_blocks(z, prep, self.chunks)
        return c, g, h, (z, scores, grams)

    def nothing_kept(self, z: Array) -> tuple[Array, Array, Array]:
        """Zeros shaped as :meth:`linearize_extra` keeps, for a state not linearised yet."""
        k, b = z.size, self.chunks.n_blocks
        return jnp.zeros_like(z), jnp.zeros((b, k), z.dtype), jnp.zeros((b, k, k), z.dtype)


def moved_block_moments(
    obj: Objective, z: np.ndarray, kept: tuple, cost: float
) -> tuple[np.ndarray, float, np.ndarray, np.ndarray] | None:
    """:meth:`Objective.natural_block_moments` at the answer ``z`` from the block sums a
    descent kept at its last linearisation (``kept``: its point, scores and Gram matrices
    in the solver space) and the cost ``C(z)`` (no robust loss: ``r.r = 2 C``).

    To natural units by the chain rule (``J_x = J_z dz/dx``,
    :meth:`~brdffit.core.parameters.ParameterLayout.solver_jacobian`), then moved from the
    point of the linearisation to the answer to first order, ``s_b + A_b (x - x_lin)``
    (exact for a model linear in its parameters). The descent stops when a step changes
    the cost or the point by less than its tolerances, so the answer is that one step
    from the linearisation or the linearisation itself (MINPACK's convention keeps
    ``J`` there unmoved).

    None where a jointly solved pair has a member on its bound: there
    :meth:`~brdffit.core.parameters.ParameterLayout.from_solver` clips it and the chain
    rule does not hold (the caller then takes the moments from a pass at the answer)."""
    layout = obj.layout
    z_lin, scores, grams = (np.asarray(a, float) for a in kept)
    x_lin, x = layout.from_solver(z_lin), layout.from_solver(np.asarray(z, float))
    members = [i for pair in layout.pairs() for i in pair]
    if members:
        lo, hi = layout.bounds_flat()
        if np.any((x[members] <= lo[members]) | (x[members] >= hi[members])):
            return None
    t = layout.solver_jacobian(x_lin)
    grams_n = t.T @ grams @ t
    scores_n = scores @ t + grams_n @ (x - x_lin)
    return np.sum(grams_n, axis=0), 2.0 * float(cost), scores_n, grams_n


@program
def cost(obj: Objective, z: Array, prep: Prepared) -> Array:
    """Jitted :meth:`Objective.cost`."""
    return obj.cost(z, prep)


@program
def plain_residuals(obj: Objective, z: Array, prep: Prepared) -> Array:
    """Jitted :meth:`Objective.residuals`."""
    return obj.residuals(z, prep)


@program
def natural_moments(obj: Objective, z: Array, prep: Prepared):
    """Jitted :meth:`Objective.natural_moments`."""
    return obj.natural_moments(z, prep)


@program
def block_moments(obj: Objective, z: Array, prep: Prepared, chunks: BlockChunks):
    """Jitted :meth:`Objective.block_moments`."""
    return obj.block_moments(z, prep, chunks)


@program
def natural_block_moments(obj: Objective, z: Array, prep: Prepared, chunks: BlockChunks):
    """Jitted :meth:`Objective.natural_block_moments`."""
    return obj.natural_block_moments(z, prep, chunks)


@program
def losses_at(obj: Objective, z: Array, prep: Prepared, sides: dict):
    """Every metric's loss at ``z`` (:func:`brdffit.engine.misfit.losses`; ``sides`` as
    :meth:`Objective.answer` takes them): the pass at the answer when the covariance's
    moments come from the descent (:class:`WithBlockSums`)."""
    return misfit.losses(obj.model.evaluate(obj.params(z), prep.g), prep.cos_i, sides)


@program
def answer(obj: Objective, z: Array, prep: Prepared, chunks: BlockChunks | None, sides: dict):
    """Jitted :meth:`Objective.answer`."""
    return obj.answer(z, prep, chunks, sides)


def start_params(model: AbstractModel, init: Mapping[str, object] | None) -> Params:
    """The model's defaults with ``init`` (name -> natural value) checked and put in
    (NumPy: the starts are made on the host)."""
    params = {p.name: np.full(p.shape, p.default) for p in model.parameters}
    for name, value in (init or {}).items():
        params[name] = model.parameter(name).check_value(value)
    return params


def freeze_map(model: AbstractModel, freeze: object, start: Params) -> dict[str, object]:
    """``freeze`` as name -> natural value: a mapping as given, names at their ``start``."""
    if freeze is None:
        return {}
    if isinstance(freeze, Mapping):
        return dict(freeze)
    if isinstance(freeze, str):
        freeze = [freeze]
    for name in freeze:
        model.parameter(name)
    return {name: np.asarray(start[name]) for name in freeze}
