"""The block errors of ``errors="blocks"``: cluster covariance over (theta_h, theta_d) blocks.

Model error is a smooth function of (theta_h, theta_d): the residuals of a fit to
measured data change sign over a few degrees (specular peak, Fresnel rise), so a
:data:`~brdffit.core.result_terms.BLOCK_DEG`-degree block holds a stretch of correlated
error while the 80-degree cut keeps 50-70 occupied blocks. The estimator, its small-sample
degrees of freedom and why these are described in :mod:`brdffit.engine.uncertainty`;
this module holds the arithmetic, on ``k x k`` matrices only: ``A = J^T J`` and each
block's Gram matrix ``A_b = J_b^T J_b`` and score ``s_b = J_b^T e_b``
(:meth:`brdffit.engine.objective.Objective.natural_block_moments`).

Every function works on the column-scaled matrices (``A / outer(d, d)``, ``d`` the
square root of ``diag(A)``), as :func:`brdffit.engine.uncertainty.conditioning` does, so
scalars of very different units do not lose digits in the eigen-decompositions.
"""

from __future__ import annotations

import equinox as eqx
import numpy as np
from jaxtyping import Array, Int
from scipy import stats

from brdffit.core.result_terms import BLOCK_DEG
from brdffit.engine.metrics import Prepared, to_device
from brdffit.util.memo import per_object

MIN_BLOCKS = 20
"""Fewer occupied blocks than this and ``errors="blocks"`` gives no errors (the cluster
sum of ``G`` scores has rank ``< G`` and is unreliable for small ``G``)."""

SINGULAR = 1e15
"""A block's leverage (an eigenvalue of ``A^-1/2 A_b A^-1/2``, at most 1) within
``1 / SINGULAR`` of 1 means that block alone identifies a direction: the leverage
correction divides by ``1 - l``, which float64 resolves to 1 in 4.5e15."""


def block_cells(prep: Prepared, block_deg: float = BLOCK_DEG) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's block coordinates ``(floor(theta_h / deg), floor(theta_d / deg))``
    (the padding rows after the samples left out)."""
    n = prep.n
    th = np.degrees(np.arccos(np.clip(np.asarray(prep.g.cos_h)[:n], -1.0, 1.0)))
    td = np.degrees(np.arccos(np.clip(np.asarray(prep.g.cos_d)[:n], -1.0, 1.0)))
    return np.floor(th / block_deg).astype(int), np.floor(td / block_deg).astype(int)


def block_index(prep: Prepared, block_deg: float = BLOCK_DEG) -> tuple[np.ndarray, int]:
    """Each sample's (theta_h, theta_d) block, numbered 0..G-1 over occupied blocks; G."""
    i, j = block_cells(prep, block_deg)
    per_row = int(np.ceil(90.0 / block_deg)) + 1
    occupied, ids = np.unique(i * per_row + j, return_inverse=True)
    return ids.astype(np.int32), int(occupied.size)


BLOCK_CHUNK = 2_048
"""Samples per chunk of :class:`BlockChunks`: each chunk's Gram matrices are one small
matrix product (2,048 x 3P), and a block wastes less than one chunk of padding (61
blocks of 36 to 54,000 samples on the full MERL grid: 479 chunks, 8% more rows than
samples)."""


class BlockChunks(eqx.Module):
    """The samples grouped by block and cut into chunks of :data:`BLOCK_CHUNK`, so that
    each block's sums are matrix products over whole chunks (no scatter per sample).

    Fields: ``index`` (chunks, :data:`BLOCK_CHUNK`) the samples of each chunk, the
    sample count ``n`` (a row of zeros) where a block's last chunk is short; ``block``
    each chunk's block; ``n_blocks`` (static).
    """

    index: Int[Array | np.ndarray, "c m"]
    block: Int[Array | np.ndarray, " c"]
    n_blocks: int = eqx.field(static=True)

    @classmethod
    def of(cls, ids: np.ndarray, n_blocks: int, chunk: int = BLOCK_CHUNK) -> BlockChunks:
        """The chunks of samples whose blocks are ``ids`` (0..``n_blocks``-1)."""
        ids = np.asarray(ids)
        order = np.argsort(ids, kind="stable")
        counts = np.bincount(ids, minlength=n_blocks)
        per = -(-counts // chunk)  # chunks per block
        first = np.concatenate([[0], np.cumsum(per)[:-1]])  # each block's first chunk
        start = np.concatenate([[0], np.cumsum(counts)[:-1]])  # its first sorted sample
        sorted_ids = ids[order]
        slot = first[sorted_ids] * chunk + np.arange(ids.size) - start[sorted_ids]
        index = np.full(int(per.sum()) * chunk, ids.size, np.int32)
        index[slot] = order
        block = np.repeat(np.arange(n_blocks, dtype=np.int32), per)
        return cls(to_device(index.reshape(-1, chunk)), to_device(block), n_blocks)


def block_chunks(prep: Prepared, block_deg: float = BLOCK_DEG) -> BlockChunks:
    """:class:`BlockChunks` of :func:`block_index`, made once per ``prep`` while it lives."""

    def make() -> BlockChunks:
        return BlockChunks.of(*block_index(prep, block_deg))

    return per_object(prep, ("block_chunks", block_deg), make)


def _leverages(
    jtj: np.ndarray, grams: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | str:
    """``d``, ``A^-1/2``, ``A^1/2`` (column-scaled) and the blocks' ``l`` (G, k) and ``V``
    (G, k, k) with ``A^-1/2 A_b A^-1/2 = V_b diag(l_b) V_b^T``; or why not (a reason
    string). The blocks' matrices are decomposed as one stack (a loop over blocks in
    Python cost more than the decompositions)."""
    g = grams.shape[0]
    if g < MIN_BLOCKS:
        return f"{g} blocks for errors='blocks', fewer than {MIN_BLOCKS}"
    d = np.sqrt(np.diag(jtj))
    if not (np.all(np.isfinite(jtj)) and np.all(d > 0) and np.all(np.isfinite(grams))):
        return "J^T J or a block's Gram matrix is not finite, or a column is zero"
    ev, vec = np.linalg.eigh(jtj / np.outer(d, d))
    if ev[0] <= 0.0:
        return "J^T J is singular (errors='blocks')"
    inv_half = vec @ np.diag(ev**-0.5) @ vec.T
    half = vec @ np.diag(ev**0.5) @ vec.T
    lev, v = np.linalg.eigh(inv_half @ (grams / np.outer(d, d)) @ inv_half)
    bad = ~np.all(np.isfinite(lev), axis=1) | (np.max(lev, axis=1) > 1.0 - 1.0 / SINGULAR)
    if np.any(bad):
        b = int(np.argmax(bad))
        return f"block {b} alone identifies a direction of J^T J (errors='blocks')"
    return d, inv_half, half, np.clip(lev, 0.0, None), v


def _spectral(v: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``V_b diag(values_b) V_b^T`` for each block: ``v`` (G, k, k), ``values`` (G, k)."""
    return (v * values[:, None, :]) @ np.swapaxes(v, 1, 2)


def block_covariance(
    jtj: np.ndarray, scores: np.ndarray, grams: np.ndarray, power: float = 0.5
) -> tuple[np.ndarray | None, str | None]:
    """The leverage-corrected cluster covariance and why not, if not.

    ``jtj`` (k, k); ``scores`` (G, k) the blocks' ``J_b^T e_b``; ``grams`` (G, k, k) their
    ``J_b^T J_b``. With ``M_b = A^-1/2 A_b A^-1/2 = V diag(l) V^T`` each block's
    contribution is ``u_b = A^-1/2 V diag((1 - l)^-power) V^T A^-1/2 s_b``: ``power`` 0 is
    the plain cluster sandwich (CR1), 1/2 (default) CR2 (Bell and McCaffrey 2002),
    ``cov = sum u_b u_b^T``; 1 is the one-step cluster jackknife CR3
    (``u_b = (A - A_b)^-1 s_b``), ``cov = (G-1)/G sum u_b u_b^T``. None with a reason below
    :data:`MIN_BLOCKS` blocks or when one block alone identifies a direction (``l`` -> 1).
    """
    parts = _leverages(jtj, grams)
    if isinstance(parts, str):
        return None, parts
    return _cluster_cov(parts, scores, power), None


def _cluster_cov(parts: tuple, scores: np.ndarray, power: float) -> np.ndarray:
    """:func:`block_covariance` from :func:`_leverages`' parts."""
    d, inv_half, _, lev, v = parts
    g = scores.shape[0]
    factor = _spectral(v, (1.0 - lev) ** -power)  # (G, k, k)
    u = (inv_half @ factor @ inv_half @ (scores / d)[:, :, None])[:, :, 0] / d
    cov = u.T @ u * ((g - 1) / g if power == 1.0 else 1.0)
    return 0.5 * (cov + cov.T)


def effective_dof(jtj: np.ndarray, grams: np.ndarray) -> np.ndarray | None:
    """Each scalar's degrees of freedom for its CR2 variance (Bell and McCaffrey 2002).

    The CR2 variance of scalar ``i`` is a quadratic form ``e^T (I-H) G G^T (I-H) e`` in the
    errors, ``G``'s column ``b`` being block ``b``'s rows of ``(I - H_bb)^-1/2 J_b A^-1 c``
    (``c`` the unit vector of ``i``, ``H = J A^-1 J^T``). Under independent errors of one
    variance it is distributed as a weighted sum of chi-squares with weights the
    eigenvalues ``lambda`` of ``B = G^T (I-H) G``, and Satterthwaite's approximation gives
    ``nu = (sum lambda)^2 / sum lambda^2``. ``B`` needs no ``n``-sized matrix: with
    ``q = A^-1/2 c`` and ``M_b = V diag(l) V^T``,
    ``g_b^T g_b = q^T V diag(l / (1 - l)) V^T q`` and
    ``J_b^T g_b = A^1/2 V diag(l / sqrt(1 - l)) V^T q``, so
    ``B = diag(g_b^T g_b) - W A^-1 W^T`` with ``W``'s rows ``J_b^T g_b``. ``nu`` runs from 1
    (one block carries the scalar) to at most ``G``. None where :func:`block_covariance` gives
    no covariance.
    """
    parts = _leverages(jtj, grams)
    return None if isinstance(parts, str) else _dof(parts)


def _dof(parts: tuple) -> np.ndarray:
    """:func:`effective_dof` from :func:`_leverages`' parts."""
    _, inv_half, half, lev, v = parts
    a_inv = inv_half @ inv_half
    gram_terms = _spectral(v, lev / (1.0 - lev))  # (G, k, k)
    cross = half @ _spectral(v, lev / np.sqrt(1.0 - lev))  # (G, k, k)
    q = inv_half  # column i: A^-1/2 c_i
    gg = np.einsum("ai,gab,bi->ig", q, gram_terms, q)  # (k, G)
    w = np.einsum("gab,bi->iga", cross, q)  # (k, G, k)
    b = gg[:, :, None] * np.eye(gg.shape[1]) - w @ a_inv @ np.swapaxes(w, 1, 2)  # (k, G, G)
    lam = np.linalg.eigvalsh(b)
    return lam.sum(axis=1) ** 2 / np.sum(lam**2, axis=1)


def coverage_factor(dof: np.ndarray, level: float = 0.95) -> np.ndarray:
    """``t_q(nu) / z_q``, ``q = (1 + level) / 2``: the factor that widens a normal interval
    into Student's for ``nu`` degrees of freedom (1 for ``nu`` -> inf; 6.5 at ``nu`` = 1)."""
    q = 0.5 * (1.0 + level)
    return stats.t.ppf(q, np.asarray(dof, float)) / stats.norm.ppf(q)


def block_errors(
    jtj: np.ndarray, scores: np.ndarray, grams: np.ndarray, level: float = 0.95
) -> tuple[np.ndarray | None, np.ndarray | None, str | None]:
    """What ``errors="blocks"`` reports: the CR2 covariance widened by each scalar's
    :func:`coverage_factor` at ``level`` (``cov * outer(f, f)``), the degrees of freedom,
    and why not, if not; the blocks' leverages are decomposed once for both."""
    parts = _leverages(jtj, grams)
    if isinstance(parts, str):
        return None, None, parts
    dof = _dof(parts)
    f = coverage_factor(dof, level)
    return _cluster_cov(parts, scores, 0.5) * np.outer(f, f), dof, None
