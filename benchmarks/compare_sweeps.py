"""How much a sweep's ranking depends on its grid: two sweeps of the same models compared.

Issue 31, item 4: the 100-material comparison runs on a MERL sub-grid; this measures
what the sub-grid changes. For every (material, metric) that both sweep folders hold,
the models are ranked by the metric as ``brdffit report`` ranks them
(:func:`brdffit.selection.crossrank.matrices`) and the two rankings are compared: Kendall's tau
(scipy), whether the best model is the same, how many of the top three agree, and the
largest move of one model's rank.

Each of the two may be a sweep folder or the folder ``brdffit report`` wrote for one
(its ``per_material_<metric>.csv`` tables hold the same ranks), so a sweep whose fit
files were not kept, like the stride sweep in ``benchmarks/results/sweep_nbrdf_s335``,
can still be compared.

Run: python3 benchmarks/compare_sweeps.py SWEEP_A SWEEP_B [--label-a stride] [--label-b full]

Figures: benchmarks/results/sweep.md.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np
from scipy.stats import kendalltau

from brdffit.selection.crossrank import matrices
from brdffit.selection.sweep_results import load_sweep

Ranks = dict[str, dict[str, dict[str, float]]]
"""metric -> material -> model -> rank (1 best, ties shared)."""


def ranks_of(folder: str) -> Ranks:
    """The ranks of a sweep folder, or of a ``brdffit report`` folder's CSV tables."""
    tables = sorted(Path(folder).glob("per_material_*.csv"))
    if tables:
        out: Ranks = {}
        for path in tables:
            metric = path.stem.removeprefix("per_material_")
            with path.open(newline="") as f:
                for row in csv.DictReader(f):
                    out.setdefault(metric, {}).setdefault(row["material"], {})[row["model"]] = (
                        float(row["rank"])
                    )
        return out
    res = load_sweep(folder)
    out = {}
    for metric in res.metrics:
        m = matrices(res, metric)
        out[metric] = {
            material: dict(zip(m.models, map(float, m.rank[i]), strict=True))
            for i, material in enumerate(m.materials)
        }
    return out


def compare(a_dir: str, b_dir: str) -> list[dict]:
    """One row per (material, metric) in both sweeps (the models both hold, in ``a``'s
    order)."""
    a, b = ranks_of(a_dir), ranks_of(b_dir)
    rows = []
    for metric in [m for m in a if m in b]:
        for material in [m for m in a[metric] if m in b[metric]]:
            ma, mb = a[metric][material], b[metric][material]
            models = [m for m in ma if m in mb]
            ra = np.array([ma[m] for m in models])
            rb = np.array([mb[m] for m in models])
            if not (np.isfinite(ra).all() and np.isfinite(rb).all()):
                continue
            tau = kendalltau(ra, rb).statistic
            top_a, top_b = (_top3(models, r) for r in (ra, rb))
            move = int(np.argmax(np.abs(ra - rb)))
            rows.append(
                {
                    "material": material, "metric": metric, "tau": float(tau),
                    "best_a": models[int(np.argmin(ra))], "best_b": models[int(np.argmin(rb))],
                    "top3": len(top_a & top_b), "move": float(abs(ra[move] - rb[move])),
                    "moved": models[move] if ra[move] != rb[move] else "-",
                }
            )  # fmt: skip
    return rows


def _top3(models: list[str], rank: np.ndarray) -> set[str]:
    return set(np.asarray(models)[np.argsort(rank, kind="stable")[:3]])


def model_table(a_dir: str, b_dir: str, label_a: str, label_b: str) -> str:
    """Markdown table per metric and model: mean rank and wins (rank 1, ties included)
    over the materials both sweeps hold, in each sweep, ordered by ``b``'s mean rank."""
    a, b = ranks_of(a_dir), ranks_of(b_dir)
    out = [
        f"| metric | model | mean rank ({label_a}) | mean rank ({label_b}) | change "
        f"| wins ({label_a}) | wins ({label_b}) |",
        "|---|---|---|---|---|---|---|",
    ]
    for metric in [m for m in a if m in b]:
        materials = [m for m in a[metric] if m in b[metric]]
        models = [m for m in a[metric][materials[0]] if m in b[metric][materials[0]]]
        ra = np.array([[a[metric][t][m] for m in models] for t in materials])
        rb = np.array([[b[metric][t][m] for m in models] for t in materials])
        for j in np.argsort(rb.mean(axis=0), kind="stable"):
            out.append(
                f"| {metric} | {models[j]} | {ra[:, j].mean():.2f} | {rb[:, j].mean():.2f} "
                f"| {rb[:, j].mean() - ra[:, j].mean():+.2f} | {int((ra[:, j] == 1).sum())} "
                f"| {int((rb[:, j] == 1).sum())} |"
            )
    return "\n".join(out)


def table(rows: list[dict], label_a: str, label_b: str) -> str:
    """Markdown table of :func:`compare`'s rows."""
    out = [
        f"| material | metric | Kendall tau | best ({label_a}) | best ({label_b}) | top 3 shared "
        "| largest rank move |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        out.append(
            f"| {r['material']} | {r['metric']} | {r['tau']:.3f} | {r['best_a']} | {r['best_b']} "
            f"| {r['top3']}/3 | {r['move']:.1f} ({r['moved']}) |"
        )
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sweep_a")
    ap.add_argument("sweep_b")
    ap.add_argument("--label-a", default="A")
    ap.add_argument("--label-b", default="B")
    ap.add_argument(
        "--models-only", action="store_true", help="only the per-model table, not every pair"
    )
    args = ap.parse_args()
    rows = compare(args.sweep_a, args.sweep_b)
    if not args.models_only:
        print(table(rows, args.label_a, args.label_b), end="\n\n")
    print(model_table(args.sweep_a, args.sweep_b, args.label_a, args.label_b))
    taus = [r["tau"] for r in rows]
    same = sum(r["best_a"] == r["best_b"] for r in rows)
    print(
        f"\n{len(rows)} (material, metric) pairs: Kendall tau median {np.median(taus):.3f}, "
        f"min {min(taus):.3f}; same best model in {same}"
    )


if __name__ == "__main__":
    main()
