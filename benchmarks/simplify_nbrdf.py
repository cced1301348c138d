"""Model reduction on measured stand-ins: :func:`brdffit.simplify` on 24 NBRDF materials.

For 24 materials evenly spread over the sorted list of ``../shared/data/merl_nbrdf``
(the neural reconstructions of the MERL materials, Sztrajman et al. 2021; the same
selection as ``benchmarks/split_halves.py``), each evaluated on the MERL grid at
``--stride`` (default ``5 5 9``: 18 theta_h x 18 theta_d x 20 phi_d bin centres, about
3,000 cells inside the 80-degree cut), the script runs :func:`brdffit.simplify` from
``--model`` (default ``disney``, every optional feature on: 13 free scalars) under
``low_e2`` with its defaults (5-fold CV over (theta_h, theta_d) blocks, a feature stays
when its held-out gain has t > 2.13) and writes one row per material: the chosen
variant, its parameter count, its in-sample loss and held-out loss over the full
model's, the changes taken, and its evaluation cost over the full model's.

NBRDF values carry no measurement noise: what a variant loses is model error, shared
by neighbouring cells, which is why the criterion holds out whole blocks.

Run from the repository root: ``python3 benchmarks/simplify_nbrdf.py [--model disney]
[--stride 5 5 9] [--n 24] [--cache FILE.jsonl] [--md
benchmarks/results/simplify_nbrdf.md]``. With ``--cache`` every material's record is
appended to that file, so a killed run resumes.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from brdffit import enable_compilation_cache, models, simplify  # noqa: E402
from brdffit.io.load import load_measurements  # noqa: E402
from brdffit.selection.families import family_of  # noqa: E402

NBRDF = Path(__file__).resolve().parents[2] / "shared" / "data" / "merl_nbrdf"


def materials(n: int) -> list[Path]:
    """``n`` materials evenly spread over the sorted NBRDF list."""
    files = sorted(NBRDF.glob("*.json"))
    pick = np.unique(np.linspace(0, len(files) - 1, n).round().astype(int))
    return [files[i] for i in pick]


def run_one(path: Path, spec: str, stride: tuple[int, int, int]) -> dict:
    """One reduction; the record the table and the cache keep."""
    data = load_measurements(path, stride=stride)
    t0 = time.perf_counter()
    r = simplify(models.from_spec(spec), data, throw=False)
    start = r.path[0]
    pick = next(row for row in r.path if row.decision == "chosen")
    return {
        "material": path.stem, "family": family_of(path.stem), "start": r.full_label,
        "chosen": r.chosen, "n_free": r.result.n_free, "n_free_full": r.full.n_free,
        "loss_ratio": r.loss_ratio, "held_ratio": pick.value / start.value,
        "removed": list(r.removed), "cost_ratio": r.cost_ratio,
        "converged": r.result.converged, "wall_s": time.perf_counter() - t0,
    }  # fmt: skip


def table(records: list[dict]) -> str:
    """The Markdown table, one row per material, and the count of each change taken."""
    head = "| material | family | chosen variant | k | loss vs full | held-out vs full | changes taken | eval cost vs full |"  # noqa: E501
    lines = [head, "|---|---|---|---|---|---|---|---|"]
    for r in records:
        lines.append(
            f"| {r['material']} | {r['family']} | `{r['chosen']}` | {r['n_free']} of "
            f"{r['n_free_full']} | {r['loss_ratio']:.4f} | {r['held_ratio']:.4f} | "
            f"{'; '.join(r['removed']) or '-'} | {r['cost_ratio']:.2f} |"
        )
    counts: dict[str, int] = {}
    for r in records:
        for change in r["removed"]:
            for part in change.split(" + "):
                counts[part] = counts.get(part, 0) + 1
    tally = ", ".join(f"{k} {v}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1]))
    k = [r["n_free"] for r in records]
    return (
        "\n".join(lines)
        + f"\n\nChanges taken over {len(records)} materials: {tally or 'none'}. Parameters "
        f"kept: median {np.median(k):.0f} of {records[0]['n_free_full']}."
    )


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default="disney")
    p.add_argument("--stride", type=int, nargs=3, default=(5, 5, 9))
    p.add_argument("--n", type=int, default=24)
    p.add_argument("--cache", default=None, help="JSON lines of finished materials (resume)")
    p.add_argument("--md", default=None, help="write the table (Markdown) here")
    a = p.parse_args(argv)
    enable_compilation_cache()
    cache = Path(a.cache) if a.cache else None
    done = {}
    if cache is not None and cache.exists():
        for line in cache.read_text().splitlines():
            rec = json.loads(line)
            done[(rec["material"], rec["start"])] = rec
    label = models.label(models.from_spec(a.model))
    t0 = time.perf_counter()
    records = []
    for path in materials(a.n):
        rec = done.get((path.stem, label))
        if rec is None:
            rec = run_one(path, a.model, tuple(a.stride))
            if cache is not None:
                with cache.open("a") as fh:
                    fh.write(json.dumps(rec) + "\n")
            print(f"{path.stem}: {rec['chosen']} ({rec['wall_s']:.1f} s)", flush=True)
        records.append(rec)
    import jax

    header = (
        f"# Model reduction on {len(records)} NBRDF materials: {label}, low_e2, cv\n\n"
        f"Command: `python3 benchmarks/simplify_nbrdf.py --model {a.model} --stride "
        f"{' '.join(map(str, a.stride))} --n {a.n}`. Machine: {platform.machine()}, jax "
        f"{jax.__version__}, {jax.default_backend()}; {time.perf_counter() - t0:.0f} s "
        f"wall for the materials not cached (searches: median "
        f"{np.median([r['wall_s'] for r in records]):.0f} s).\n\n"
        "k: free scalars of the chosen variant and of the full model; loss vs full: the "
        "chosen variant's in-sample low_e2 over the full model's (>= 1: the full model "
        "nests it); held-out vs full: the same for the 5-fold held-out loss; eval cost: "
        "jitted evaluation time on the data's directions over the full model's."
    )
    text = f"{header}\n\n{table(records)}\n"
    print(text)
    if a.md:
        Path(a.md).write_text(text)


if __name__ == "__main__":
    main()
