"""How much a sweep's ranking depends on its grid: two sweeps of the same models compared.

Issue 31, item 4: the 100-material comparison runs on a MERL sub-grid; this measures
what the sub-grid changes. For every (material, metric) that both sweep folders hold,
the models are ranked by the metric as ``brdffit report`` ranks them
(:func:`brdffit.selection.crossrank.matrices`) and the two rankings are compared: Kendall's tau
(scipy), whether the best model is the same, how many of the top three agree, and the
largest move of one model's rank.

Run: python3 benchmarks/compare_sweeps.py SWEEP_A SWEEP_B [--label-a stride] [--label-b full]

Figures: benchmarks/results/sweep.md.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.stats import kendalltau

from brdffit.selection.crossrank import matrices
from brdffit.selection.sweep_results import load_sweep


def compare(a_dir: str, b_dir: str) -> list[dict]:
    """One row per (material, metric) in both sweeps (same models, in ``a``'s order)."""
    a, b = load_sweep(a_dir), load_sweep(b_dir)
    rows = []
    for metric in [m for m in a.metrics if m in b.metrics]:
        ma, mb = matrices(a, metric), matrices(b, metric)
        models = [m for m in ma.models if m in mb.models]
        ja = [ma.models.index(m) for m in models]
        jb = [mb.models.index(m) for m in models]
        for material in [m for m in ma.materials if m in mb.materials]:
            ra = ma.rank[ma.materials.index(material), ja]
            rb = mb.rank[mb.materials.index(material), jb]
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
    args = ap.parse_args()
    rows = compare(args.sweep_a, args.sweep_b)
    print(table(rows, args.label_a, args.label_b))
    taus = [r["tau"] for r in rows]
    same = sum(r["best_a"] == r["best_b"] for r in rows)
    print(
        f"\n{len(rows)} (material, metric) pairs: Kendall tau median {np.median(taus):.3f}, "
        f"min {min(taus):.3f}; same best model in {same}"
    )


if __name__ == "__main__":
    main()
