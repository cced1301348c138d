"""Where a warm ``brdffit.fit`` spends its time: the descents, the starts, and the result.

For each model, on one NBRDF material (``--stride``, default the full MERL grid), a warm
``fit(model, data, metric)`` with its defaults, best of ``--repeats`` after one fit
that compiles; the parts, timed by wrapping the engine's methods for the timed fits:

- ``finish``: the descent on all samples (the last :meth:`Engine._descend` of a fit,
  its tried steps in ``steps``);
- ``race``: the other descents (the starts' race on thinned samples, the refinement on
  more, the cross-metric race);
- ``starts``: the rest of :meth:`Engine.run` (drawing and solving starts, host work);
- ``result``: everything after :meth:`Engine.run` (the covariance, every metric's loss,
  the :class:`~brdffit.FitResult`).

``race + starts + result`` is what a fit costs beyond its steps on all samples: issue
42 asks for a Lambert fit at full resolution with well under 0.1 s of it.

Run: python3 benchmarks/fit_parts.py [--models lambert walter] [--metric low_e2]
     [--material blue-metallic-paint] [--stride 1 1 1] [--repeats 3]
     [--keep-freed-memory]

``--keep-freed-memory``: glibc set as the ``brdffit`` command sets it
(:func:`brdffit.keep_freed_memory`); without it the process's defaults.

Before/after: run it from a worktree of the older commit (``PYTHONPATH=<worktree>``);
the wrapped methods exist in both. Figures: ``benchmarks/results/fit_lm.md``.
"""

from __future__ import annotations

import argparse
import functools
import platform
import time

import brdffit
from benchmarks.published_record import measurements
from brdffit import models
from brdffit.engine import batch


def _timed(calls: list, fn):
    @functools.wraps(fn)
    def inner(*args, **kwargs):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        calls.append(time.perf_counter() - t0)
        return out

    return inner


def parts(model: str, data, metric: str, repeats: int) -> dict[str, float]:
    """Best-of-``repeats`` warm fit time and its parts (module docstring), seconds."""
    spec = models.from_spec(model)
    brdffit.fit(spec, data, metric)  # compiles
    best: dict[str, float] | None = None
    run, descend = batch.Engine.run, batch.Engine._descend
    for _ in range(repeats):
        runs: list[float] = []
        descents: list[float] = []
        batch.Engine.run = _timed(runs, run)
        batch.Engine._descend = _timed(descents, descend)
        try:
            t0 = time.perf_counter()
            r = brdffit.fit(spec, data, metric)
            total = time.perf_counter() - t0
        finally:
            batch.Engine.run, batch.Engine._descend = run, descend
        row = {
            "total": total,
            "finish": descents[-1],
            "race": sum(descents[:-1]),
            "starts": runs[0] - sum(descents),
            "result": total - runs[0],
            "steps": r.n_steps,
            "loss": r.loss,
        }
        if best is None or total < best["total"]:
            best = row
    assert best is not None
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", nargs="+", default=["lambert", "walter"])
    ap.add_argument("--metric", default="low_e2")
    ap.add_argument("--material", default="blue-metallic-paint")
    ap.add_argument("--stride", nargs=3, type=int, default=[1, 1, 1])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--keep-freed-memory", action="store_true", help="as the command sets glibc")
    a = ap.parse_args()
    kept = a.keep_freed_memory and brdffit.keep_freed_memory()  # before JAX runs anything
    data = measurements(a.material, tuple(a.stride))
    print(
        f"# {a.material}, stride {tuple(a.stride)}, {a.metric}; {platform.machine()}; "
        f"freed memory kept: {bool(kept)}"
    )
    print("| model | fit | finish (steps) | race | starts | result | beyond the finish | loss |")
    print("|---|---|---|---|---|---|---|---|")
    for name in a.models:
        p = parts(name, data, a.metric, a.repeats)
        beyond = p["race"] + p["starts"] + p["result"]
        print(
            f"| {name} | {p['total']:.3f} s | {p['finish']:.3f} s ({p['steps']}) | "
            f"{p['race']:.3f} s | {p['starts']:.3f} s | {p['result']:.3f} s | "
            f"{beyond:.3f} s | {p['loss']:.12g} |"
        )


if __name__ == "__main__":
    main()
