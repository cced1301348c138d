"""The fits of a case and their classification: recovered, or why not."""

from __future__ import annotations

import json
import math
import os
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from brdffit import models as registry
from brdffit.core.result import FitResult
from brdffit.engine import robust as robust_mod
from brdffit.engine.fit import fit
from brdffit.engine.metrics import get_metric, prepare

from .cases import CaseSpec, case_spec, case_start, fitter_version, make_data, not_applicable
from .files import is_finished, write_case
from .regimes import (
    ABS_TOL,
    MAX_STEPS,
    N_SAMPLES,
    N_STARTS,
    NOT_IDENTIFIABLE,
    REGIMES,
    REL_TOL,
    STALL_DISTANCE,
    Regime,
)  # fmt: skip

# ------------------------------------------------------------------------------ fits


@eqx.filter_jit
def _objective(model, robust, params, prep, scale):
    return robust_mod.objective(model.evaluate(params, prep.g), prep, robust, scale)


def objective(model, robust: str | None, scale: float, params: dict, prep) -> float:
    """``0.5 sum rho(r)^2`` of the residuals of ``prep``'s metric at ``params`` (natural
    units)."""
    p = {k: jnp.asarray(v, jnp.float64) for k, v in params.items()}
    return float(_objective(model, robust, p, prep, jnp.asarray(scale)))


def zero_objective(robust: str | None, scale: float, prep) -> float:
    """The objective of the zero BRDF: the data's own energy (the tolerance floor's scale)."""
    zero = jnp.zeros_like(prep.values)
    return float(robust_mod.objective(zero, prep, robust, jnp.asarray(scale)))


def _finite_params(params: dict) -> bool:
    return all(np.all(np.isfinite(np.asarray(v, float))) for v in params.values())


def case_fit(
    model,
    data,
    metric: str,
    regime: Regime,
    spec: CaseSpec,
    init: dict,
    scale=None,
    max_steps: int = MAX_STEPS,
    seed: int = 0,
    screen: int | None = None,
):
    """The fit the suite runs from ``init`` (``seed`` seeds its screen; ``scale`` the
    robust scale, ``None`` to estimate it; ``screen=0`` a plain descent from ``init``,
    ``None`` the fit's default screen); returns the :class:`FitResult`."""
    return fit(
        model,
        data,
        metric,
        init=init,
        freeze=spec.freeze or None,
        cut_deg=regime.cut_deg,
        n_restarts=0,
        **({} if screen is None else {"screen": screen}),
        seed=seed,
        robust=regime.robust,
        robust_scale=scale,
        max_steps=max_steps,
        throw=False,
    )


def _one_fit(run: Callable[[], FitResult]) -> tuple[dict, FitResult | None]:
    """Run one fit, ``run()`` (a :func:`case_fit` call), and record it; returns (record
    dict, FitResult or None when it raised)."""

    t0 = time.perf_counter()
    try:
        r = run()
    except Exception as e:  # recorded as a failure, the suite goes on
        return {
            "status": "EXCEPTION",
            "error": f"{type(e).__name__}: {e}",
            "traceback": traceback.format_exc(limit=4),
            "wall_time": time.perf_counter() - t0,
            "n_steps": None,
            "loss": None,
            "finite": False,
        }, None
    finite = (
        math.isfinite(r.loss)
        and _finite_params(r.params)
        and all(math.isfinite(v) for v in r.losses.values())
    )
    return {
        "status": r.status.name,
        "loss": r.loss,
        "n_steps": int(r.n_steps),
        "wall_time": float(r.wall_time),
        "finite": finite,
        "at_bound": list(r.at_bound),
        "condition_number": r.condition_number,
        "params": {k: np.asarray(v, float).tolist() for k, v in r.params.items()},
        "stderr_nonfinite": [
            k for k, v in (r.stderr or {}).items() if not np.all(np.isfinite(np.asarray(v)))
        ],
        "errors_reason": r.errors_reason,
    }, r


def _classify(rec: dict, best: float, tol: float) -> tuple[bool, str | None]:
    """(recovered, failure reason) of one fit record with its objective ``J``."""
    status = rec["status"]
    if status == "EXCEPTION":
        return False, f"exception {rec['error'].split(':')[0]}"
    j = rec.get("objective")
    if status != "NONFINITE" and (not rec["finite"] or j is None or not math.isfinite(j)):
        return False, "silent non-finite"
    if status == "NONFINITE":
        return False, "NONFINITE"
    if status != "CONVERGED":
        at_min = j is not None and j - best <= tol
        return False, f"{status} ({'at the minimum' if at_min else 'short of it'})"
    if j - best > tol:
        return False, "wrong minimum"
    return True, None


def _u_distance(model, freeze, a: dict, b: dict) -> float:
    """Largest difference of the free scalars of ``a`` and ``b`` in the optimiser space."""

    d = 0.0
    for p in model.parameters:
        if p.name in freeze:
            continue
        ua, ub = (np.asarray(p.to_unconstrained(jnp.asarray(x[p.name], float))) for x in (a, b))
        d = max(d, float(np.max(np.abs(ua - ub))))
    return d


def run_case(
    model_name: str,
    metric: str,
    regime: Regime | str,
    *,
    n_starts: int = N_STARTS,
    n_samples: int = N_SAMPLES,
    max_steps: int = MAX_STEPS,
) -> dict:
    """Run one case (reference fit + ``n_starts`` random starts); returns its JSON dict."""

    regime = REGIMES[regime] if isinstance(regime, str) else regime
    out: dict = {
        "model": model_name,
        "metric": metric,
        "regime": regime.name,
        "description": regime.description,
        "settings": {"n_starts": n_starts, "n_samples": n_samples, "rel_tol": REL_TOL,
                     "abs_tol": ABS_TOL, "cut_deg": regime.cut_deg, "robust": regime.robust,
                     "max_steps": max_steps, "fitter": fitter_version()},
    }  # fmt: skip
    reason = not_applicable(model_name, regime)
    if reason:
        out.update(applicable=False, reason=reason, identifiable=None)
        return out
    t_case = time.perf_counter()
    spec = case_spec(model_name, regime)
    model = spec.build()
    data, info = make_data(spec, regime, n_samples)
    prep = prepare(data, get_metric(metric), cut_deg=regime.cut_deg)
    out.update(
        applicable=True,
        options=spec.options,
        truth={k: np.asarray(v).tolist() for k, v in spec.truth.items()},
        frozen=sorted(spec.freeze),
        notes=list(spec.notes),
        data=info,
        n_fitted=prep.n,
    )
    free_truth = {k: v for k, v in spec.truth.items() if k not in spec.freeze}

    def one_fit(init: dict, scale, **kw) -> tuple[dict, FitResult | None]:
        return _one_fit(
            lambda: case_fit(model, data, metric, regime, spec, init, scale, max_steps, **kw)
        )

    ref, ref_result = one_fit(free_truth, None)
    scale = ref_result.robust_scale if ref_result is not None else None
    robust_scale = 1.0 if scale is None else float(scale)
    starts = []
    for i in range(n_starts):
        init = case_start(model, spec, i)
        rec, _ = one_fit(init, scale, seed=i + 1)
        rec["seed"] = i
        rec["init"] = {k: np.asarray(v).tolist() for k, v in init.items()}
        starts.append(rec)
    # the truth's basin: a plain descent from the truth, no screen
    local = one_fit(free_truth, scale, screen=0)[0] if corrupts(regime) else None
    for rec in [ref, *starts, *([local] if local else [])]:
        rec["objective"] = (
            objective(model, regime.robust, robust_scale, rec["params"], prep)
            if rec.get("params") is not None and rec["finite"]
            else None
        )
    j0 = zero_objective(regime.robust, robust_scale, prep)
    jt = objective(model, regime.robust, robust_scale, spec.truth, prep)
    out.update(robust_scale=scale, zero_objective=j0, truth_objective=jt, reference=ref,
               starts=starts, **({"local": local} if local else {}))  # fmt: skip
    score(out, model)
    out["case_time"] = time.perf_counter() - t_case
    return out


def score(case: dict, model=None) -> dict:
    """Classify the fits of a case dict (``reference``, ``starts`` with their objectives,
    ``zero_objective``) and fill in the recovery fields; returns ``case``.

    Works on a stored case too (the tolerances are this module's): the model is built
    from ``case["model"]`` and ``case["options"]`` when not given.
    """
    if model is None:
        model = registry.get(case["model"], **case.get("options", {}))
    ref, starts, j0 = case["reference"], case["starts"], case["zero_objective"]
    local = case.get("local")
    freeze = set(case.get("frozen", ()))
    fits = [ref, *starts, *([local] if local else [])]
    finite = [r for r in fits if r.get("objective") is not None and math.isfinite(r["objective"])]
    jt = case.get("truth_objective")
    if jt is not None and math.isfinite(jt):  # the truth itself bounds the best minimum
        finite.append({"objective": jt, "params": case["truth"]})
    best_rec = min(finite, key=lambda r: r["objective"]) if finite else None
    best = best_rec["objective"] if best_rec else float("nan")
    tol = REL_TOL * abs(best) + ABS_TOL * j0 if best_rec else float("nan")
    failures: dict[str, int] = {}
    excess: dict[str, list[float]] = {}
    for rec in fits:
        rec.setdefault("objective", None)
        ok, why = _classify(rec, best, tol)
        j = rec["objective"]
        if j is not None and math.isfinite(best):
            rec["excess"] = (j - best) / max(abs(best), ABS_TOL * j0, 1e-300)
        if why == "wrong minimum" and best_rec is not None:
            # converged above the tolerance: next to the best point (a stall) or elsewhere
            rec["u_distance"] = _u_distance(model, freeze, rec["params"], best_rec["params"])
            if rec["u_distance"] < STALL_DISTANCE:
                why = "stalled next to the minimum"
        rec["recovered"], rec["reason"] = ok, why
        if rec is not ref and rec is not local and why is not None:
            failures[why] = failures.get(why, 0) + 1
            if rec.get("excess") is not None:
                excess.setdefault(why, []).append(rec["excess"])
    declared = NOT_IDENTIFIABLE.get((case["model"], case["regime"]))
    reason = declared or _optimum_moved(REGIMES.get(case["regime"]), local or ref, jt)
    case.update(identifiable=reason is None, not_identifiable_reason=reason)
    n_ok = sum(r["recovered"] for r in starts)
    steps = [r["n_steps"] for r in starts if r.get("n_steps") is not None]
    times = [r["wall_time"] for r in starts]
    case.update(
        best_objective=best,
        tolerance=tol,
        recovery=n_ok / len(starts) if starts else float("nan"),
        n_recovered=n_ok,
        median_steps=float(np.median(steps)) if steps else None,
        median_time=float(np.median(times)) if times else None,
        failures=failures,
        failure_excess={k: float(np.median(v)) for k, v in excess.items()},
        n_nonfinite=sum(not r["finite"] and r["status"] != "EXCEPTION" for r in fits),
        condition_number=ref.get("condition_number"),
    )
    return case


def corrupts(regime: Regime) -> bool:
    """True when the regime corrupts the data (noise, outliers): the truth is then no
    longer an exact minimum, and the suite also descends plainly from it."""
    return bool(regime.noise_mult or regime.outliers)


def _optimum_moved(
    regime: Regime | None, ref: dict, truth_objective: float | None = None
) -> str | None:
    """Why a case is not identifiable from its data, or None: in a regime that corrupts
    the data (noise, outliers), the descent from the truth converged to a distinct
    minimum (a wrong minimum, not a stall) that some start beat.

    ``ref`` is the case's ``local`` fit, a plain descent from the truth with no screen:
    its end is the minimum of the truth's basin. (Cases stored before that fit existed
    pass their reference, whose own screen can leave the basin.) When a start beats it
    elsewhere, the lowest minimum is not the truth's: the corruption decides which of
    several minima is lowest, and reaching it is a search among minima that say nothing
    about the material. On noise-free data the truth is an exact minimum, so there a
    failed reference stays the fitter's failure. A descent that ends above
    ``truth_objective``, the objective at the truth itself, did not descend: that too
    stays the fitter's failure, whatever the data.
    """
    if regime is None or not corrupts(regime):
        return None
    if ref.get("status") != "CONVERGED" or ref.get("reason") != "wrong minimum":
        return None
    if truth_objective is not None and not ref["objective"] <= truth_objective:
        return None
    what = "outliers" if regime.outliers else "noise"
    return (
        f"the {what} move the lowest minimum out of the truth's basin: the descent from "
        f"the truth converges {ref.get('excess', float('nan')):.1e} (relative) above it, "
        f"{ref.get('u_distance', float('nan')):.2g} away in the optimiser space"
    )


def rescore(out: str | os.PathLike[str]) -> int:
    """Re-classify every finished case in folder ``out`` with the current tolerances
    (no refit); rewrites the files atomically and returns how many it rescored."""
    n = 0
    for p in sorted(Path(out).glob("*__*__*.json")):
        if p.name.endswith(".error.json") or not is_finished(p):
            continue
        d = json.loads(p.read_text())
        if d.get("applicable"):
            write_case(p, score(d))
            n += 1
    return n
