"""The resumable suite runner and the tables."""

from __future__ import annotations

import functools
import os
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path

from benchmarks.jobs import run_jobs
from brdffit import models as registry
from brdffit.engine.metrics import get_metric
from brdffit.util.atomic import remove_temporaries
from brdffit.util.text_table import render

from .files import case_path, is_finished, write_case
from .regimes import (
    DEFAULT_METRICS,
    MAX_STEPS,
    N_SAMPLES,
    N_STARTS,
    RECOVERY_TARGET,
    REGIMES,
    ROLES,
)  # fmt: skip
from .scoring import run_case


def _run_one(
    case: tuple[str, str, str], out: str, n_starts: int, n_samples: int, max_steps: int
) -> dict:
    """Run (and write) one case ``(model, metric, regime)``; returns its status line dict.

    An exception is written to the case's ``.error.json`` and the case is retried on
    the next run."""
    model, metric, name = case
    path = case_path(out, model, metric, name)
    try:
        res = run_case(
            model, metric, name, n_starts=n_starts, n_samples=n_samples, max_steps=max_steps
        )
    except Exception as e:
        info = {"model": model, "metric": metric, "regime": name}
        info.update(error=f"{type(e).__name__}: {e}", traceback=traceback.format_exc())
        write_case(path.with_suffix(".error.json"), info)
        return {"case": path.name, "ok": False, "error": info["error"]}
    write_case(path, res)
    path.with_suffix(".error.json").unlink(missing_ok=True)
    return {"case": path.name, "ok": True, "recovery": res.get("recovery")}


def run_suite(
    out: str | os.PathLike[str],
    models: Sequence[str],
    metrics: Sequence[str] = DEFAULT_METRICS,
    regimes: Sequence[str] = tuple(REGIMES),
    *,
    n_starts: int = N_STARTS,
    n_samples: int = N_SAMPLES,
    max_steps: int = MAX_STEPS,
    jobs: int = 1,
    progress: Callable[[str], None] | None = None,
) -> int:
    """Run every unfinished case of ``models x metrics x regimes`` into folder ``out``.

    ``jobs`` > 1 runs the cases in that many worker processes
    (:func:`benchmarks.jobs.run_jobs`); each worker compiles a model once and keeps it.
    Returns the number of cases run.
    """

    for m in models:
        registry.get(m)
        if m not in ROLES:
            raise ValueError(f"model {m!r} has no stress roles in benchmarks.stress.ROLES")
    for m in metrics:
        get_metric(m)
    unknown = [r for r in regimes if r not in REGIMES]
    if unknown:
        raise ValueError(f"unknown regime(s) {unknown}; known: {', '.join(REGIMES)}")
    Path(out).mkdir(parents=True, exist_ok=True)
    remove_temporaries(out)
    todo = [
        (mo, me, r)
        for mo in models
        for me in metrics
        for r in regimes
        if not is_finished(case_path(out, mo, me, r))
    ]
    say = progress or (lambda s: None)

    def crashed(case: tuple[str, str, str], e: BaseException) -> dict:
        name = case_path(out, *case).name  # a dead worker: the case reruns next time
        return {"case": name, "ok": False, "error": f"worker failed: {type(e).__name__}: {e}"}

    work = functools.partial(
        _run_one, out=str(out), n_starts=n_starts, n_samples=n_samples, max_steps=max_steps
    )
    run_jobs(todo, work, lambda case, d: say(_progress_line(d)), crashed, jobs)
    return len(todo)


def _progress_line(d: dict) -> str:
    if not d["ok"]:
        return f"{d['case']}: ERROR {d['error']}"
    rec = d.get("recovery")
    return f"{d['case']}: " + ("not applicable" if rec is None else f"recovery {100 * rec:.0f}%")


# ------------------------------------------------------------------------------ table


def _failures_cell(d: dict) -> str:
    parts = []
    data, n = d.get("data") or {}, d.get("settings", {}).get("n_samples")
    if data.get("nonfinite_values"):
        parts.append(f"data: {data['nonfinite_values']} non-finite values")
    if n is not None and d.get("n_fitted") is not None and d["n_fitted"] < n:
        parts.append(f"data: {d['n_fitted']} of {n} samples fitted")
    ref = d.get("reference") or {}
    if ref and not ref.get("recovered", True):
        parts.append(f"reference: {ref.get('reason')}")
    for why, k in sorted((d.get("failures") or {}).items(), key=lambda kv: -kv[1]):
        exc = (d.get("failure_excess") or {}).get(why)
        parts.append(f"{k}x {why}" + ("" if exc is None else f" (excess {exc:.1e})"))
    return "; ".join(parts)


def _fmt(x: float | None, spec: str) -> str:
    return "" if x is None else format(x, spec)


def format_table(rows: Sequence[dict]) -> str:
    """The Markdown table of case results (:func:`load_results`)."""
    head = ["model", "metric", "regime", "identifiable", "recovery %", "median steps",
            "median time (s)", "cond (ref)", "failures"]  # fmt: skip
    body = []
    for d in rows:
        if not d.get("applicable", False):
            cells = [d["model"], d["metric"], d["regime"], "", "n/a", "", "", "",
                     f"not applicable: {d.get('reason', '')}"]  # fmt: skip
        else:
            cond = d.get("condition_number")
            cells = [
                d["model"],
                d["metric"],
                d["regime"],
                "yes" if d["identifiable"] else "no",
                f"{100 * d['recovery']:.0f} ({d['n_recovered']}/{len(d['starts'])})",
                _fmt(d.get("median_steps"), ".0f"),
                _fmt(d.get("median_time"), ".2f"),
                "" if cond is None else f"{cond:.1e}",
                _failures_cell(d),
            ]
        body.append(cells)
    return render(head, body, "markdown").rstrip("\n")


def format_matrix(rows: Sequence[dict]) -> str:
    """Recovery % per model (rows) and regime (columns), one Markdown table per metric.

    A cell is the recovery in percent, ``n/a`` for a case that does not apply, ``NI``
    appended for a case that is not identifiable, and empty for a case not run.
    """
    by_key = {(d["model"], d["metric"], d["regime"]): d for d in rows}
    regimes = [r for r in REGIMES if any(d["regime"] == r for d in rows)]
    blocks = []
    for metric in dict.fromkeys(d["metric"] for d in rows):
        body = []
        for model in sorted({d["model"] for d in rows if d["metric"] == metric}):
            cells = [model]
            for regime in regimes:
                d = by_key.get((model, metric, regime))
                if d is None:
                    cells.append("")
                elif not d.get("applicable", False):
                    cells.append("n/a")
                else:
                    ni = "" if d.get("identifiable") else " NI"
                    cells.append(f"{100 * d['recovery']:.0f}{ni}")
            body.append(cells)
        blocks.append(f"{metric}:\n\n" + render(["model", *regimes], body, "markdown"))
    return "\n".join(blocks).rstrip("\n")


def summary(rows: Sequence[dict]) -> str:
    """One line: cases run, not applicable, identifiable ones (the others named), those
    under the recovery target, fits that ended non-finite (and whether any did so
    silently)."""
    run = [d for d in rows if d.get("applicable")]
    ident = [d for d in run if d.get("identifiable")]
    not_ident = [
        f"{d['model']}/{d['metric']}/{d['regime']}" for d in run if not d.get("identifiable")
    ]
    under = [d for d in ident if d["recovery"] < RECOVERY_TARGET]
    nonfinite = sum(d.get("n_nonfinite", 0) for d in run)
    silent = sum((d.get("failures") or {}).get("silent non-finite", 0) for d in run)
    if len(under) <= 12:
        names = ", ".join(f"{d['model']}/{d['metric']}/{d['regime']}" for d in under)
    else:
        per_model: dict[str, int] = {}
        for d in under:
            per_model[d["model"]] = per_model.get(d["model"], 0) + 1
        names = "by model: " + ", ".join(f"{k} {v}" for k, v in per_model.items())
    return (
        f"{len(rows)} cases: {len(run)} run, {len(rows) - len(run)} not applicable; "
        f"{len(ident)} identifiable"
        + (f" ({len(not_ident)} not: {', '.join(not_ident)})" if not_ident else "")
        + f", {len(under)} under {100 * RECOVERY_TARGET:.0f}% recovery"
        + (f" ({names})" if names else "")
        + f"; {nonfinite} non-finite fits ({silent} silent)"
    )
