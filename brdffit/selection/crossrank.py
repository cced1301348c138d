"""Ranking of models across many materials, from a sweep folder's JSON files alone.

Per material, the models fitted under one metric are ranked as :func:`brdffit.rank`
does (by the metric value, losses within a relative :data:`~brdffit.selection.rank.LOSS_RTOL`
tied and given their average rank; AIC and BIC ranks beside it; a fit that did not
converge ranked by the finite loss it reached and marked, failed and missing fits
last). Over all materials each model gets its mean rank, its wins (materials where
it ranks first; a tie for first is a win for every tied model, so wins can add up to
more than the number of materials) and its median relative error ``loss / best loss on
that material - 1``, each with a 95% percentile bootstrap interval
over materials (``numpy.random.default_rng(seed)``, materials drawn with replacement).
A model is named by its label (:func:`brdffit.models.label`), so each variant of a model
(``lafortune[n_lobes=2]``) ranks as a model of its own. Families come from a
``families`` mapping (a user's file, :func:`brdffit.selection.families.read_families`), else the
sweep manifest, else :func:`brdffit.selection.families.family_of`.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from brdffit.core.result import loss_kind, per_sample
from brdffit.errors import SweepError
from brdffit.selection.families import FAMILIES, family_of
from brdffit.selection.rank import LOSS_RTOL, rank_text, ranks
from brdffit.util.text_table import render


@dataclass(frozen=True)
class Record:
    """One result file of a sweep, the fields the ranking and the Pareto study read.

    ``loss`` is the value of ``metric`` (the one fitted), ``losses`` every metric on
    the same samples; ``wall_time`` in s; ``eval_ns`` ns per sample (``nan`` if not
    timed); ``status`` the :class:`brdffit.Status` name; ``provenance`` a short label
    of the code and device that computed it (``"unrecorded"`` in older sweeps).
    ``model`` is the label of the fitted variant (``walter``, ``lafortune[n_lobes=2]``),
    the result file's ``label`` (older sweeps, default options only: its ``model``).
    """

    material: str
    family: str
    model: str
    metric: str
    loss: float
    losses: dict
    aic: float
    bic: float
    n_free: int
    converged: bool
    status: str
    wall_time: float
    eval_ns: float
    provenance: str = "unrecorded"
    loss_per_sample: float = math.nan


@dataclass(frozen=True)
class SweepResults:
    """A sweep folder read back: manifest, results (sorted), recorded errors, and the
    result files that could not be read (``unreadable``: (path relative to the folder,
    why) pairs; the report lists them and goes on without them)."""

    manifest: dict
    records: tuple[Record, ...]
    errors: tuple[dict, ...]
    families: dict = field(default_factory=dict)
    unreadable: tuple[tuple[str, str], ...] = ()

    @property
    def materials(self) -> list[str]:
        """Materials of the manifest, in its order."""
        return list(self.manifest["materials"])

    @property
    def models(self) -> list[str]:
        """Model labels of the manifest, in its order."""
        return list(self.manifest["models"])

    @property
    def metrics(self) -> list[str]:
        """Metrics of the manifest, in its order."""
        return list(self.manifest["metrics"])

    def family(self, material: str) -> str:
        """Family from ``families`` (a user's file), else the manifest, else the name."""
        if material in self.families:
            return self.families[material]
        m = self.manifest["materials"].get(material, {})
        return m.get("family") or family_of(material)


def provenance_label(d: dict | None) -> str:
    """``brdffit 0.1.0 (git f1ea536), jax 0.10.2 on cpu (cpu)`` from a result's provenance."""
    if not d:
        return "unrecorded"
    return (
        f"brdffit {d.get('brdffit')} (git {d.get('git')}), jax {d.get('jax')} "
        f"on {d.get('backend')} ({d.get('device')})"
    )


def _record_family(d: dict, families: dict[str, str]) -> str:
    return families.get(d["material"]) or d.get("family") or family_of(d["material"])


def _num(x: object) -> float:
    return float("nan") if x is None else float(x)


def load_sweep(
    sweep_dir: str | os.PathLike[str], families: dict[str, str] | None = None
) -> SweepResults:
    """Read ``sweep.json`` and every ``<material>/<label>__<metric>[.error].json``.

    ``families``: material -> family, replacing the recorded ones for those materials.
    A result file that does not parse or lacks a field (truncated, foreign) is skipped
    and listed in ``unreadable``. Raises :class:`SweepError` when ``sweep.json`` is
    missing or is not a sweep manifest.
    """
    families = dict(families or {})
    root = Path(sweep_dir)
    try:
        manifest = json.loads((root / "sweep.json").read_text())
    except (OSError, ValueError) as e:
        raise SweepError(f"{root}: not a sweep folder (sweep.json: {e})") from e
    if not (
        isinstance(manifest, dict)
        and isinstance(manifest.get("materials"), dict)
        and isinstance(manifest.get("settings"), dict)
        and all(isinstance(manifest.get(k), dict | list) for k in ("models", "metrics"))
    ):
        raise SweepError(
            f"{root / 'sweep.json'}: not a sweep manifest (expected an object with "
            "materials, models, metrics and settings)"
        )
    records, errors, unreadable = [], [], []
    for p in sorted(root.glob("*/*.json")):
        try:
            d = json.loads(p.read_text())
            if not isinstance(d, dict):
                raise TypeError(f"a JSON {type(d).__name__}, not an object")
            if p.name.endswith(".error.json"):
                missing = [k for k in ("material", "model", "metric", "error") if k not in d]
                if missing:
                    raise KeyError(", ".join(missing))
                errors.append(d)
            else:
                records.append(_record(d, families))
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
            why = f"missing field {e}" if isinstance(e, KeyError) else str(e) or type(e).__name__
            unreadable.append((str(p.relative_to(root)), " ".join(why.split())))
    return SweepResults(manifest, tuple(records), tuple(errors), families, tuple(unreadable))


def _record(d: dict, families: dict[str, str]) -> Record:
    """The :class:`Record` of a result file's JSON object (``KeyError`` for a missing
    field, ``ValueError``/``TypeError`` for a value of the wrong kind)."""
    for key in ("material", "metric"):
        if not isinstance(d[key], str):
            raise TypeError(f"field {key!r} is {d[key]!r}, not a string")
    return Record(
        material=d["material"],
        family=_record_family(d, families),
        model=str(d.get("label") or d["model"]),
        metric=d["metric"],
        loss=_num(d["loss"]),
        losses={k: _num(v) for k, v in d.get("losses", {}).items()},
        aic=_num(d.get("aic")),
        bic=_num(d.get("bic")),
        n_free=int(d.get("n_free", 0)),
        converged=bool(d.get("converged", False)),
        status=str(d.get("status", "")),
        wall_time=_num(d.get("wall_time")),
        eval_ns=_num(d.get("eval_ns_per_sample")),
        provenance=provenance_label(d.get("provenance")),
        loss_per_sample=per_sample(d["metric"], _num(d["loss"]), d.get("n_samples", 0)),
    )


@dataclass(frozen=True)
class Matrices:
    """Materials x models arrays for one metric (NaN where missing or failed).

    ``loss``, ``loss_per_sample``, ``aic``, ``bic``, ``rel`` (loss / best - 1); ``rank``,
    ``rank_aic``, ``rank_bic`` (1 = best, ties share their average rank, a fit that did
    not converge ranked by its finite loss, missing and failed ranked last; module
    docstring); ``win`` (bool: a finite loss tied for the best); ``converged`` (bool: a
    fit exists and converged; a finite loss where it is False is marked not converged).
    """

    metric: str
    materials: tuple[str, ...]
    families: tuple[str, ...]
    models: tuple[str, ...]
    loss: np.ndarray
    aic: np.ndarray
    bic: np.ndarray
    rel: np.ndarray
    rank: np.ndarray
    rank_aic: np.ndarray
    rank_bic: np.ndarray
    win: np.ndarray
    loss_per_sample: np.ndarray | None = None
    converged: np.ndarray | None = None


def matrices(res: SweepResults, metric: str) -> Matrices:
    """The per-material values and ranks of every model under ``metric``."""
    if metric not in res.metrics:
        raise SweepError(f"metric {metric!r} is not in this sweep ({', '.join(res.metrics)})")
    mats, mods = res.materials, res.models
    shape = (len(mats), len(mods))
    loss, aic, bic, per = (np.full(shape, np.nan) for _ in range(4))
    ok = np.zeros(shape, bool)
    im, jm = {m: i for i, m in enumerate(mats)}, {m: j for j, m in enumerate(mods)}
    for r in res.records:
        if r.metric == metric and math.isfinite(r.loss) and r.material in im and r.model in jm:
            i, j = im[r.material], jm[r.model]
            loss[i, j], aic[i, j], bic[i, j] = r.loss, r.aic, r.bic
            per[i, j], ok[i, j] = r.loss_per_sample, r.converged
    best = np.array([np.nanmin(row) if np.isfinite(row).any() else np.nan for row in loss])
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = loss / best[:, None] - 1.0
    rank = np.array([ranks(row, LOSS_RTOL) for row in loss]).reshape(shape)
    first = rank.min(axis=1, keepdims=True) if mods else rank
    return Matrices(
        metric,
        tuple(mats),
        tuple(res.family(m) for m in mats),
        tuple(mods),
        loss,
        aic,
        bic,
        rel,
        rank,
        np.array([ranks(row) for row in aic]).reshape(shape),
        np.array([ranks(row) for row in bic]).reshape(shape),
        np.isfinite(loss) & (rank == first),
        per,
        ok,
    )


@dataclass(frozen=True)
class AggregateRow:
    """One model over all materials; each ``(lo, hi)`` is a 95% bootstrap interval.

    ``n_materials`` counts the materials with a finite loss, ``n_unconverged`` those of
    them whose fit did not converge (ranked by the loss it reached).
    """

    model: str
    mean_rank: float
    mean_rank_ci: tuple[float, float]
    wins: int
    wins_ci: tuple[float, float]
    median_rel_err: float
    median_rel_err_ci: tuple[float, float]
    n_materials: int
    n_unconverged: int = 0


def _stats(rank: np.ndarray, win: np.ndarray, rel: np.ndarray, axis: int):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns -> NaN
        return rank.mean(axis), win.sum(axis), np.nanmedian(rel, axis)


def aggregate(mx: Matrices, *, n_boot: int = 1000, seed: int = 0) -> tuple[AggregateRow, ...]:
    """Mean rank, wins and median relative error per model, best mean rank first.

    A tie for first counts as a win for each tied model (module docstring).
    """
    n = len(mx.materials)
    mean, wins, med = _stats(mx.rank, mx.win, mx.rel, 0)
    idx = np.random.default_rng(seed).integers(0, n, (n_boot, n))
    b_mean, b_wins, b_med = _stats(mx.rank[idx], mx.win[idx], mx.rel[idx], 1)

    def ci(b: np.ndarray, j: int) -> tuple[float, float]:
        col = b[:, j][np.isfinite(b[:, j])]
        if col.size == 0:
            return (math.nan, math.nan)
        return tuple(float(x) for x in np.percentile(col, [2.5, 97.5]))

    rows = [
        AggregateRow(
            model=m,
            mean_rank=float(mean[j]),
            mean_rank_ci=ci(b_mean, j),
            wins=int(wins[j]),
            wins_ci=ci(b_wins.astype(float), j),
            median_rel_err=float(med[j]),
            median_rel_err_ci=ci(b_med, j),
            n_materials=int(np.isfinite(mx.loss[:, j]).sum()),
            n_unconverged=_n_unconverged(mx, j),
        )
        for j, m in enumerate(mx.models)
    ]
    return tuple(sorted(rows, key=lambda r: (r.mean_rank, r.model)))


def _n_unconverged(mx: Matrices, j: int) -> int:
    if mx.converged is None:
        return 0
    return int((np.isfinite(mx.loss[:, j]) & ~mx.converged[:, j]).sum())


def aggregate_table(rows: tuple[AggregateRow, ...], fmt: str = "markdown") -> str:
    """The aggregate ranking as a Markdown (``fmt="markdown"``) or CSV table."""
    if fmt == "csv":
        head = ["model", "mean_rank", "mean_rank_lo", "mean_rank_hi", "wins", "wins_lo"]
        head += ["wins_hi", "median_rel_err", "median_rel_err_lo", "median_rel_err_hi", "n"]
        head += ["n_unconverged"]
        body = [
            [r.model, f"{r.mean_rank:.6g}", *(f"{x:.6g}" for x in r.mean_rank_ci), str(r.wins)]
            + [f"{x:.6g}" for x in (*r.wins_ci, r.median_rel_err, *r.median_rel_err_ci)]
            + [str(r.n_materials), str(r.n_unconverged)]
            for r in rows
        ]
        return render(head, body, "csv")
    head = ["model", "mean rank [95% CI]", "wins [95% CI]", "median rel. error [95% CI]", "n"]
    body = [
        [
            r.model,
            f"{r.mean_rank:.2f} [{r.mean_rank_ci[0]:.2f}, {r.mean_rank_ci[1]:.2f}]",
            f"{r.wins} [{r.wins_ci[0]:.0f}, {r.wins_ci[1]:.0f}]",
            f"{r.median_rel_err:.3g} [{r.median_rel_err_ci[0]:.3g}, {r.median_rel_err_ci[1]:.3g}]",
            f"{r.n_materials}" + (f" ({r.n_unconverged} not converged)" if r.n_unconverged else ""),
        ]
        for r in rows
    ]
    return render(head, body, "markdown")


def per_material_table(mx: Matrices, fmt: str = "markdown") -> str:
    """Every (material, model): metric value (as defined, and per sample), AIC, BIC,
    their ranks, relative error, and whether the fit converged (``no``: ranked by the
    loss it reached; ``-``: no result)."""
    kind = loss_kind(mx.metric)
    head = ["material", "family", "model", f"{mx.metric} ({kind})", "per sample", "AIC", "BIC"]
    head += ["rank", "rank AIC", "rank BIC", "rel. error", "converged"]
    per = mx.loss_per_sample if mx.loss_per_sample is not None else np.full_like(mx.loss, np.nan)
    body = []
    for i, mat in enumerate(mx.materials):
        for j in np.argsort(mx.rank[i], kind="stable"):
            vals = (mx.loss[i, j], per[i, j], mx.aic[i, j], mx.bic[i, j])
            body.append(
                [mat, mx.families[i], mx.models[j], *(f"{v:.6g}" for v in vals)]
                + [rank_text(x) for x in (mx.rank[i, j], mx.rank_aic[i, j], mx.rank_bic[i, j])]
                + [f"{mx.rel[i, j]:.4g}", _converged_text(mx, i, int(j))]
            )
    return render(head, body, fmt)


def _converged_text(mx: Matrices, i: int, j: int) -> str:
    if not np.isfinite(mx.loss[i, j]):
        return "-"
    return "yes" if mx.converged is None or mx.converged[i, j] else "no"


def family_table(mx: Matrices, fmt: str = "markdown", top: int = 3) -> str:
    """Per material family: its size and the ``top`` models by mean rank over its materials.

    Mean ranks are those of :attr:`Matrices.rank` (ties averaged, unconverged last),
    so a model's place within a family reads like the overall ranking.
    """
    head = ["family", "n", *(f"#{k + 1} (mean rank)" for k in range(top))]
    body = []
    for fam in sorted(set(mx.families)):
        rows = np.array([f == fam for f in mx.families])
        mean = mx.rank[rows].mean(axis=0)
        best = np.argsort(mean, kind="stable")[:top]
        cells = [f"{mx.models[j]} ({mean[j]:.2f})" for j in best]
        body.append([fam, str(int(rows.sum())), *cells, *[""] * (top - len(cells))])
    return render(head, body, fmt)


def cluster_order(vectors: np.ndarray) -> np.ndarray:
    """Row order putting similar rows next to each other; fewer than 3 rows keep their order.

    Average-linkage hierarchical clustering of the rows (Euclidean distance), leaves
    ordered by ``scipy.cluster.hierarchy.optimal_leaf_ordering`` (adjacent rows as close
    as the tree allows), the order turned so that it starts at the end holding the lower
    original index, and runs of identical rows kept in their original order.
    Deterministic: the same rows give the same order.
    """
    n = len(vectors)
    if n < 3:
        return np.arange(n)
    from scipy.cluster.hierarchy import leaves_list, linkage, optimal_leaf_ordering

    x = np.asarray(vectors, float)
    tree = optimal_leaf_ordering(linkage(x, method="average", metric="euclidean"), x)
    order = leaves_list(tree)
    order = list(order if order[0] < order[-1] else order[::-1])
    start = 0
    for pos in range(1, n + 1):  # runs of identical rows in their original order
        if pos == n or not np.array_equal(x[order[pos]], x[order[start]]):
            order[start:pos] = sorted(order[start:pos])
            start = pos
    return np.array(order, int)


def material_order(mx: Matrices) -> np.ndarray:
    """Row order grouping materials by family (family order of :data:`FAMILIES`).

    Inside a family the materials follow :func:`cluster_order` of their rank vectors
    (``mx.rank`` rows), so materials that rank the models alike sit together; a family
    of fewer than 3 materials keeps the manifest order.
    """
    fam = {f: k for k, f in enumerate(FAMILIES)}
    groups: dict[str, list[int]] = {}
    for i in sorted(range(len(mx.materials)), key=lambda i: (fam.get(mx.families[i], 99), i)):
        groups.setdefault(mx.families[i], []).append(i)
    out = [np.array(g)[cluster_order(mx.rank[g])] for g in groups.values()]
    return np.concatenate(out).astype(int) if out else np.zeros(0, int)


def rank_matrix_figure(mx: Matrices, rows: tuple[AggregateRow, ...] | None = None):
    """Image of ranks, materials (:func:`material_order`) x models (best mean rank first).

    A rank reached by a fit that did not converge is marked ``*``. The figure is sized
    from its labels (constrained layout; the image at least 2.2 in tall, so the colour
    bar holds its label), so no label is cut off.
    """
    import matplotlib.pyplot as plt

    order = material_order(mx)
    cols = [mx.models.index(r.model) for r in (rows or aggregate(mx, n_boot=1))]
    img = mx.rank[np.ix_(order, cols)]
    n, k = img.shape
    ylabels = [f"{mx.families[i]}: {mx.materials[i]}" for i in order]
    xlabels = [mx.models[c] for c in cols]
    y_room, x_room = (0.06 * max(map(len, lab), default=0) for lab in (ylabels, xlabels))
    size = (1.9 + 0.55 * k + y_room, 1.1 + max(0.25 * n, 2.2) + 0.87 * x_room)
    fig, ax = plt.subplots(figsize=size, layout="constrained")
    im = ax.imshow(img, cmap="viridis_r", aspect="auto", vmin=1, vmax=max(k, 2))
    ax.set_xticks(range(k), xlabels, rotation=60, ha="right", rotation_mode="anchor", fontsize=8)
    ax.set_yticks(range(n), ylabels, fontsize=7)
    fams = [mx.families[i] for i in order]
    for y in range(1, n):
        if fams[y] != fams[y - 1]:
            ax.axhline(y - 0.5, color="w", lw=2)
    ok = np.ones_like(img, bool) if mx.converged is None else mx.converged[np.ix_(order, cols)]
    unconverged = np.isfinite(mx.loss[np.ix_(order, cols)]) & ~ok
    if n * k <= 400:
        for y in range(n):
            for x in range(k):
                c = "k" if img[y, x] <= (k + 1) / 2 else "w"
                t = rank_text(img[y, x]) + ("*" if unconverged[y, x] else "")
                ax.text(x, y, t, ha="center", va="center", fontsize=7, color=c)
    fig.colorbar(im, ax=ax, label="rank (1 = best)")
    note = "; * not converged" if unconverged.any() else ""
    ax.set_title(f"rank by {mx.metric} per material{note}", fontsize=10)
    return fig
