"""brdffit's fits against every published MERL fit in bbm's 14 fit files (issue 41, item 1).

For each fit set (:mod:`benchmarks.published.families`) and each of its materials
(Ngan et al.: 86, Löw et al. and Bagher et al.: 100), on the NBRDF network of the
material (``$BRDFFIT_NBRDF``, default ``../shared/data/merl_nbrdf`` beside the repository)
evaluated on a strided MERL grid:

1. brdffit fits the model with that fit set's formula, with its defaults, under the
   metric the set was published with;
2. bbm's C++ (:mod:`benchmarks.published.bbm`) evaluates the published fit, and brdffit's
   model evaluates its own fit, on the same cells, and one scorer
   (:mod:`benchmarks.published.score`) computes every metric of both;
3. where the formulas are the same, brdffit's fit is also written in the published form
   and scored through bbm (``mapped``): it must equal brdffit's own score, which checks the
   map and the formula together;
4. where the published fit scores lower, brdffit is fitted again from the published
   values (clipped into its bounds): if that reaches the published score, the default
   fit stopped in another basin (a local minimum); if a published value lies outside
   brdffit's bounds, the bound is named.

One JSON file per (set, material) in ``--out``, written atomically; a rerun skips those
present, so an interrupted run resumes. The markdown table is printed (``--md`` writes it).

Run (nice: the box is shared):
    nice python -m benchmarks.published_record [--families ngan_ward ...]
        [--materials alum-bronze ...] [--stride 3 3 5] [--jobs 2]
        [--out /tmp/brdffit_published/s335] [--full-grid [MATERIAL ...]]
        [--md table.md] [--csv benchmarks/results/published_record.csv]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import pickle
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

import numpy as np

from benchmarks.jobs import run_jobs
from benchmarks.published import bbm, score
from benchmarks.published.families import FAMILIES, Family
from benchmarks.published.fitfile import read_fit_file
from brdffit import fit, models
from brdffit.io.load import load_measurements
from brdffit.util.atomic import write_atomic

NBRDF = Path(
    os.environ.get("BRDFFIT_NBRDF", Path(__file__).resolve().parents[2] / "shared/data/merl_nbrdf")
)
CACHE = Path(tempfile.gettempdir()) / "brdffit_published"
TIE = 1e-6
"""Relative margin within which two scores count as equal: the published parameters are
printed to 3-6 digits, which moves their score by more than this."""


def measurements(material: str, stride: tuple[int, int, int]):
    """The NBRDF material on the strided MERL grid, pickled once per stride."""
    path = CACHE / ("data_s" + "".join(map(str, stride))) / f"{material}.pkl"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        data = load_measurements(NBRDF / f"{material}.json", stride=stride)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(pickle.dumps(data))
        tmp.replace(path)
    return pickle.loads(path.read_bytes())


def _scores(f: np.ndarray, at: score.Cells) -> dict[str, float]:
    return {m: score.loss(m, f, at) for m in score.METRICS}


def _outside(model, params: dict) -> list[str]:
    """Names of the parameters whose value lies outside the model's bounds."""
    bad = []
    for p in model.parameters:
        v = np.asarray(params[p.name], float)
        if np.any(v < p.bounds[0]) or np.any(v > p.bounds[1]):
            bad.append(p.name)
    return bad


def _clipped(model, params: dict) -> dict:
    """``params`` moved inside the bounds (by 1e-6 of the range), as ``fit``'s ``init`` must be."""
    out = {}
    for p in model.parameters:
        lo, hi = p.bounds
        span = hi - lo if np.isfinite(hi - lo) else 1.0
        out[p.name] = np.clip(np.asarray(params[p.name], float), lo + 1e-6 * span, hi - 1e-6 * span)
    return out


def _restricted(model, params: dict) -> dict:
    """Published values in the model's own table: a grey parameter takes its mean."""
    names = {p.name: p for p in model.parameters}
    return {
        k: (np.float64(np.mean(v)) if k in names and names[k].shape == () else v)
        for k, v in params.items()
        if k in names
    }


def compare(family: Family, material: str, stride: tuple[int, int, int]) -> dict:
    """The comparison row of one published fit (see the module text)."""
    data = measurements(material, stride)
    at = score.cells(data)
    wi, wo = data.wi[at.index], data.wo[at.index]
    model = models.from_spec(family.spec)
    published = read_fit_file(family.file)[material]

    t0 = time.perf_counter()
    r = fit(model, data, family.metric, throw=False)
    seconds = time.perf_counter() - t0
    reading = family.reading or bbm.evaluate
    ours = _scores(np.asarray(model.eval(r.params, wi, wo)), at)
    theirs = _scores(reading(published.expression, wi, wo), at)
    row = {
        "family": family.key,
        "material": material,
        "metric": family.metric,
        "spec": family.spec,
        "stride": list(stride),
        "status": r.status.name,
        "steps": r.n_steps,
        "seconds": seconds,
        "loss_brdffit": r.loss,
        "ours": ours,
        "published": theirs,
        "params": {k: np.asarray(v).tolist() for k, v in r.params.items()},
        "at_bound": list(r.at_bound),
        "mapped": None,
        "outside_bounds": None,
        "refit": None,
    }
    if family.reading is not None:
        row["published_bbm"] = _scores(bbm.evaluate(published.expression, wi, wo), at)
    if family.to_published is not None:
        row["mapped"] = _scores(reading(family.to_published(r.params), wi, wo), at)
    if family.from_published is not None:
        start = _restricted(model, family.from_published(published))
        row["outside_bounds"] = _outside(model, start)
        m = family.metric
        if theirs[m] < ours[m] * (1.0 - TIE):
            again = fit(model, data, m, init=_clipped(model, start), throw=False)
            row["refit"] = {
                "scores": _scores(np.asarray(model.eval(again.params, wi, wo)), at),
                "status": again.status.name,
                "params": {k: np.asarray(v).tolist() for k, v in again.params.items()},
            }
    return row


def _path(out: Path, key: str, material: str) -> Path:
    return out / key / f"{material}.json"


def work(job: tuple[str, str], stride: tuple[int, int, int], out: Path) -> str:
    """Run one comparison and write its row atomically; the status line."""
    key, material = job
    row = compare(FAMILIES[key], material, stride)
    _path(out, key, material).parent.mkdir(parents=True, exist_ok=True)
    write_atomic(_path(out, key, material), [json.dumps(row, indent=1).encode()])
    m = row["metric"]
    return f"{key} {material}: ours {row['ours'][m]:.6g} published {row['published'][m]:.6g}"


def rescore(material: str, keys: list[str], out: Path) -> str:
    """Score the stored fits of ``material`` (every set in ``keys``) on the full MERL grid.

    A fit made on a sub-grid and scored on the full grid bounds from above what a fit on
    the full grid would score there, so "ours no worse" on the full grid with the
    sub-grid fit holds a fortiori for a full-grid fit; rows in ``out/full/<set>/``."""
    todo = [k for k in keys if (out / k / f"{material}.json").exists()]
    todo = [k for k in todo if not _path(out / "full", k, material).exists()]
    if not todo:
        return f"{material}: nothing to rescore"
    data = load_measurements(NBRDF / f"{material}.json")
    at = score.cells(data)
    wi, wo = data.wi[at.index], data.wo[at.index]
    for key in todo:
        row = json.loads(_path(out, key, material).read_text())
        family = FAMILIES[key]
        model = models.from_spec(family.spec)
        published = read_fit_file(family.file)[material]
        params = {k: np.asarray(v) for k, v in row["params"].items()}
        reading = family.reading or bbm.evaluate
        full = {
            "family": key,
            "material": material,
            "metric": row["metric"],
            "cells": int(at.index.size),
            "ours": _scores(np.asarray(model.eval(params, wi, wo)), at),
            "published": _scores(reading(published.expression, wi, wo), at),
        }
        _path(out / "full", key, material).parent.mkdir(parents=True, exist_ok=True)
        write_atomic(_path(out / "full", key, material), [json.dumps(full, indent=1).encode()])
    return f"{material}: rescored {len(todo)} fit sets on {at.index.size} cells"


def _verdict(row: dict) -> tuple[bool, str]:
    """(ours no worse, reason if not)."""
    m = row["metric"]
    ours, theirs = row["ours"][m], row["published"][m]
    if ours <= theirs * (1.0 + TIE):
        return True, ""
    reasons = []
    if row.get("outside_bounds"):
        reasons.append("published " + "+".join(row["outside_bounds"]) + " outside the bounds")
    refit = row.get("refit")
    if refit is not None and refit["scores"][m] <= theirs * (1.0 + TIE):
        reasons.append("local minimum (a fit from the published values wins)")
    elif refit is not None:
        reasons.append("a fit from the published values does not reach it")
    if row.get("mapped") is None:
        reasons.append("different formula")
    return False, "; ".join(reasons)


def table(out: Path, keys: list[str]) -> str:
    """Markdown: per family, materials, ours no worse, median score ratio, misses."""
    lines = [
        "| fit set | metric | materials | ours no worse | median ours / published | "
        "mapped = ours (max rel. diff) | full grid: ours no worse |",
        "|---|---|---|---|---|---|---|",
    ]
    details = []
    for key in keys:
        rows = [json.loads(p.read_text()) for p in sorted((out / key).glob("*.json"))]
        if not rows:
            continue
        m = rows[0]["metric"]
        verdicts = [_verdict(r) for r in rows]
        wins = sum(v for v, _ in verdicts)
        ratio = np.median([r["ours"][m] / r["published"][m] for r in rows])
        mapped = [
            abs(r["mapped"][m] / r["ours"][m] - 1.0) for r in rows if r.get("mapped") is not None
        ]
        mapped_s = f"{max(mapped):.1e}" if mapped else "no exact map"
        full = [json.loads(p.read_text()) for p in sorted((out / "full" / key).glob("*.json"))]
        full_wins = sum(f["ours"][m] <= f["published"][m] * (1.0 + TIE) for f in full)
        full_s = f"{full_wins} of {len(full)}" if full else "not scored"
        lines.append(
            f"| {key} | {m} | {len(rows)} | {wins} ({100 * wins / len(rows):.0f}%) | "
            f"{ratio:.3f} | {mapped_s} | {full_s} |"
        )
        for r, (v, why) in zip(rows, verdicts, strict=True):
            if not v:
                details.append(
                    f"- {key}, {r['material']}: ours {r['ours'][m]:.5g}, published "
                    f"{r['published'][m]:.5g} ({r['ours'][m] / r['published'][m]:.3f}x): {why}"
                )
    notes = [f"- {k}: {FAMILIES[k].note}" for k in keys if FAMILIES[k].note]
    return "\n".join(lines + [""] + notes + ([""] + details if details else [])) + "\n"


def write_csv(out: Path, keys: list[str], path: Path) -> int:
    """One line per stored comparison (sub-grid and, where rescored, full-grid scores under
    the set's metric); the number of lines."""
    lines = []
    for key in keys:
        for p in sorted((out / key).glob("*.json")):
            r = json.loads(p.read_text())
            m = r["metric"]
            full = _path(out / "full", key, r["material"])
            f = json.loads(full.read_text()) if full.exists() else None
            lines.append({
                "fit_set": key, "material": r["material"], "metric": m, "model": r["spec"],
                "status": r["status"], "steps": r["steps"], "seconds": f"{r['seconds']:.2f}",
                "ours": f"{r['ours'][m]:.9g}", "published": f"{r['published'][m]:.9g}",
                "mapped": f"{r['mapped'][m]:.9g}" if r.get("mapped") else "",
                "full_grid_ours": f"{f['ours'][m]:.9g}" if f else "",
                "full_grid_published": f"{f['published'][m]:.9g}" if f else "",
                "published_outside_bounds": "+".join(r.get("outside_bounds") or []),
            })  # fmt: skip
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(lines[0]))
        w.writeheader()
        w.writerows(lines)
    return len(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", nargs="+", default=list(FAMILIES), choices=list(FAMILIES))
    ap.add_argument("--materials", nargs="+", default=None)
    ap.add_argument("--stride", nargs=3, type=int, default=[3, 3, 5])
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--md", type=Path, default=None)
    ap.add_argument("--csv", type=Path, default=None, help="write one line per comparison")
    ap.add_argument(
        "--full-grid",
        nargs="*",
        default=None,
        metavar="MATERIAL",
        help="score the stored fits of these materials (none named: all) on the full grid",
    )
    a = ap.parse_args(argv)
    stride = tuple(a.stride)
    out = a.out or CACHE / ("s" + "".join(map(str, stride)))
    jobs = []
    for key in a.families:
        fits = read_fit_file(FAMILIES[key].file)
        for material in a.materials or sorted(fits):
            if material in fits and not _path(out, key, material).exists():
                jobs.append((key, material))
    print(f"{len(jobs)} comparisons to run; rows in {out}", file=sys.stderr)

    def record(job, status):
        print(status, file=sys.stderr, flush=True)

    def crashed(job, err):
        return f"{job}: crashed: {err!r}"

    run_jobs(jobs, partial(work, stride=stride, out=out), record, crashed, processes=a.jobs)
    if a.full_grid is not None:
        stored = {p.stem for k in a.families for p in (out / k).glob("*.json")}
        names = a.full_grid or sorted(stored)
        work_full = partial(rescore, keys=a.families, out=out)
        run_jobs(names, work_full, record, crashed, processes=a.jobs)
    md = table(out, a.families)
    print(md)
    if a.md:
        a.md.write_text(md)
    if a.csv:
        write_csv(out, a.families, a.csv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
