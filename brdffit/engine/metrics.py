"""Fitting metrics: residual vectors for Levenberg-Marquardt and the scalar losses reported.

Every metric compares ``f cos(theta_i)`` of model and data, linearly or through
``ln(1 + x)``, with a per-sample weight (DESIGN.md):

======== ================================================ ===================== ==========
name     loss                                             weight                source
======== ================================================ ===================== ==========
ngan     sqrt(sum w (fm ci - fd ci)^2 / sum w)            w = solid angle       Ngan 2005
low_e1   sum ((fm - fd) ci)^2 sin(theta_i)                sin(theta_i)          Löw 2012
low_e2   sum (ln(1 + fm ci) - ln(1 + fd ci))^2 sin(th_i)  sin(theta_i)          Löw 2012
log1p_l1 mean |ln(1 + fm ci) - ln(1 + fd ci)|             uniform               Sztrajman 2021
======== ================================================ ===================== ==========

Sums and means run over the valid channels of the valid samples
(``Measurements.channel_valid``): a channel a source did not measure has weight 0 and
the normalisations count only the channels fitted, so a table with every channel
valid gives the same numbers as before per-channel masks. Ngan et al. cut
both angles at 80 degrees; here the cut (``cut_deg``, default 80) applies to every
metric and is chosen once, when the data are prepared.

The residuals LM minimises and the exact losses reported are in
:mod:`brdffit.engine.misfit`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import equinox as eqx
import jax
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from brdffit.core.geometry import ShadingGeometry, shading_geometry
from brdffit.core.measurements import Measurements
from brdffit.errors import ParameterError
from brdffit.util.memo import per_object
from brdffit.util.programs import program

L1_DELTA = 1e-3


@dataclass(frozen=True)
class Metric:
    """A named metric: how ``f cos`` is compared, weighted and turned into a loss.

    Fields: ``name``; ``log1p`` compare ``ln(1 + f cos)`` instead of ``f cos``;
    ``weighting`` "solid_angle", "sin_theta_i" or "uniform"; ``l1`` absolute instead
    of squared differences; ``source`` the paper.
    """

    name: str
    log1p: bool
    weighting: Literal["solid_angle", "sin_theta_i", "uniform"]
    l1: bool
    source: str

    def channel_weights(self, data: Measurements, keep: np.ndarray, use: np.ndarray) -> np.ndarray:
        """(len(keep), 3) weights of the samples ``keep`` (indices), 0 where ``use`` (the
        same shape) is False, normalised as the loss needs: ``solid_angle`` to a sum of 3
        (1 per channel, as a mean over channels of normalised sums), ``uniform`` to a sum
        of 1 (a mean over the channels fitted), ``sin_theta_i`` unnormalised."""
        use = np.asarray(use, float)
        if self.weighting == "solid_angle":
            w = data.weights[keep][:, None] * use
            return 3.0 * w / max(np.sum(w), np.finfo(float).tiny)
        if self.weighting == "sin_theta_i":
            return np.sqrt(np.clip(1.0 - data.wi[keep, 2] ** 2, 0.0, None))[:, None] * use
        return use / max(np.sum(use), 1.0)

    @property
    def root(self) -> bool:
        """The loss is the square root of the weighted sum (Ngan's RMS)."""
        return self.name == "ngan"


METRICS: dict[str, Metric] = {
    m.name: m
    for m in (
        Metric("ngan", False, "solid_angle", False, "Ngan, Durand, Matusik 2005"),
        Metric("low_e1", False, "sin_theta_i", False, "Löw et al. 2012, E1"),
        Metric("low_e2", True, "sin_theta_i", False, "Löw et al. 2012, E2"),
        Metric("log1p_l1", True, "uniform", True, "Sztrajman et al. 2021"),
    )
}


def get_metric(name: str) -> Metric:
    """The metric called ``name``; :class:`ParameterError` listing the known ones otherwise."""
    if name not in METRICS:
        raise ParameterError(f"unknown metric {name!r}; known: {', '.join(METRICS)}")
    return METRICS[name]


SHAPE_BITS = 4
"""Significant bits of a padded sample count (:func:`shape_bucket`): at most 1/8 of the
rows a descent evaluates are padding (1/16 on average)."""


def shape_bucket(n: int) -> int:
    """The sample count ``n`` rounded up to ``m 2^e`` with ``2^(SHAPE_BITS-1) < m <=
    2^SHAPE_BITS``.

    XLA compiles one program per array shape, and compiling a fit's descents costs
    seconds (walter's first fit in a fresh process: about 6 s, nearly all of it
    compilation) where running them on 20,000 samples takes 0.2 s. Data of any size in a
    bucket share the programs, padded with rows that add exactly nothing
    (:meth:`Prepared.pad`): materials with different valid cells or a file read at
    another stride compile once per bucket, not once per count (the same idea as padding
    variable-length batches to a few lengths).
    """
    if n <= 1 << SHAPE_BITS:
        return n
    unit = 1 << ((n - 1).bit_length() - SHAPE_BITS)
    return -(-n // unit) * unit


class Prepared(eqx.Module):
    """One data set as one metric sees it: the samples and channels it fits, its weights,
    its data side and how it transforms a model's values; computed once.

    The metric lives here, as data: its switches are arrays, so one compiled solve serves
    every metric (the cross-metric start descends under a second one).

    Fields: ``g`` shading geometry of the kept samples; ``cos_i`` (N,); ``target``
    (N, 3) the data side ``T(f_data cos_i)``; ``weight`` (N, 3) the metric's weight per
    sample and channel, 0 for a channel left out; ``values`` (N, 3) the data in 1/sr
    (0 where left out); ``log1p`` (bool scalar) ``T`` is ``ln(1 + x)``, not ``x``; ``l1``
    absolute differences (LM: the pseudo-Huber surrogate); ``root`` the reported loss is
    the square root of the weighted sum (``ngan``); ``count`` (int scalar) how many of
    the N rows are samples: the rest are padding (:meth:`pad`), after them. ``count`` is
    an array, not a static field, so that data of every count padded to one size share
    a compiled program.
    """

    g: ShadingGeometry
    cos_i: Float[Array, " n"]
    target: Float[Array, "n 3"]
    weight: Float[Array, "n 3"]
    values: Float[Array, "n 3"]
    log1p: Bool[Array | np.ndarray, ""]
    l1: Bool[Array | np.ndarray, ""]
    root: Bool[Array | np.ndarray, ""]
    count: Int[Array | np.ndarray, ""]

    @property
    def n(self) -> int:
        """Number of samples (padding rows not counted)."""
        return int(self.count)

    @property
    def rows(self) -> int:
        """Number of rows of the arrays: the samples and the padding after them."""
        return int(self.cos_i.shape[0])

    def take(self, idx: np.ndarray) -> Prepared:
        """The samples ``idx`` (indices into the samples), same metric (host-side
        indexing: no program compiled per size)."""
        return self._rows(lambda a: np.asarray(a)[idx], len(idx))

    def pad(self, size: int, geometry: Prepared | None = None) -> Prepared:
        """``size`` rows: these and copies of the first sample with weight, data and
        target 0, so every residual and Jacobian row they add is exactly 0 (the model
        is evaluated where the first sample is, so they are finite when it is).

        ``geometry``: the same samples already padded to ``size`` under another metric;
        its directions are shared, not copied again.
        """
        extra = size - self.rows
        if extra <= 0:
            return self
        if geometry is None:
            g, cos_i = jax.tree.map(
                lambda a: to_device(np.concatenate([a, np.repeat(np.asarray(a)[:1], extra, 0)])),
                (self.g, self.cos_i),
            )
        else:
            g, cos_i = geometry.g, geometry.cos_i
        target, weight, values = (
            to_device(np.concatenate([a, np.zeros((extra, 3))]))
            for a in (self.target, self.weight, self.values)
        )
        return Prepared(
            g, cos_i, target, weight, values, self.log1p, self.l1, self.root, self.count
        )

    def padded(self, geometry: Prepared | None = None) -> Prepared:
        """:meth:`pad` to :func:`shape_bucket` of the sample count; computed once per
        :class:`Prepared` (:func:`brdffit.util.memo.per_object`: a sweep fits one data set
        many times). Data from :func:`prepare_all` are padded already: itself."""
        size = shape_bucket(self.n)
        if self.rows >= size:  # itself (kept out of the memo: a value must not hold its owner)
            return self
        return per_object(self, "padded", lambda: self.pad(size, geometry))

    def _rows(self, f, count: int) -> Prepared:
        """Every per-sample array mapped by ``f`` (numpy in, numpy out; ``count`` samples
        in the result), same metric."""
        per_sample = (self.g, self.cos_i, self.target, self.weight, self.values)
        g, cos_i, target, weight, values = jax.tree.map(lambda a: to_device(f(a)), per_sample)
        return Prepared(
            g, cos_i, target, weight, values, self.log1p, self.l1, self.root, _count(count)
        )


def _count(n: int) -> np.ndarray:
    """:attr:`Prepared.count` of ``n`` samples."""
    return np.asarray(n, np.int64)


def keep_mask(data: Measurements, cut_deg: float | None) -> np.ndarray:
    """Valid samples (at least one channel) with both zenith angles below ``cut_deg``
    (None: no cut)."""
    keep = data.valid.copy()
    if cut_deg is not None:
        c = np.cos(np.deg2rad(cut_deg))
        keep &= (data.wi[:, 2] > c) & (data.wo[:, 2] > c)
    return keep


def prepare(
    data: Measurements,
    metric: Metric,
    *,
    cut_deg: float | None = 80.0,
    keep: np.ndarray | None = None,
) -> Prepared:
    """Select the samples and channels a metric sees and precompute everything that
    depends on data only.

    A sample is kept when it is valid and inside the cut; a channel of it is fitted when
    ``data.channel_valid`` says so and, for a log metric, when ``1 + f cos`` exceeds
    :data:`LOG_FLOOR` + 1 (a signed source's rare large negative value lies outside
    ``ln(1 + x)``'s domain: it is left out, never clamped and fitted).
    ``keep`` overrides the sample selection (a boolean mask or indices into ``data``).
    Raises :class:`ParameterError` if no sample is left.
    """
    keep = _keep_indices(data, cut_deg, keep)
    g = _geometry(data.wi[keep], data.wo[keep])
    return _prepared(data, metric, keep, g)


def prepare_all(
    data: Measurements, *, cut_deg: float | None = 80.0, keep: np.ndarray | None = None
) -> dict[str, Prepared]:
    """:func:`prepare` for every metric, sharing one geometry, each padded to
    :func:`shape_bucket` of the sample count (:meth:`Prepared.pad`); name -> Prepared.

    Padded once, here: the descents, the covariance and every metric's loss run on these
    arrays as they are (padding the other three metrics' data in each fit, for their
    losses, copied every full array: 0.05-0.07 s at the full MERL grid). Without
    ``keep``, computed once per data set and cut while the data set lives
    (:func:`brdffit.util.memo.per_object`): every fit of a sweep to one material, and a
    fit's thinned copies of it, reuse the same arrays."""
    if keep is None:
        return per_object(data, ("prepare_all", cut_deg), lambda: _prepare_all(data, cut_deg))
    return _prepare_all(data, cut_deg, keep)


def _prepare_all(
    data: Measurements, cut_deg: float | None, keep: np.ndarray | None = None
) -> dict[str, Prepared]:
    keep = _keep_indices(data, cut_deg, keep)
    rows = np.concatenate([keep, np.repeat(keep[:1], shape_bucket(keep.size) - keep.size)])
    g = _geometry(data.wi[rows], data.wo[rows])
    shared: dict = {}
    return {m.name: _prepared(data, m, keep, g, shared) for m in METRICS.values()}


_geometry = program(shading_geometry)
"""The data's shading geometry as a stored program (:mod:`brdffit.util.programs`);
:func:`brdffit.core.geometry.shading_geometry` itself stays a plain ``jax.jit``, which
JAX's transformations (``vmap``, ``grad`` through the directions) can enter."""


LOG_FLOOR = -0.999
"""Smallest ``f cos`` a log metric fits (``ln(1 + x)`` is -6.9 there; -inf at -1)."""


def channels_used(metric: Metric, values: np.ndarray, cos_i: np.ndarray, valid: np.ndarray):
    """(N, 3) the channels a metric fits: ``valid``, and inside ``ln(1 + x)``'s domain
    (``f cos > LOG_FLOOR``) for a log metric."""
    if not metric.log1p:
        return valid
    return valid & (values * cos_i[:, None] > LOG_FLOOR)


def _keep_indices(data: Measurements, cut_deg: float | None, keep) -> np.ndarray:
    """Indices of the samples kept (``keep`` overrides the mask of :func:`keep_mask`)."""
    keep = np.asarray(keep_mask(data, cut_deg) if keep is None else keep)
    if keep.dtype == bool:
        keep = np.flatnonzero(keep)
    if keep.size == 0:
        raise ParameterError(
            f"{data.source}: no valid sample left for the fit (cut at {cut_deg} degrees)"
        )
    return keep


def _prepared(
    data: Measurements,
    metric: Metric,
    keep: np.ndarray,
    g: ShadingGeometry,
    shared: dict | None = None,
) -> Prepared:
    """:class:`Prepared` of ``metric`` on the samples ``keep`` with geometry ``g``, which
    may have more rows than ``keep`` (padding, :meth:`Prepared.pad`: the data side 0
    there).

    ``shared`` (from :func:`prepare_all`): the channels used, values and target made for
    an earlier metric of the same transform (``f cos`` or ``ln(1 + f cos)``), which this
    one shares as the same arrays: the metrics of one transform differ only in their
    weights and form, so their targets are equal (:func:`brdffit.engine.misfit.losses`
    relies on it), and at the full MERL grid each shared array saves 22 MB of device
    memory per data set."""
    shared = {} if shared is None else shared
    cos_i = np.asarray(g.cos_i)[: keep.size]
    extra = np.zeros((g.cos_i.shape[0] - keep.size, 3))

    def side(a: np.ndarray) -> Array:
        return to_device(np.concatenate([a, extra]) if extra.size else a)

    if metric.log1p not in shared:
        use = channels_used(metric, data.values[keep], cos_i, data.channel_valid[keep])
        values = np.where(use, data.values[keep], 0.0)
        target = side(transform_side(metric, values, cos_i))
        shared[metric.log1p] = (use, side(values), target)
    use, values, target = shared[metric.log1p]
    return Prepared(
        g=g,
        cos_i=g.cos_i,
        target=target,
        weight=side(metric.channel_weights(data, keep, use)),
        values=values,
        log1p=np.asarray(metric.log1p),
        l1=np.asarray(metric.l1),
        root=np.asarray(metric.root),
        count=_count(keep.size),
    )


def to_device(a: np.ndarray) -> Array:
    """A host array put on the default device as it is (``jax.device_put``:
    ``jnp.asarray`` of a NumPy array compiles a small program per shape, some 10 ms
    each in a fresh process)."""
    return jax.device_put(np.asarray(a))


def transform_side(metric: Metric, f: np.ndarray, cos_i: np.ndarray) -> np.ndarray:
    """``f cos_i`` or ``ln(1 + f cos_i)`` (argument floored at :data:`LOG_FLOOR`; the
    data's channels below it are left out by :func:`prepare`); on the host."""
    x = f * cos_i[:, None]
    return np.log1p(np.maximum(x, LOG_FLOOR)) if metric.log1p else x
