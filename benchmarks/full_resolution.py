"""Every model x both metrics x four NBRDF materials at full resolution: converged, time, memory.

Issue 28, item 2: every model should fit every material on the full MERL grid
(1,458,000 cells; those inside the 80-degree cut are fitted) within 4 GB and 60 s warm.
Each (model, metric) pair is one subprocess, so compilation is paid once per pair as a
user fitting many materials pays it: it reads the materials (cached once each as a pickle
of the :class:`~brdffit.Measurements`, so the NBRDF network is evaluated once), fits the
first material once cold (``first s``: compilation included), then runs
``brdffit.fit(model, data, metric)`` with its defaults on every material warm (all have
the same grid, so the compiled code is reused) and reports each warm fit's status, steps,
loss and wall time, the process's peak resident memory so far (``ru_maxrss``: data,
compiled code and the fit's arrays together; an upper bound for the row's own fit) and
the 1-minute load average of the box when the fit ended (2 cores: above 2 the times are
stretched by other work). A pair that runs past ``--timeout`` seconds is killed and its
missing rows are recorded as such.

Run (nice: the box is shared):
    nice python3 benchmarks/full_resolution.py [--models sgd low ...] [--metrics low_e2 ngan]
        [--materials chrome-steel blue-metallic-paint green-plastic beige-fabric]
        [--timeout 1800] [--out /tmp/brdffit_full_resolution/rows.jsonl]

Rows are appended to ``--out`` as JSON lines as their pair finishes (a rerun skips pairs
already there), and the markdown table of every row so far is printed at the end. The
NBRDF files are read from ``$BRDFFIT_NBRDF`` (default ``/work/shared/data/merl_nbrdf``).

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
        from brdffit.io.load import load_measurements

        CACHE.mkdir(exist_ok=True)
        data = load_measurements(NBRDF / f"{material}.json")
        tmp = path.with_suffix(".tmp")
        tmp.write_bytes(pickle.dumps(data))
        tmp.replace(path)
    return path


def one_pair(model_name: str, metric: str, materials: list[str]) -> list[dict]:
    """Fit the first material cold, then every material warm, in this process; the rows."""
    from brdffit import fit, models

    model = models.get(model_name)
    data = {m: pickle.loads(cached(m).read_bytes()) for m in materials}
    t0 = time.perf_counter()
    fit(model, data[materials[0]], metric, throw=False)
    first = time.perf_counter() - t0
    rows = []
    for material in materials:
        t0 = time.perf_counter()
        r = fit(model, data[material], metric, throw=False)
        warm = time.perf_counter() - t0
        row = {
            "model": model_name,
            "metric": metric,
            "material": material,
            "status": r.status.name,
            "steps": r.n_steps,
            "loss": r.loss,
            "warm_s": warm,
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "load": os.getloadavg()[0],
            "n_data": r.n_data,
        }
        if material == materials[0]:
            row["first_s"] = first
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def run_pair(model_name: str, metric: str, materials: list[str], timeout: float) -> list[dict]:
    """:func:`one_pair` in a subprocess; a crash or a timeout becomes rows too."""
    cmd = [sys.executable, __file__, "--pair", model_name, metric, *materials]
    t0 = time.perf_counter()
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        stdout, why = out.stdout, None
        if out.returncode != 0:
            err = (out.stderr.strip().splitlines() or ["?"])[-1][:160]
            why = f"ERROR rc={out.returncode}: {err}"
    except subprocess.TimeoutExpired as e:
        stdout = e.stdout.decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
        why = f"KILLED after {timeout:.0f} s"
    rows = {}
    for line in stdout.splitlines():
        if line.startswith("{"):
            r = json.loads(line)
            rows[r["material"]] = r
    missing = {"status": why or "ERROR: no row printed", "first_s": time.perf_counter() - t0}
    return [
        rows.get(m) or {"model": model_name, "metric": metric, "material": m} | missing
        for m in materials
    ]


def table(rows: list[dict]) -> str:
    """Markdown table of the rows (model, metric, material order as given)."""
    lines = [
        "| model | metric | material | status | steps | warm s | first s | peak MB | load | loss |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:

        def num(key: str, fmt: str, r: dict = r) -> str:
            return fmt.format(r[key]) if key in r else "-"

        lines.append(
            f"| {r['model']} | {r['metric']} | {r['material']} | {r['status']} | "
            f"{num('steps', '{}')} | {num('warm_s', '{:.1f}')} | {num('first_s', '{:.1f}')} | "
            f"{num('peak_mb', '{:.0f}')} | {num('load', '{:.1f}')} | {num('loss', '{:.4g}')} |"
        )
    return "\n".join(lines)


def main() -> None:
    from brdffit import models

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pair", nargs="+", metavar="MODEL METRIC MATERIAL")
    ap.add_argument("--models", nargs="+", default=models.available())
    ap.add_argument("--metrics", nargs="+", default=list(METRICS))
    ap.add_argument("--materials", nargs="+", default=list(MATERIALS))
    ap.add_argument("--timeout", type=float, default=1800.0)
    ap.add_argument("--out", default=str(CACHE / "rows.jsonl"))
    args = ap.parse_args()
    if args.pair:
        one_pair(args.pair[0], args.pair[1], args.pair[2:])
        return
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)  # before the first pair, not after it
    done = {}
    if out.exists():
        for line in out.read_text().splitlines():
            r = json.loads(line)
            done[(r["model"], r["metric"], r["material"])] = r
    for material in args.materials:
        cached(material)
    rows = []
    for name in args.models:
        for metric in args.metrics:
            if any((name, metric, m) not in done for m in args.materials):
                for r in run_pair(name, metric, args.materials, args.timeout):
                    done[(name, metric, r["material"])] = r
                    with out.open("a") as f:
                        f.write(json.dumps(r) + "\n")
                    print(table([r]).splitlines()[-1], flush=True)
            rows += [done[(name, metric, m)] for m in args.materials]
    print(table(rows))


if __name__ == "__main__":
    main()
