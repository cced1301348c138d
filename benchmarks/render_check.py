"""Render check: a fitted, exported material against Mitsuba's own ``measured`` plugin.

Issue 28, item 3. For each RGL-EPFL ``.bsdf`` file given: read it on a strided MERL grid
(:func:`brdffit.read_rgl`), fit each model (``--metric``, default ``ngan``; default
starts), export the fit to Mitsuba 3 (:func:`brdffit.write_exports`, target
``mitsuba``), then render a unit sphere with Mitsuba twice, once with ``{"type":
"measured", "filename": FILE}`` and once with the exported BSDF, in the same scene
(orthographic camera along -z, box pixel filter, ``direct`` integrator, ``independent``
sampler, same seed, resolution and spp), under

- ``env``: a white constant environment of radiance 1 (a pixel then holds the directional
  albedo of the material for its view direction);
- ``point``: a point light at (3, 3, 4), intensity 34 (unit irradiance at the centre).

Measured, over the pixels whose whole footprint lies on the sphere (:func:`sphere_mask`):

- ``rel RMSE``: ``||export - measured|| / ||measured||`` over those pixels and the three
  channels (linear radiance), per lighting;
- ``ratio``: mean export radiance / mean measured radiance per channel, under ``env``;
- ``noise``: the rel RMSE between two renders of the measured file with seeds 0 and 1,
  about sqrt(2) times the Monte Carlo noise of one render: a rel RMSE near it is noise.

Why ``ngan`` by default: under ``env`` a pixel is the directional albedo ``a(wo) =
integral of f cos(theta_i) d(wi)``, and by Cauchy-Schwarz the solid-angle RMS over the
views of ``a``'s error, the part of it inside the cut, is at most ``Omega`` times
``ngan``'s loss (``Omega = 2 pi (1 - cos 80 deg) = 5.19`` sr, the incident directions
inside the cut), which is what ``ngan`` minimises; the log metrics bound nothing of the
kind (``--metric low_e2`` gives their figures; benchmarks/results/render_check.md has
both).

Target (issue 28): on materials the model family can represent (felts, papers, leaves,
matte paints) rel RMSE <= 0.10 and every channel's ratio in [0.90, 1.10] under ``env``.

Mitsuba runs in a subprocess (the variant, ``scalar_rgb`` by default, is the one whose
``measured`` plugin works on this machine; ``llvm_ad_rgb`` aborts there, see
brdffit/io/rgl.py): a crash cannot take the benchmark down and is reported.

Run (15-90 s per material and three models, 6 min for 11 files, on the 2-core box):

    nice python -m benchmarks.render_check /work/rgl_data/*.bsdf \\
        [--models "lambert,walter,disney[subsurface=false,clearcoat=false,anisotropic=false]"] \\
        [--metric ngan] [--stride 3 3 5] [--res 64] [--spp 256] [--png NAME ...] \\
        [--out benchmarks/results/render_check.md] [--title TEXT] [--append]

Latest figures: benchmarks/results/render_check.md. :func:`render_check` and
:func:`sphere_mask` are plain functions (numpy and a Mitsuba subprocess, no brdffit), used
by tests/benchmarks/test_render_check.py.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

DEFAULT_MODELS = "lambert,walter,disney[subsurface=false,clearcoat=false,anisotropic=false]"
LIGHTS = ("env", "point")
SCALE = 1.05  # half-width of the orthographic view, sphere radii
POINT_POSITION = (3.0, 3.0, 4.0)
POINT_INTENSITY = 34.0  # |position|^2: unit irradiance at the sphere's centre
TARGET_RMSE = 0.10
TARGET_RATIO = (0.90, 1.10)
MATTE_WORDS = ("felt", "paper", "leaf", "matte", "cardboard", "colodur")

# The worker: argv = variant, job file (JSON list of {bsdf, light, res, spp, seed, out}).
_WORKER = r"""
import json, sys
import numpy as np
variant, job_path = sys.argv[1:3]
import mitsuba as mi
mi.set_variant(variant)
T = mi.ScalarTransform4f
for job in json.load(open(job_path)):
    res, s = job["res"], job["scale"]
    sensor = {
        "type": "orthographic",
        "to_world": T().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0])
        @ T().scale([s, s, 1.0]),
        "film": {"type": "hdrfilm", "width": res, "height": res, "pixel_format": "rgb",
                 "rfilter": {"type": "box"}},
        "sampler": {"type": "independent", "sample_count": job["spp"]},
    }
    if job["light"] == "env":
        light = {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}}
    else:
        light = {"type": "point", "position": job["position"],
                 "intensity": {"type": "rgb", "value": job["intensity"]}}
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "direct"}, "sensor": sensor,
                          "sphere": {"type": "sphere", "bsdf": job["bsdf"]}, "light": light})
    np.save(job["out"], np.array(mi.render(scene, seed=job["seed"]), dtype=np.float64))
"""


def sphere_mask(res: int, scale: float = SCALE) -> np.ndarray:
    """(res, res) bool: pixels whose whole square footprint lies inside the unit sphere's disc.

    The orthographic view spans ``[-scale, scale]`` on both axes; a pixel is kept when its
    centre's distance from the axis plus its half-diagonal is below 1, so no kept pixel
    mixes sphere and background.
    """
    c = (np.arange(res) + 0.5) / res * 2 * scale - scale
    x, y = np.meshgrid(c, c)
    return np.hypot(x, y) + np.sqrt(2) * scale / res < 1.0


def compare(test: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> dict[str, object]:
    """``rel_rmse`` (``||test - ref|| / ||ref||`` over masked pixels, all channels) and
    ``ratio`` (per channel: mean of ``test`` / mean of ``ref`` over masked pixels)."""
    a, b = test[mask], ref[mask]
    rel = float(np.sqrt(np.sum((a - b) ** 2) / np.sum(b**2)))
    ratio = tuple(float(x) for x in a.mean(0) / b.mean(0))
    return {"rel_rmse": rel, "ratio": ratio}


def _render(jobs: list[dict], variant: str, folder: Path) -> list[np.ndarray]:
    path = folder / "jobs.json"
    path.write_text(json.dumps(jobs))
    done = subprocess.run(
        [sys.executable, "-c", _WORKER, variant, str(path)], capture_output=True, text=True
    )
    if done.returncode != 0:
        tail = " ".join(done.stderr.split()[-40:])
        raise RuntimeError(f"Mitsuba worker ({variant}) exited {done.returncode}: {tail}")
    return [np.load(j["out"]) for j in jobs]


def render_check(
    bsdf_file: str | Path,
    materials: Mapping[str, dict],
    *,
    res: int = 64,
    spp: int = 256,
    seed: int = 0,
    variant: str = "scalar_rgb",
) -> dict[str, object]:
    """Render ``bsdf_file`` with ``measured`` and each of ``materials`` (label -> Mitsuba
    BSDF dict) on the sphere under both lightings and compare (module docstring).

    Returns ``{"measured_mean": {light: mean RGB over the sphere}, "noise": {light:
    rel_rmse}, "images": {label or "measured": {light:
    (res, res, 3)}}, label: {light: compare(...)}}``. Raises ``RuntimeError`` when the
    Mitsuba worker crashes.
    """
    measured = {"type": "measured", "filename": str(Path(bsdf_file).resolve())}
    bsdfs = {"measured": measured, **materials}
    with tempfile.TemporaryDirectory(prefix="render_check.") as tmp:
        folder = Path(tmp)
        jobs, keys = [], []
        for label in bsdfs:
            keys += [(label, light, seed) for light in LIGHTS]
        keys += [("measured", light, seed + 1) for light in LIGHTS]
        for k, (label, light, s) in enumerate(keys):
            jobs.append(
                {
                    "bsdf": bsdfs[label],
                    "light": light,
                    "res": res,
                    "spp": spp,
                    "seed": s,
                    "scale": SCALE,
                    "position": list(POINT_POSITION),
                    "intensity": POINT_INTENSITY,
                    "out": str(folder / f"{k}.npy"),
                }
            )
        images = dict(zip(keys, _render(jobs, variant, folder), strict=True))
    mask = sphere_mask(res)
    ref = {light: images[("measured", light, seed)] for light in LIGHTS}
    out: dict[str, object] = {
        "measured_mean": {light: tuple(ref[light][mask].mean(0).tolist()) for light in LIGHTS},
        "noise": {
            light: compare(images[("measured", light, seed + 1)], ref[light], mask)["rel_rmse"]
            for light in LIGHTS
        },
        "images": {
            label: {light: images[(label, light, seed)] for light in LIGHTS} for label in bsdfs
        },
    }
    for label in materials:
        out[label] = {
            light: compare(images[(label, light, seed)], ref[light], mask) for light in LIGHTS
        }
    return out


# ---- the benchmark proper (brdffit imported here only) ----


def mask_summary(m) -> str:
    """Samples above the horizon and inside the 80-degree fit cut: how many the reader
    masks whole, per channel (when it keeps a per-channel mask), and how many hold a
    negative value in some channel (masked or kept, depending on the reader)."""
    wi, wo = np.asarray(m.wi), np.asarray(m.wo)
    cos80 = np.cos(np.radians(80.0))
    inside = (wi[:, 2] > cos80) & (wo[:, 2] > cos80)
    n = int(inside.sum())
    valid = np.asarray(m.valid)
    channels = getattr(m, "channel_valid", None)
    channels = valid if valid.ndim == 2 else channels
    whole = int((inside & ~(valid if valid.ndim == 1 else valid.any(1))).sum())
    text = f"{whole} of {n} ({100 * whole / n:.1f}%) masked"
    if channels is not None:
        per = "/".join(str(int((inside & ~np.asarray(channels)[:, c]).sum())) for c in range(3))
        text += f", per channel R/G/B {per}"
    neg = int((inside & (np.asarray(m.values) < 0).any(1)).sum())
    return text + f"; {neg} with a negative channel"


def is_matte(name: str) -> bool:
    """A material the issue's target applies to (felts, papers, leaves, matte paints)."""
    return any(w in name for w in MATTE_WORDS) and "metallic" not in name


def _fit_and_export(path: Path, specs: Sequence[str], stride, folder: Path, metric: str):
    import brdffit  # deferred: render_check() and sphere_mask() run without brdffit
    from brdffit import models

    t = time.perf_counter()
    try:
        data = brdffit.read_rgl(path, stride=tuple(stride))
        masked = mask_summary(data)
    except Exception as exc:  # an unreadable file: every model a failed row, the run goes on
        why = f"{type(exc).__name__}: {exc}"
        fits = {spec: {"error": why} for spec in specs}
        return {
            "read_s": time.perf_counter() - t,
            "masked": "not read",
            "read_error": why,
            "fits": fits,
        }
    rows = {"read_s": time.perf_counter() - t, "masked": masked, "fits": {}}
    for spec in specs:
        row: dict[str, object] = {}
        try:
            t = time.perf_counter()
            r = brdffit.fit(models.from_spec(spec), data, metric)
            row["fit_s"] = time.perf_counter() - t
            row["status"] = r.status.name
            prefix = folder / f"{path.stem}.{spec.split('[')[0]}"
            ((e, _),) = brdffit.write_exports(r, ["mitsuba"], prefix)
            row |= {"target": e.target_model, "export_error": e.error, "material": e.material}
            row["params"] = {
                k: np.round(np.asarray(v, float), 4).tolist() for k, v in r.params.items()
            }
        except Exception as exc:  # a benchmark reports every failure and goes on
            row["error"] = f"{type(exc).__name__}: {exc}"
        rows["fits"][spec] = row
    return rows


def _png(path: Path, images: Mapping[str, Mapping[str, np.ndarray]], labels: Sequence[str]) -> None:
    """Rows: env, point; columns: measured, then each label; sRGB, 2x nearest upscaling."""
    import matplotlib.image  # deferred: heavy, figures only

    def srgb(x: np.ndarray, exposure: float) -> np.ndarray:
        x = np.clip(exposure * np.nan_to_num(x), 0.0, 1.0)
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)

    res = images["measured"]["env"].shape[0]
    c = (np.arange(res) + 0.5) / res * 2 * SCALE - SCALE
    off = np.hypot(*np.meshgrid(c, c)) > 1.0  # background: grey, so a white sphere shows
    rows = []
    for light, exposure in (("env", 1.0), ("point", 2.0)):
        tiles = [srgb(images[k][light], exposure) for k in ("measured", *labels)]
        for t in tiles:
            t[off] = 0.35
        gap = np.ones((tiles[0].shape[0], 2, 3))
        rows.append(np.concatenate([t for tile in tiles for t in (tile, gap)][:-1], axis=1))
    grid = np.concatenate([rows[0], np.ones((2, rows[0].shape[1], 3)), rows[1]], axis=0)
    grid = grid.repeat(2, 0).repeat(2, 1)
    path.parent.mkdir(parents=True, exist_ok=True)
    matplotlib.image.imsave(path, grid)


def _short(spec: str) -> str:
    return spec.split("[")[0]


def _meets(env: Mapping[str, object]) -> bool:
    lo, hi = TARGET_RATIO
    return env["rel_rmse"] <= TARGET_RMSE and all(lo <= x <= hi for x in env["ratio"])


def _best_table(results: dict, specs: Sequence[str]) -> list[str]:
    """Per material, the model with the smallest env rel RMSE (point rel RMSE breaks ties)."""
    lines = [
        "| material | class | best model | env rel RMSE | point rel RMSE | env ratio R, G, B "
        "| target |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, r in results.items():
        done = [s for s in specs if s in r.get("render", {})]
        if not done:
            lines.append(f"| {name} | | none rendered | | | | |")
            continue
        best = min(done, key=lambda s: (r["render"][s]["env"]["rel_rmse"], s))
        env, pt = r["render"][best]["env"], r["render"][best]["point"]
        cls = "matte" if is_matte(name) else "glossy/layered"
        verdict = "meets" if _meets(env) else "misses"
        lines.append(
            f"| {name} | {cls} | {_short(best)} | {env['rel_rmse']:.3f} | {pt['rel_rmse']:.3f} "
            f"| {', '.join(f'{x:.3f}' for x in env['ratio'])} | {verdict} |"
        )
    return lines


def _table(results: dict, specs: Sequence[str]) -> list[str]:
    lines = [
        "| material | class | masked inside 80° (of the strided grid) | measured env mean R, G, B "
        "| model -> Mitsuba BSDF | export err | env rel RMSE | point rel RMSE "
        "| env ratio R, G, B | noise env/point | target |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in results.items():
        cls = "matte" if is_matte(name) else "glossy/layered"
        noise = r.get("noise", {})
        for spec in specs:
            f = r["fits"][spec]
            mean = ", ".join(f"{x:.3f}" for x in r.get("measured_mean", {}).get("env", ()))
            head = f"| {name} | {cls} | {r['masked']} | {mean} | {_short(spec)}"
            if "error" in f or spec not in r.get("render", {}):
                why = f.get("error") or r.get("render_error", "not rendered")
                lines.append(f"{head} | failed: {why[:120]} | | | | | |")
                continue
            c = r["render"][spec]
            env, pt = c["env"], c["point"]
            ok = _meets(env)
            if cls == "matte":
                verdict = "meets" if ok else "misses"
            else:
                verdict = "(meets)" if ok else "-"
            lines.append(
                f"{head} -> {f['target']} | {f['export_error']:.3f} | {env['rel_rmse']:.3f} "
                f"| {pt['rel_rmse']:.3f} | {', '.join(f'{x:.3f}' for x in env['ratio'])} "
                f"| {noise['env']:.3f}/{noise['point']:.3f} | {verdict} |"
            )
    return lines


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--models", default=DEFAULT_MODELS, help="comma-separated model specs")
    ap.add_argument("--stride", nargs=3, type=int, default=(3, 3, 5))
    ap.add_argument("--metric", default="ngan", help="fitting metric (brdffit metrics)")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--variant", default=os.environ.get("BRDFFIT_RGL_VARIANT", "scalar_rgb"))
    ap.add_argument("--png", nargs="*", default=(), help="material names to save PNGs of")
    ap.add_argument("--png-dir", type=Path, default=Path("benchmarks/results/render_check"))
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/render_check.md"))
    ap.add_argument("--json", type=Path, default=None, help="also write every figure as JSON")
    ap.add_argument("--title", default="Render check")
    ap.add_argument("--append", action="store_true")
    args = ap.parse_args(argv)

    import brdffit  # deferred: render_check() and sphere_mask() run without brdffit
    from brdffit.models import split_specs

    specs = split_specs(args.models)
    results: dict[str, dict] = {}
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="render_check_exports.") as tmp:
        for path in args.files:
            name = path.name.removesuffix(".bsdf").removesuffix("_rgb")
            t = time.perf_counter()
            r = _fit_and_export(path, specs, args.stride, Path(tmp), args.metric)
            mats = {s: f["material"] for s, f in r["fits"].items() if "material" in f}
            if "read_error" in r:  # unreadable: nothing to render, its rows say why
                r["render_error"] = f"not rendered: {r['read_error']}"
            else:
                try:
                    chk = render_check(path, mats, res=args.res, spp=args.spp, variant=args.variant)
                    r["noise"] = chk["noise"]
                    r["measured_mean"] = chk["measured_mean"]
                    r["render"] = {s: chk[s] for s in mats}
                    if name in args.png:
                        _png(args.png_dir / f"{name}.png", chk["images"], list(mats))
                except RuntimeError as exc:
                    r["render_error"] = str(exc)
            r["total_s"] = time.perf_counter() - t
            results[name] = r
            print(f"{name}: {r['total_s']:.0f} s", file=sys.stderr, flush=True)
            for line in _table({name: r}, specs)[2:]:
                print(line, file=sys.stderr, flush=True)
    total = time.perf_counter() - t_all

    import mitsuba  # deferred: optional dependency

    try:
        commit = subprocess.run(
            ["git", "-C", str(Path(brdffit.__file__).parent), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = "?"
    lines = [
        f"## {args.title}",
        "",
        f"brdffit from `{Path(brdffit.__file__).parent}` (repository HEAD {commit}), "
        f"Mitsuba {mitsuba.__version__} `{args.variant}`, {platform.machine()} "
        f"{os.cpu_count()} cores; stride {' '.join(map(str, args.stride))}, metric {args.metric}, "
        f"{args.res}x{args.res} px, {args.spp} spp, seed 0; {total / 60:.1f} min in all.",
        "",
        "Best model per material (smallest env rel RMSE):",
        "",
        *_best_table(results, specs),
        "",
        "Every model:",
        "",
        *_table(results, specs),
        "",
        "Fitted parameters (natural units) and fit times:",
        "",
    ]
    for name, r in results.items():
        for spec, f in r["fits"].items():
            if "params" in f:
                p = "; ".join(f"{k} {v}" for k, v in f["params"].items())
                lines.append(f"- {name} {_short(spec)} ({f['status']}, {f['fit_s']:.1f} s): {p}")
    text = "\n".join(lines) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if args.append and args.out.exists():
        text = args.out.read_text() + "\n" + text
    args.out.write_text(text)
    if args.json:
        slim = {n: {k: v for k, v in r.items()} for n, r in results.items()}
        args.json.write_text(json.dumps(slim, indent=1, default=str))
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
