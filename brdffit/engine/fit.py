"""Fit a model to measurements: starts, one batched bounded LM solve, the result.

:func:`fit` and :func:`fit_many` run the same engine:

1. the candidates of :mod:`brdffit.engine.starts` (the cross-metric start among them) are
   descended by the bounded Levenberg-Marquardt of :mod:`brdffit.engine.lm`, raced by
   successive halving in one compiled call (:func:`brdffit.engine.race.race`), on evenly
   thinned samples when the data are large (:func:`brdffit.engine.batch.coarse_size`);
2. the lowest is finished on all samples;
3. with a robust loss, its scale is set from the plain optimum's residuals, and the
   plain optimum and every candidate are descended again under the robust loss (outliers
   can drag the plain optimum into a corner whose robust descent stays there); the
   lowest robust objective is finished on all samples;
4. :mod:`brdffit.engine.assembly` turns the answer into a :class:`FitResult`, with
   the errors of :mod:`brdffit.engine.uncertainty`.

:func:`fit_many` fits problems of equal shape (materials, texels): on an accelerator it
stacks them and batches every solve over them, on the CPU it runs one problem per core.
Steps 1-3 are :class:`brdffit.engine.batch.Engine`.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.measurements import Measurements
from brdffit.core.result import FitResult
from brdffit.engine import lm, starts
from brdffit.engine import metrics as metrics_mod
from brdffit.engine.assembly import assemble
from brdffit.engine.batch import Engine
from brdffit.engine.block_errors import block_chunks
from brdffit.engine.objective import Objective, freeze_map, start_params
from brdffit.engine.settings import COARSE, Freeze, Settings
from brdffit.engine.uncertainty import resolve
from brdffit.errors import FitError, ParameterError


def fit(
    model: AbstractModel,
    data: Measurements,
    metric: str = "low_e2",
    *,
    init: Mapping[str, object] | None = None,
    freeze: Freeze = None,
    cut_deg: float | None = 80.0,
    n_restarts: int = 1,
    screen: int = 32,
    seed: int = 0,
    max_steps: int = 512,
    ftol: float = 1e-10,
    xtol: float = 1e-10,
    gtol: float = 1e-10,
    errors: str = "auto",
    robust: str | None = None,
    robust_scale: float | None = None,
    coarse: int | None = COARSE,
    throw: bool = True,
) -> FitResult:
    """Fit ``model`` to ``data`` by bounded Levenberg-Marquardt on the residuals of ``metric``.

    Arguments:
    - ``model``: a model from :func:`brdffit.models.get`.
    - ``data``: measurements; only valid samples inside the angle cut are used.
    - ``metric``: ``"ngan"``, ``"low_e1"``, ``"low_e2"`` or ``"log1p_l1"``.
    - ``init``: start values (natural units) for some parameters; others use defaults.
    - ``freeze``: names (frozen at their start value) or name -> value; frozen
      parameters leave the fit and get zero standard error.
    - ``cut_deg``: zenith-angle cut for both directions, degrees (``None``: none).
    - ``n_restarts``: seeded random starts near the first one (:mod:`brdffit.engine.starts`).
    - ``screen``: candidates spread over the nonlinear parameters' ranges; of the
      cheapest few, those with no cheaper candidate near them become starts (one per
      valley). 0 turns the screen off.
    - ``max_steps``: tried LM steps per descent. ``ftol``, ``xtol``, ``gtol``: relative
      stopping tolerances (:mod:`brdffit.engine.lm`).
    - ``errors``: ``"auto"`` (default: ``"blocks"`` for measured data, ``"sandwich"`` for
      :attr:`~brdffit.core.measurements.Measurements.synthetic` data), ``"sandwich"``
      (independent residuals), ``"classic"`` (independent, one variance) or ``"blocks"``
      (model error shared by neighbouring cells, as in measured data; 95% intervals from
      Student's t); :mod:`brdffit.engine.uncertainty`.
    - ``robust``: ``None``, ``"huber"`` or ``"cauchy"``: a robust loss on the metric's
      residuals against outliers; ``robust_scale`` (residual units) defaults to the
      tuning constant (1.345 Huber, 2.385 Cauchy) times 1.4826 MAD of the plain
      optimum's residuals. The reported ``loss`` stays the metric's own value.
    - ``coarse``: the starts run on every k-th sample, at most ``coarse`` of them (and
      at most a ``COARSE_SHARE``-th, a 32nd, of the samples, but not under
      ``COARSE_FLOOR``), and the best one is then finished on all samples (``None``:
      starts on all samples).
      Data are thinned only when that at least halves them
      (:func:`brdffit.engine.batch.coarse_size`).
    - ``throw``: raise :class:`FitError` (carrying the result) if the fit did not converge.

    Returns a :class:`FitResult`; a non-finite or unfinished fit is never marked converged.
    """
    kwargs = dict(
        init=init, freeze=freeze, cut_deg=cut_deg, n_restarts=n_restarts, screen=screen,
        seed=seed, max_steps=max_steps, ftol=ftol, xtol=xtol, gtol=gtol, errors=errors,
        robust=robust, robust_scale=robust_scale, coarse=coarse, throw=throw,
    )  # fmt: skip
    return fit_many(model, [data], metric, **kwargs)[0]


def fit_many(
    model: AbstractModel,
    datasets: Sequence[Measurements],
    metric: str = "low_e2",
    **kwargs,
) -> list[FitResult]:
    """:func:`fit` of one model to many data sets of equal shape; one result each.

    Takes the keyword arguments of :func:`fit`, applied to every data set (``init``,
    ``freeze``, ``seed``: each problem gets the same start policy, so a result equals
    that of :func:`fit` on its data). Every data set must keep the same number of
    samples after the cut (e.g. texels or materials on one MERL grid); their directions
    may differ. ``throw=True`` raises for the first problem, in order, that did not
    converge. Each result's ``wall_time`` is the time from the call to that result.

    On an accelerator the problems are solved as one batch (:func:`_batched`); on the
    CPU, one per core at a time (:func:`_concurrent`).
    """
    t0 = time.perf_counter()
    unknown = sorted(set(kwargs) - {f.name for f in dataclasses.fields(Settings)})
    if unknown:
        raise ParameterError(f"fit_many: unknown keyword(s) {unknown}; see brdffit.fit")
    s = Settings(**kwargs)
    if not datasets:
        raise ParameterError("fit_many: no data set given")
    for d in datasets:
        require_measurements(d)
    m = metrics_mod.get_metric(metric)
    first = start_params(model, s.init)
    obj = Objective.build(model, freeze_map(model, s.freeze, first))
    per = [metrics_mod.prepare_all(d, cut_deg=s.cut_deg) for d in datasets]
    sizes = {p[m.name].n for p in per}
    if len(sizes) > 1:
        names = ", ".join(f"{d.source}: {p[m.name].n}" for d, p in zip(datasets, per, strict=True))
        raise ParameterError(f"fit_many: data sets keep different sample counts ({names})")
    problems = _Batch(obj, s, m, first | obj.frozen, list(datasets), per, t0)
    workers = cores() if lm.batch_size() is None else 0
    results = _concurrent(problems, workers) if workers and len(per) > 1 else _batched(problems)
    for r in results:
        if s.throw and not r.converged:
            raise FitError(f"fit of {model.name} to {r.source}: {r.status.value}", r)
    return results


@dataclasses.dataclass(frozen=True)
class _Batch:
    """What the problems of one :func:`fit_many` call share, and each one's data."""

    obj: Objective
    s: Settings
    m: metrics_mod.Metric
    first: dict
    datasets: list[Measurements]
    per: list[dict[str, metrics_mod.Prepared]]
    t0: float

    def solve(self, rows: Sequence[int]) -> list[FitResult]:
        """The problems ``rows`` solved together (:class:`Engine`), each assembled."""
        other = starts.OTHER_METRIC[self.m.log1p]
        preps = [self.per[i][self.m.name] for i in rows]
        padded = [p.padded() for p in preps]
        engine = Engine(self.obj, self.s, [self.per[i][other] for i in rows])
        chunks = None
        if len(rows) == 1 and self.s.robust is None:
            if resolve(self.s.errors, self.datasets[rows[0]].synthetic) == "blocks":
                chunks = block_chunks(preps[0])
        outcomes = engine.run(preps, padded, self.first, chunks)
        out = []
        for i, o, q in zip(rows, outcomes, padded, strict=True):
            obj = self.obj
            if o.robust_scale is not None:
                obj = obj.with_robust(self.s.robust, o.robust_scale)
            out.append(
                assemble(
                    obj, self.m, o, self.per[i], padded=q, errors=self.s.errors,
                    cut=self.s.cut_deg, source=self.datasets[i].source, t0=self.t0,
                    synthetic=self.datasets[i].synthetic,
                )
            )  # fmt: skip
        return out


def _batched(problems: _Batch) -> list[FitResult]:
    """Every problem in one batched solve: the accelerator runs the batch in parallel
    (``vmap``, :func:`brdffit.engine.lm.batch_size`)."""
    return problems.solve(range(len(problems.per)))


def _concurrent(problems: _Batch, workers: int) -> list[FitResult]:
    """Each problem solved alone, as :func:`fit` solves it, ``workers`` at a time in
    threads.

    On the CPU a batched solve runs its problems one after another inside one program
    (``lax.map``) and saves only the dispatch between fits; it measured 0.86-1.29x a
    loop of fits (``benchmarks/results/fit_many.md``). Problems of a few thousand samples
    leave all but one core idle (XLA splits an operation across threads only when it
    is large), and a fit alternates between the host (holding the GIL) and XLA (not
    holding it), so independent problems run in threads, one per core: 1.4-1.6x a loop
    on this project's 2-core box at 2,000 and 20,000 samples, with the same answers. Each
    thread holds one problem's working set, so memory grows with the cores in use.
    """
    with ThreadPoolExecutor(max_workers=workers) as pool:
        done = pool.map(lambda i: problems.solve([i])[0], range(len(problems.per)))
        return list(done)


def cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def require_measurements(data: object) -> None:
    """Raise :class:`ParameterError` unless ``data`` is :class:`Measurements`, naming the
    NBRDF reader when ``data`` is the network ``read_nbrdf`` returns."""
    if isinstance(data, Measurements):
        return
    hint = (
        " (an NBRDF network: evaluate it with brdffit.io.nbrdf.read_nbrdf_measurements)"
        if type(data).__name__ == "NBRDF"
        else ""
    )
    raise ParameterError(
        f"fit takes Measurements (from a reader or synthesize); got {type(data).__name__}{hint}"
    )
