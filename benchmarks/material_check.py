"""Material check: ``brdffit material`` on every RGL-EPFL file, its Mitsuba export rendered
beside Mitsuba's own ``measured`` plugin (issue 43, item 4).

For each ``.bsdf`` file: read it on a strided MERL grid for the fits (``--stride``) and at
full resolution for the scores, run :func:`brdffit.export.material.best_material` for
``mitsuba`` (its forms and the reference, ``walter[n_lobes=2,sheen=true]``) and for
``gltf`` (its forms; the reference's scores are the same fit's), then render the chosen
Mitsuba export and the measurement with :func:`benchmarks.render_check.render_check`
(unit sphere, white environment ``env`` and a point light ``point``; rel RMSE over the
sphere's pixels, env colour ratios, Monte Carlo noise from a second seed). glTF has no
renderer here: its rows give the render-space errors that ``brdffit material`` measures
(albedo error, point-light error; :mod:`brdffit.export.material`).

Targets (issue 43): env rel RMSE <= 0.10 with every colour ratio in [0.90, 1.10] on at least
85% of the files; median point-light rel RMSE <= 0.15; no export error above 0.05 where
the form is exact.

Resumable: one JSON per file in ``--state`` (written atomically); a file already there is
not run again. The Markdown table is written from every JSON at the end, followed by
``<out>.notes.md`` (what the pictures show, written by whoever looked at them).

    nice python -m benchmarks.material_check /work/rgl_data/*.bsdf \\
        [--stride 5 5 9] [--res 48] [--spp 128] [--png NAME ...] \\
        [--state benchmarks/results/material_check] [--out benchmarks/results/material_check.md]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from benchmarks.render_check import TARGET_RATIO, TARGET_RMSE, _png, is_matte, render_check

STATE = Path("benchmarks/results/material_check")


def _form_row(f) -> dict:
    e = f.export
    return {
        "spec": f.spec,
        "n_free": f.n_free,
        "albedo": f.error.albedo,
        "point": f.error.point,
        "score": f.error.score,
        "ratio": list(f.error.ratio),
        "exact": None if e is None else bool(e.exact),
        "export_error": None if e is None else float(e.error),
        "target_model": None if e is None else e.target_model,
        "seconds": f.seconds,
        "status": f.result.status.name,
    }


def run_file(path: Path, stride, res: int, spp: int, png_dir: Path | None) -> dict:
    """Both targets' material runs and the Mitsuba render of one file, as a JSON-able dict."""
    import brdffit
    from brdffit.export.material import best_material
    from brdffit.export.render_score import Measured

    t0 = time.perf_counter()
    data = brdffit.read_rgl(path, stride=tuple(stride))
    full = Measured.of(brdffit.read_rgl(path))  # the scores' side, read once for both
    out: dict = {"file": path.name, "read_s": time.perf_counter() - t0}
    mit = best_material(data, "mitsuba", measured=full)
    glt = best_material(data, "gltf", measured=full, reference=None)
    glt = dataclasses.replace(glt, reference=mit.reference)
    for name, m in (("mitsuba", mit), ("gltf", glt)):
        out[name] = {
            "forms": [_form_row(f) for f in m.forms],
            "chosen": m.chosen.spec,
            "written": m.chosen.export.target_model,
            "missing": m.missing(),
        }
    out["reference"] = _form_row(mit.reference)
    bsdf = mit.chosen.export.material
    r = render_check(path, {"chosen": bsdf}, res=res, spp=spp)
    out["render"] = {light: r["chosen"][light] for light in ("env", "point")}
    out["noise"] = r["noise"]
    out["measured_mean"] = r["measured_mean"]
    if png_dir is not None:
        _png(png_dir / f"{path.stem}.png", r["images"], ["chosen"])
    out["seconds"] = time.perf_counter() - t0
    return out


DARK = 0.05
"""A channel whose measured env mean is below this fraction of the brightest channel's:
its ratio is noise over ~0 (cg_sunflower's blue), judged apart (:func:`_meets_lit`)."""


def _meets(env: dict) -> bool:
    lo, hi = TARGET_RATIO
    return env["rel_rmse"] <= TARGET_RMSE and all(lo <= x <= hi for x in env["ratio"])


def _meets_lit(r: dict) -> bool:
    """:func:`_meets` with the ratio of a :data:`DARK` channel not judged."""
    env, mean = r["render"]["env"], r["measured_mean"]["env"]
    lo, hi = TARGET_RATIO
    lit = [x for x, m in zip(env["ratio"], mean, strict=True) if m >= DARK * max(mean)]
    return env["rel_rmse"] <= TARGET_RMSE and all(lo <= x <= hi for x in lit)


def _why(r: dict) -> str:
    """What keeps a file from the env target, from its own figures."""
    env = r["render"]["env"]
    parts = []
    if env["rel_rmse"] > TARGET_RMSE:
        parts.append(f"env rel RMSE {env['rel_rmse']:.3f}")
    lo, hi = TARGET_RATIO
    off = [f"{c} {x:.2f}" for c, x in zip("RGB", env["ratio"], strict=True) if not lo <= x <= hi]
    if off:
        parts.append("colour " + ", ".join(off))
    ref, chosen = (
        r["reference"],
        next(f for f in r["mitsuba"]["forms"] if f["spec"] == r["mitsuba"]["chosen"]),
    )
    if ref["score"] < chosen["score"] * 0.9:
        parts.append(f"richer form scores {ref['score']:.3f} vs {chosen['score']:.3f}")
    return "; ".join(parts)


def table(results: list[dict]) -> list[str]:
    """The Markdown tables and the target summary."""
    lines = [
        "| material | class | Mitsuba form (written) | env rel RMSE | point rel RMSE | env ratio "
        "R, G, B | noise env/point | env target | glTF form | glTF albedo / point err "
        "| two lobes + sheen albedo / point err | what keeps it from the target |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        name = r["file"].removesuffix("_rgb.bsdf")
        env, pt = r["render"]["env"], r["render"]["point"]
        g = next(f for f in r["gltf"]["forms"] if f["spec"] == r["gltf"]["chosen"])
        ref = r["reference"]
        lines.append(
            f"| {name} | {'matte' if is_matte(name) else 'glossy/layered'} "
            f"| {r['mitsuba']['chosen']} ({r['mitsuba']['written']}) | {env['rel_rmse']:.3f} "
            f"| {pt['rel_rmse']:.3f} | {', '.join(f'{x:.2f}' for x in env['ratio'])} "
            f"| {r['noise']['env']:.3f}/{r['noise']['point']:.3f} "
            f"| {'meets' if _meets(env) else 'misses'} | {r['gltf']['chosen']} "
            f"| {g['albedo']:.3f} / {g['point']:.3f} | {ref['albedo']:.3f} / {ref['point']:.3f} "
            f"| {'' if _meets(env) else _why(r)} |"
        )
    n = len(results)
    meets = sum(_meets(r["render"]["env"]) for r in results)
    med = statistics.median(r["render"]["point"]["rel_rmse"] for r in results) if n else np.nan
    exact_err = [
        f["export_error"]
        for r in results
        for t in ("mitsuba", "gltf")
        for f in r[t]["forms"]
        if f["exact"]
    ]
    worst = max(exact_err, default=float("nan"))
    inexact = sorted(
        {
            f"{r['file'].removesuffix('_rgb.bsdf')}: {f['spec']} {f['export_error']:.3f}"
            for r in results
            for f in r["mitsuba"]["forms"]
            if f["exact"] is False and f["spec"] == r["mitsuba"]["chosen"]
        }
    )
    lit = sum(_meets_lit(r) for r in results)
    lines += [
        "",
        f"- env target met on {meets} of {n} files ({100 * meets / max(n, 1):.0f}%; target 85%)",
        f"- the same, a channel darker than {DARK:.0%} of the brightest not judged by its "
        f"ratio: {lit} of {n} ({100 * lit / max(n, 1):.0f}%)",
        f"- median point-light rel RMSE of the chosen Mitsuba form: {med:.3f} (target 0.15)",
        f"- largest export error among exact forms: {worst:.2e} (target 0.05)",
        f"- chosen Mitsuba forms whose export is not exact: {', '.join(inexact) or 'none'}",
    ]
    return lines


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--stride", nargs=3, type=int, default=(5, 5, 9))
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--spp", type=int, default=128)
    ap.add_argument("--png", nargs="*", default=(), help="material names to save PNGs of")
    ap.add_argument("--state", type=Path, default=STATE)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/material_check.md"))
    args = ap.parse_args(argv)
    from brdffit.util.atomic import write_text

    args.state.mkdir(parents=True, exist_ok=True)
    for path in sorted(args.files):
        done = args.state / f"{path.stem}.json"
        if done.exists():
            continue
        name = path.stem.removesuffix("_rgb")
        print(f"material_check: {name}", flush=True)
        try:
            png = args.state if name in args.png else None
            r = run_file(path, args.stride, args.res, args.spp, png)
        except Exception as exc:  # a benchmark reports every failure and goes on
            print(f"material_check: {name} failed: {type(exc).__name__}: {exc}", flush=True)
            continue
        write_text(done, json.dumps(r, indent=1))
        env = r["render"]["env"]
        print(
            f"  {r['mitsuba']['chosen']}: env {env['rel_rmse']:.3f}, point "
            f"{r['render']['point']['rel_rmse']:.3f}, {r['seconds']:.0f} s",
            flush=True,
        )
    results = [json.loads(p.read_text()) for p in sorted(args.state.glob("*.json"))]
    notes = args.out.with_suffix(".notes.md")  # what the pictures show, written by hand
    tail = [notes.read_text()] if notes.exists() else []
    write_text(args.out, "\n".join(["# Material check", "", *table(results), "", *tail]))


if __name__ == "__main__":
    main()
