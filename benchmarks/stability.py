"""Numerical-stability stress suite: every model x metric x regime, recovery from random starts.

For each case (model, metric, regime of :data:`stress.REGIMES`): synthetic data
from a truth drawn for the regime, one fit from the truth and ``--starts`` seeded random
starts; a start is recovered when it is finite, converged and within a relative 1e-6 of
the best objective (floor 1e-10 of the data's own energy). See ``benchmarks/stress``.

Each case is written to ``OUT/<model>__<metric>__<regime>.json`` as soon as it finishes
(atomically), so an interrupted run resumes where it stopped; the Markdown table and a
summary line are printed at the end and written to ``OUT/table.md``.

Run: python3 benchmarks/stability.py --out stress-out [--models walter,lambert | all]
         [--metrics low_e2,ngan] [--regimes baseline,near_mirror | all] [--starts 20]
         [--samples 2000] [--max-steps 512] [--jobs N]
     python3 benchmarks/stability.py --out stress-out --table     # table from existing JSON
     python3 benchmarks/stability.py --out stress-out --rescore   # re-classify, no refit
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the root: the truths in tests.cases

import stress  # noqa: E402  (benchmarks/stress: the script's folder is on sys.path)

from brdffit.util.atomic import write_text  # noqa: E402


def _names(ap: argparse.ArgumentParser, text: str, known: list[str], what: str) -> list[str]:
    if text == "all":
        return known
    names = [s.strip() for s in text.split(",") if s.strip()]
    bad = [n for n in names if n not in known]
    if bad:
        ap.error(f"--{what}s: unknown {what} {', '.join(bad)}; known: {', '.join(known)}")
    return names


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="folder of per-case JSON files")
    ap.add_argument("--models", default="all", help="comma-separated names, or all")
    ap.add_argument("--metrics", default=",".join(stress.DEFAULT_METRICS))
    ap.add_argument("--regimes", default="all", help="comma-separated names, or all")
    ap.add_argument("--starts", type=int, default=stress.N_STARTS)
    ap.add_argument("--samples", type=int, default=stress.N_SAMPLES)
    ap.add_argument("--max-steps", type=int, default=stress.MAX_STEPS, help="LM steps per descent")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes (spawn)")
    ap.add_argument("--table", action="store_true", help="only print the table from OUT")
    ap.add_argument(
        "--rescore",
        action="store_true",
        help="re-classify the fits in OUT with the current tolerances (no refit), then print",
    )
    args = ap.parse_args()
    out = Path(args.out)
    if args.rescore:
        print(f"# rescored {stress.rescore(out)} case(s)")
    elif not args.table:
        import brdffit
        from brdffit.engine.metrics import METRICS

        brdffit.enable_compilation_cache()
        models = _names(ap, args.models, sorted(stress.ROLES), "model")
        metrics = _names(ap, args.metrics, list(METRICS), "metric")
        regimes = _names(ap, args.regimes, list(stress.REGIMES), "regime")
        n_cases = len(models) * len(metrics) * len(regimes)
        print(
            f"# {n_cases} cases: {len(models)} models x {len(metrics)} metrics x "
            f"{len(regimes)} regimes, {args.starts} starts, {args.samples} samples, "
            f"{args.jobs} job(s)",
            flush=True,
        )
        t0 = time.perf_counter()
        n = stress.run_suite(
            out,
            models,
            metrics,
            regimes,
            n_starts=args.starts,
            n_samples=args.samples,
            max_steps=args.max_steps,
            jobs=args.jobs,
            progress=lambda line: print(f"[{time.perf_counter() - t0:7.0f} s] {line}", flush=True),
        )
        print(f"# {n} cases run in {time.perf_counter() - t0:.0f} s", flush=True)
    rows = stress.load_results(out)
    if not rows:
        print(f"stability.py: error: {out}: no finished case", file=sys.stderr)
        sys.exit(2)
    text = (
        "\n\n".join([stress.format_matrix(rows), stress.format_table(rows), stress.summary(rows)])
        + "\n"
    )
    print(text)
    errors = sorted(out.glob("*.error.json"))
    if errors:
        print(f"# {len(errors)} case(s) raised (see {out}/*.error.json; rerun to retry)")
    write_text(out / "table.md", text)


if __name__ == "__main__":
    main()
