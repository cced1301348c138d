"""Every model x both metrics x four NBRDF materials at full resolution: converged, time, memory.

Issue 28, item 2: every model should fit every material on the full MERL grid
(1,458,000 cells; those inside the 80-degree cut are fitted) within 4 GB and 60 s warm.
Each cell of the table is one subprocess (so its peak memory is its own): it reads the
material (cached once per material as a pickle of the :class:`~brdffit.Measurements`, so
the NBRDF network is evaluated once), runs ``brdffit.fit(model, data, metric)`` with its
defaults twice, and reports the status of the second (warm) fit, its steps, loss and wall
time, the first call's time (compile included) and the process's peak resident memory
(``ru_maxrss``: data, compiled code and the fit's arrays together). A cell that runs past
``--timeout`` seconds is killed and recorded as such.

Run (nice: the box is shared):
    nice python3 benchmarks/full_resolution.py [--models sgd low ...] [--metrics low_e2 ngan]
        [--materials chrome-steel blue-metallic-paint green-plastic beige-fabric]
        [--timeout 900] [--out /tmp/brdffit_full_resolution/rows.jsonl]

Rows are appended to ``--out`` as JSON lines as they finish (a rerun skips cells already
there), and the markdown table of every row so far is printed at the end. The NBRDF
files are read from ``$BRDFFIT_NBRDF`` (default ``/work/shared/data/merl_nbrdf``).

Latest figures: benchmarks/results/full_resolution.md.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

MATERIALS = ("chrome-steel", "blue-metallic-paint", "green-plastic", "beige-fabric")
METRICS = ("low_e2", "ngan")
NBRDF = Path(os.environ.get("BRDFFIT_NBRDF", "/work/shared/data/merl_nbrdf"))
CACHE = Path(tempfile.gettempdir()) / "brdffit_full_resolution"


def cached(material: str) -> Path:
    """Path of the pickled full-resolution Measurements of ``material`` (made once)."""
    path = CACHE / f"{material}.pkl"
    if not path.exists():
        from brdffit.loading import load_measurements

        CACHE.mkdir(exist_ok=True)
        data = load_measurements(NBRDF / f"{material}.json")
        tmp = path.with_suffix(".tmp")
        tmp.write_bytes(pickle.dumps(data))
        tmp.replace(path)
    return path


def one_cell(model_name: str, metric: str, material: str) -> dict:
    """Fit once cold and once warm in this process; the row of the table."""
    from brdffit import fit, models

    data = pickle.loads(cached(material).read_bytes())
    model = models.get(model_name)
    t0 = time.perf_counter()
    fit(model, data, metric, throw=False)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    r = fit(model, data, metric, throw=False)
    warm = time.perf_counter() - t0
    return {
        "model": model_name,
        "metric": metric,
        "material": material,
        "status": r.status.name,
        "steps": r.n_steps,
        "loss": r.loss,
        "first_s": first,
        "warm_s": warm,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "n_data": r.n_data,
    }


def run_cell(model_name: str, metric: str, material: str, timeout: float) -> dict:
    """:func:`one_cell` in a subprocess; a crash or a timeout becomes a row too."""
    cmd = [sys.executable, __file__, "--cell", model_name, metric, material]
    row = {"model": model_name, "metric": metric, "material": material}
    t0 = time.perf_counter()
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return row | {"status": f"KILLED after {timeout:.0f} s"}
    last = out.stdout.strip().splitlines()[-1:] or [""]
    if out.returncode != 0 or not last[0].startswith("{"):
        err = (out.stderr.strip().splitlines() or ["?"])[-1][:160]
        return row | {"status": f"ERROR rc={out.returncode}: {err}",
                      "first_s": time.perf_counter() - t0}  # fmt: skip
    return json.loads(last[0])


def table(rows: list[dict]) -> str:
    """Markdown table of the rows (model, metric, material order as given)."""
    lines = [
        "| model | metric | material | status | steps | warm s | first s | peak MB | loss |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:

        def num(key: str, fmt: str, r: dict = r) -> str:
            return fmt.format(r[key]) if key in r else "-"

        lines.append(
            f"| {r['model']} | {r['metric']} | {r['material']} | {r['status']} | "
            f"{num('steps', '{}')} | {num('warm_s', '{:.1f}')} | {num('first_s', '{:.1f}')} | "
            f"{num('peak_mb', '{:.0f}')} | {num('loss', '{:.4g}')} |"
        )
    return "\n".join(lines)


def main() -> None:
    from brdffit import models

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cell", nargs=3, metavar=("MODEL", "METRIC", "MATERIAL"))
    ap.add_argument("--models", nargs="+", default=models.available())
    ap.add_argument("--metrics", nargs="+", default=list(METRICS))
    ap.add_argument("--materials", nargs="+", default=list(MATERIALS))
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--out", default=str(CACHE / "rows.jsonl"))
    args = ap.parse_args()
    if args.cell:
        print(json.dumps(one_cell(*args.cell)), flush=True)
        return
    out = Path(args.out)
    done = {}
    if out.exists():
        for line in out.read_text().splitlines():
            r = json.loads(line)
            done[(r["model"], r["metric"], r["material"])] = r
    for material in args.materials:
        cached(material)
    rows = []
    for name in args.models:
        for material in args.materials:
            for metric in args.metrics:
                key = (name, metric, material)
                if key not in done:
                    done[key] = run_cell(name, metric, material, args.timeout)
                    with out.open("a") as f:
                        f.write(json.dumps(done[key]) + "\n")
                    print(table([done[key]]).splitlines()[-1], flush=True)
                rows.append(done[key])
    print(table(rows))


if __name__ == "__main__":
    main()
