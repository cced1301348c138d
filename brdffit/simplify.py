"""Leave out what a material does not need: a greedy backward search over model variants.

:func:`simplify` starts from a model with its optional features on and, step by step,
fits every variant one move simpler, keeping the best if the criterion allows it:

* a static boolean option flipped, where that gives strictly fewer parameters (found
  from the model's fields and parameter table, no per-model list: Disney's clear coat,
  sheen, subsurface, anisotropy, metallic, specular tint; Walter's diffuse term,
  specular weight, anisotropy; ...);
* an integer lobe count ``n_...`` lowered by one (Lafortune's and Kurt's ``n_lobes``);
  every lobe is tried as the one dropped and the cheapest start is kept;
* an RGB parameter made grey, one value for the three channels
  (:mod:`brdffit.models._grey`, the spec option ``grey=a+b``).

Each variant starts from its parent's optimum (removed parameters dropped, a grey one
the mean of its channels, a lobe count's later lobes renumbered, a new parameter the
mean of its per-axis parent namesakes such as ``alpha_x``/``alpha_y`` -> ``alpha``), its affine
parameters solved again, then one bounded LM descent: a few fits per step, not a grid.

Criteria:

* ``"cv"`` (default): held-out loss over ``folds`` folds of whole 10-degree
  (theta_h, theta_d) blocks (:func:`brdffit.uncertainty.block_index`), so a held-out
  cell's neighbours, which share its model error, are held out with it. Each fold is
  fitted on the other folds (starting from its parent's fit of the same fold; the start
  model's folds from its all-data optimum) and scored on its own cells; the value is the
  metric of the out-of-fold predictions. A variant is accepted when its held-out loss
  is not worse than that of the best model met so far on the path by more than one
  standard error of the per-fold differences (``n_se`` of them; 1 by default): the
  one-standard-error rule (Breiman,
  Friedman, Olshen, Stone 1984, *Classification and Regression Trees*, sec. 3.4.3;
  Hastie, Tibshirani, Friedman 2009, *Elements of Statistical Learning*, sec. 7.10).
  Against the best rather than the parent, so that small losses do not add up along
  the path.
* ``"bic"``: ``n ln(RSS / n) + (k + 1) ln n`` as :class:`~brdffit.FitResult` reports
  it, ``n`` the residual count (3 per kept sample), ``k`` the free scalars plus the
  noise variance; accepted when not higher. It assumes independent residuals;
  measured residuals are correlated (neighbouring cells share the model's error), so
  the effective ``n`` is far smaller, the log-likelihood gains are overstated against
  the ``ln n`` penalty, and BIC favours big models on measured data.

Among the accepted variants of a step, BIC takes the lowest; CV the one with the fewest
parameters (then the lowest held-out loss), as the one-SE rule prefers the simplest. The
search stops when no simpler variant is accepted. A variant whose fit is not finite is
listed as ``failed`` and never taken.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from brdffit import lm, metrics, models, starts
from brdffit.abstract_model import AbstractModel
from brdffit.errors import ParameterError
from brdffit.fit import fit
from brdffit.measurements import Measurements
from brdffit.models._grey import Grey, make_grey
from brdffit.objective import Objective
from brdffit.result import FitResult, nan_to_none
from brdffit.tables import render
from brdffit.uncertainty import block_index
from brdffit.variants import renumber, rgb_names, scalar_count, start_rows

CRITERIA = ("cv", "bic")


@dataclass(frozen=True)
class PathRow:
    """One fitted variant: search ``step`` (0 the start), its ``label``, the ``change``
    from its parent, ``n_free`` scalars, the metric's in-sample ``loss``, the criterion
    ``value`` (BIC or held-out loss), ``se`` (cv: one standard error of the summed
    held-out difference to the best model so far, in the units of the summed weighted
    squares: those of ``value`` for every metric but ``ngan``, whose value is their
    square root; NaN for bic) and the ``decision``: ``start``, ``kept`` (the feature
    stays: variant rejected), ``removed`` (variant accepted), ``chosen`` (the variant
    the search ends on) or ``failed`` (its fit was not finite)."""

    step: int
    label: str
    change: str
    n_free: int
    loss: float
    value: float
    se: float
    decision: str


@dataclass(frozen=True, eq=False)
class Reduction:
    """What :func:`simplify` found. Fields: ``path`` (rows in search order), ``chosen``
    (label of the chosen variant, a spec every command accepts), ``result`` (its fit on
    all data), ``full`` (the start model's fit), ``cost_ratio`` (jitted evaluation time
    of the chosen over the start model on the data's directions), ``criterion``,
    ``folds`` (0 for bic), ``n_se`` (the CV tolerance in standard errors), ``metric``,
    ``source``."""

    path: tuple[PathRow, ...]
    chosen: str
    result: FitResult
    full: FitResult
    cost_ratio: float
    criterion: str
    folds: int
    n_se: float
    metric: str
    source: str

    def table(self, fmt: str = "text") -> str:
        """The path as a plain-text or Markdown (``fmt="markdown"``) table, with the choice."""
        crit = "BIC" if self.criterion == "bic" else "held-out loss (± 1 SE)"
        head = ["step", "variant", "change", "k", self.metric, crit, "decision"]
        body = [
            [str(r.step), r.label, r.change, str(r.n_free), f"{r.loss:.6g}",
             f"{r.value:.6g}" + ("" if math.isnan(r.se) else f" ± {r.se:.2g}"), r.decision]
            for r in self.path
        ]  # fmt: skip
        how = (
            "BIC, n = residuals (correlated residuals make BIC favour big models)"
            if self.criterion == "bic"
            else f"{self.folds}-fold CV over 10-degree (theta_h, theta_d) blocks, "
            f"{self.n_se:g}-SE rule"
        )
        title = f"Simplify {self.full_label} on {self.source} (metric {self.metric}; {how})"
        tail = (
            f"chosen: {self.chosen} ({self.result.n_free} of {self.full.n_free} parameters, "
            f"evaluation cost x{self.cost_ratio:.2f} of the full model)"
        )
        table = render(head, body, fmt)
        if fmt == "markdown":
            return f"**{title}**\n\n{table}\n\n{tail}"
        return f"{title}\n{table}\n{tail}"

    @property
    def full_label(self) -> str:
        """The start model's label."""
        return models.label(self.full.model, self.full.options)

    def to_dict(self) -> dict:
        """JSON-ready form (both fits as :meth:`FitResult.to_dict`)."""
        return {
            "chosen": self.chosen, "start": self.full_label, "criterion": self.criterion,
            "folds": self.folds, "n_se": self.n_se, "metric": self.metric, "source": self.source,
            "cost_ratio": self.cost_ratio, "path": [dataclasses.asdict(r) for r in self.path],
            "result": self.result.to_dict(), "full": self.full.to_dict(),
        }  # fmt: skip

    def to_json(self, indent: int | None = 2) -> str:
        """The JSON text of :meth:`to_dict` (NaN and Inf written as null)."""
        return json.dumps(nan_to_none(self.to_dict()), indent=indent)

    def plot(self, ax=None, y: str = "value"):
        """Criterion (``y="value"``) or in-sample loss (``y="loss"``) against the parameter
        count: every variant, the accepted path as a line, the chosen variant starred.
        Returns the axes."""
        import matplotlib.pyplot as plt

        if ax is None:
            ax = plt.subplots(figsize=(5.5, 4.0))[1]
        get = (lambda r: r.value) if y == "value" else (lambda r: r.loss)
        ax.plot([r.n_free for r in self.path], [get(r) for r in self.path], "o", color="0.6",
                ms=4, label="variants tried")  # fmt: skip
        walk = [r for r in self.path if r.decision in ("start", "removed", "chosen")]
        ax.plot([r.n_free for r in walk], [get(r) for r in walk], "-", color="C0", label="path")
        pick = next(r for r in self.path if r.decision == "chosen")
        ax.plot([pick.n_free], [get(pick)], "*", color="C3", ms=14, label=pick.label)
        crit = "BIC" if self.criterion == "bic" else f"held-out {self.metric}"
        ax.set_xlabel("free parameters")
        ax.set_ylabel(crit if y == "value" else f"{self.metric} (all data)")
        ax.set_title(f"{self.full_label} on {self.source}", fontsize=9)
        ax.legend(fontsize=8)
        return ax


@dataclass(frozen=True)
class _Node:
    """A fitted variant: model, natural parameters per row (row 0 all data, rows 1.. the
    folds' fits), free scalars, in-sample loss, BIC, held-out sums per fold, the
    criterion's value, and whether every fit stayed finite."""

    model: AbstractModel
    rows: dict[str, np.ndarray]
    n_free: int
    loss: float
    bic: float
    held: np.ndarray  # (folds,) held-out weighted sums
    value: float
    ok: bool


def simplify(
    model: AbstractModel,
    data: Measurements,
    metric: str = "low_e2",
    *,
    criterion: str = "cv",
    folds: int = 5,
    n_se: float = 1.0,
    cut_deg: float | None = 80.0,
    seed: int = 0,
    **fit_kwargs,
) -> Reduction:
    """Greedy backward search for the simplest variant of ``model`` the data support.

    Arguments:
    - ``model``: the start, its optional features on (e.g. ``models.get("disney")``).
    - ``data``, ``metric``, ``cut_deg``, ``seed``: as :func:`brdffit.fit`; ``seed``
      also deals the blocks into folds.
    - ``criterion``: ``"cv"`` or ``"bic"`` (module docstring).
    - ``folds``: cross-validation folds (>= 2; at most the number of blocks).
    - ``n_se``: CV accepts a variant whose held-out loss is worse by at most this many
      standard errors; 1 is the one-SE rule.
    - ``fit_kwargs``: passed to :func:`brdffit.fit` for the start model's fit and
      the chosen one's; ``freeze``, ``robust`` and the tolerances also hold in the search.

    Returns a :class:`Reduction`. Raises :class:`~brdffit.errors.ParameterError` for an
    unknown criterion or a bad fold count.
    """
    if criterion not in CRITERIA:
        raise ParameterError(f"criterion={criterion!r}: use one of {', '.join(CRITERIA)}")
    k_folds = folds if criterion == "cv" else 0
    if criterion == "cv" and (isinstance(folds, bool) or not isinstance(folds, int) or folds < 2):
        raise ParameterError(f"folds={folds!r}: use an integer >= 2")
    if not (isinstance(n_se, int | float) and math.isfinite(n_se) and n_se >= 0):
        raise ParameterError(f"n_se={n_se!r}: use a number >= 0")
    m = metrics.get_metric(metric)
    prep = metrics.prepare(data, m, cut_deg=cut_deg)
    train = np.ones((1 + k_folds, prep.n))
    if k_folds:
        ids, n_blocks = block_index(prep)
        if n_blocks < k_folds:
            raise ParameterError(f"folds={folds}: the data fill only {n_blocks} blocks")
        deal = np.empty(n_blocks, int)
        deal[np.random.default_rng(seed).permutation(n_blocks)] = np.arange(n_blocks) % k_folds
        train[1:] = deal[ids][None, :] != np.arange(k_folds)[:, None]
    full = fit(model, data, metric, cut_deg=cut_deg, seed=seed, **fit_kwargs)
    s = _Search(m, prep, jnp.asarray(train), criterion, n_se, full, fit_kwargs)
    start = {k: np.broadcast_to(v, (len(train),) + np.shape(v)) for k, v in full.params.items()}
    node = s.solve(model, start)
    path = [PathRow(0, models.label(model), "-", node.n_free, node.loss, node.value,
                    math.nan, "start")]  # fmt: skip
    best, step = node, 0
    while True:
        step += 1
        tried = [(s.solve(child, rows), change) for child, rows, change in s.moves(node)]
        scored = [(c, ch, *s.accept(c, node, best)) for c, ch in tried]
        passed = [t for t in scored if t[0].ok and t[2]]
        # BIC: the lowest; CV: the simplest within one SE, then the lowest held-out loss
        rank = (
            (lambda t: t[0].value) if criterion == "bic" else (lambda t: (t[0].n_free, t[0].value))
        )
        pick = min(passed, key=rank)[0] if passed else None
        for c, change, _, se in sorted(scored, key=lambda t: (not t[0].ok, t[0].value)):
            decision = "removed" if c is pick else ("kept" if c.ok else "failed")
            path.append(PathRow(step, models.label(c.model), change, c.n_free, c.loss, c.value,
                                se, decision))  # fmt: skip
        if pick is None:
            break
        node = pick
        best = node if node.value < best.value else best
    chosen = models.label(node.model)
    i = max(i for i, r in enumerate(path) if r.label == chosen and r.decision != "kept")
    path[i] = dataclasses.replace(path[i], decision="chosen")
    result = full
    if node.model != model:
        init = {k: v[0] for k, v in node.rows.items()}
        kw = {**fit_kwargs, "init": init, "screen": 0, "n_restarts": 0}
        kw["freeze"] = s.freeze_names(node.model)
        result = fit(node.model, data, metric, cut_deg=cut_deg, seed=seed, **kw)
    ratio = _eval_time(node.model, result.params, prep) / _eval_time(model, full.params, prep)
    return Reduction(tuple(path), chosen, result, full, ratio, criterion, k_folds, n_se, m.name,
                     data.source)  # fmt: skip


class _Search:
    """The data, folds and settings one search shares; fits and scores variants."""

    def __init__(self, m, prep, train, criterion, n_se, full: FitResult, kw: dict):
        self.m, self.prep, self.train, self.criterion, self.n_se = m, prep, train, criterion, n_se
        self.done: dict[str, _Node] = {}  # label -> fit: a variant reached twice is fitted once
        self.frozen = set(full.frozen)
        self.robust, self.scale = full.robust, full.robust_scale or 1.0
        defaults = lm.Tolerances()
        self.tol = lm.Tolerances(*(kw.get(f.name, getattr(defaults, f.name))
                                   for f in dataclasses.fields(lm.Tolerances)))  # fmt: skip

    def freeze_names(self, model: AbstractModel) -> list[str] | None:
        names = [p.name for p in model.parameters if p.name in self.frozen]
        return names or None

    def solve(self, model: AbstractModel, rows: dict[str, np.ndarray]) -> _Node:
        """Fit ``model`` on every row (all data, then each fold's training cells)."""
        key = models.label(model)
        if key not in self.done:
            self.done[key] = self._solve(model, rows)
        return self.done[key]

    def _solve(self, model: AbstractModel, rows: dict[str, np.ndarray]) -> _Node:
        freeze = {n: rows[n][0] for n in self.freeze_names(model) or ()}
        obj = Objective.build(model, self.m, freeze, self.robust, self.scale)
        lay = obj.layout
        z0 = np.stack([lay.solver_vector({k: v[r] for k, v in rows.items()})
                       for r in range(self.train.shape[0])])  # fmt: skip
        lo, hi = (jnp.asarray(b) for b in lay.solver_bounds())
        z, reason, held, rss, loss = _solve_rows(obj, jnp.asarray(z0), self.prep, self.train,
                                                 lo, hi, self.tol)  # fmt: skip
        out = [obj.params(zr) for zr in z]
        params = {p.name: np.stack([np.asarray(o[p.name]) for o in out]) for p in model.parameters}
        n, k, rss = 3 * self.prep.n, lay.size + 1, max(float(rss[0]), 1e-300)
        bic = n * math.log(rss / n) + k * math.log(n)
        held = np.asarray(held[1:])
        value = (
            bic if self.criterion == "bic" else float(self.m.loss_from_sum(jnp.asarray(held.sum())))
        )
        ok = bool(np.all(np.isfinite(np.asarray(z)))) and math.isfinite(value)
        ok = ok and not np.any(np.asarray(reason) == int(lm.Reason.NONFINITE))
        return _Node(model, params, lay.size, float(loss[0]), bic, held, value, ok)

    def accept(self, child: _Node, parent: _Node, best: _Node) -> tuple[bool, float]:
        """(accepted, one SE of the summed held-out difference to ``best``; NaN for BIC)."""
        if self.criterion == "bic":
            return child.bic <= parent.bic, math.nan
        d = child.held - best.held
        se = float(np.std(d, ddof=1) / math.sqrt(len(d)))
        return bool(np.mean(d) <= self.n_se * se), se * len(d)

    def moves(self, node: _Node):
        """Every variant one move simpler: (model, start rows, change text)."""
        model = node.model
        base, grey = (model.base, model.names) if isinstance(model, Grey) else (model, ())
        size = scalar_count(model)
        opts = base.options()
        for f in dataclasses.fields(base):
            v = getattr(base, f.name)
            if isinstance(v, bool):
                new, change = not v, f"{f.name}={str(not v).lower()}"
            elif isinstance(v, int) and f.name.startswith("n_") and v > 1:
                new, change = v - 1, f"{f.name}={v - 1}"
            else:
                continue
            try:
                child_base = models.get(base.name, **{**opts, f.name: new})
            except ParameterError:
                continue
            drops = range(1, v + 1) if not isinstance(v, bool) else (None,)
            child, rows = self._child(child_base, grey, node.rows, drops)
            if scalar_count(child) < size:
                yield child, rows, change
        for p in model.parameters:
            if p.shape == (3,) and p.name not in self.frozen:
                child = make_grey(model, [p.name])
                yield child, start_rows(child, node.rows, None), f"grey {p.name}"

    def _child(self, child_base, grey, rows, drops) -> tuple[AbstractModel, dict]:
        """``child_base`` with the parent's ``grey`` names that it still has, and its start
        rows; with several lobes to drop (``drops``), the drop whose all-data start costs
        least (a grey lobe's name moves with the lobe)."""
        out = []
        for d in drops:
            names = [renumber(n, d) for n in grey]
            child = make_grey(child_base, [n for n in names if n in rgb_names(child_base)])
            out.append((child, start_rows(child, rows, d)))
        if len(out) == 1:
            return out[0]
        costs = []
        for child, start in out:
            obj = Objective.build(child, self.m)
            z = obj.layout.solver_vector({k: v[0] for k, v in start.items()})
            costs.append(float(_cost(obj, jnp.asarray(z), self.prep)))
        return out[int(np.argmin(np.where(np.isfinite(costs), costs, np.inf)))]


@eqx.filter_jit
def _cost(obj: Objective, z, prep):
    return obj.cost(z, prep)


@eqx.filter_jit
def _solve_rows(obj: Objective, z0, prep: metrics.Prepared, train, lo, hi, tol):
    """One LM descent per row of ``z0`` on the cells ``train`` marks (one compile per
    variant); per row: answer, stop reason, held-out weighted sum, RSS and loss on all."""
    m = obj.metric

    def one(args):
        z, mask = args
        p = dataclasses.replace(prep, weight=prep.weight * mask)
        lin = starts.linear_start(obj, z, p)
        z = jnp.where(obj.cost(lin, p) < obj.cost(z, p), lin, z)
        d = lm.solve(obj, z, p, lo, hi, tol)
        f = obj.model.evaluate(obj.params(d.z), prep.g)
        e = metrics.differences(m, f, prep)
        e = jnp.abs(e) if m.l1 else e * e
        held = jnp.sum((prep.weight * (1.0 - mask))[:, None] * e)
        r = metrics.residuals(m, f, prep)
        return d.z, d.reason, held, jnp.sum(r * r), metrics.loss(m, f, prep)

    return lax.map(one, (z0, train), batch_size=lm.batch_size())


@eqx.filter_jit
def _evaluate(model, params, g):
    return model.evaluate(params, g)


def _eval_time(model: AbstractModel, params: dict, prep: metrics.Prepared) -> float:
    """Best-of-5 seconds of one jitted evaluation on ``prep``'s directions."""
    p = {k: jnp.asarray(v) for k, v in params.items()}
    jax.block_until_ready(_evaluate(model, p, prep.g))
    t0 = time.perf_counter()
    jax.block_until_ready(_evaluate(model, p, prep.g))
    reps = max(1, int(2e-3 / max(time.perf_counter() - t0, 1e-7)))
    best = math.inf
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(reps):
            out = _evaluate(model, p, prep.g)
        jax.block_until_ready(out)
        best = min(best, (time.perf_counter() - t0) / reps)
    return best
