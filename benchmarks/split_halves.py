"""Do the reported intervals hold on measured data? Two fits to two disjoint halves.

For each NBRDF material (``--materials``, default 24 spread over the alphabetical list of
``../shared/data/merl_nbrdf``) on a strided MERL grid, the cells are split into two
halves by the parity of their (theta_h, theta_d) block (the blocks of
``errors="blocks"``, :data:`brdffit.engine.uncertainty.BLOCK_DEG`) (a checkerboard, so
each half sees every region of the BRDF but no block of the other). The same model is
fitted to each half, once per kind of standard error, and each free scalar gives

    z = (a - b) / sqrt(se_a^2 + se_b^2)

If the intervals mean what they say, |z| <= 1.96 for 95% of the scalars (the halves
share no block, so under each interval's own assumptions the two estimates are
independent). Model error that neighbouring cells share makes the per-sample sandwich
far too narrow; ``errors="blocks"`` is built to admit it (:mod:`brdffit.engine.uncertainty`).
Scalars with no standard error (held on a bound) are left out and counted.

Run: python3 benchmarks/split_halves.py [--model walter] [--metric low_e2]
     [--stride 3 3 5] [--n 24] [--out benchmarks/results/split_halves.md]
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

import brdffit
from brdffit import fit, models
from brdffit.core.measurements import Measurements
from brdffit.engine.metrics import get_metric, keep_mask, prepare
from brdffit.engine.uncertainty import block_cells
from brdffit.io.load import load_measurements

NBRDF = Path(__file__).resolve().parents[2] / "shared" / "data" / "merl_nbrdf"
KINDS = ("sandwich", "classic", "blocks")


def materials(n: int) -> list[Path]:
    """``n`` materials evenly spread over the sorted NBRDF list."""
    files = sorted(NBRDF.glob("*.json"))
    pick = np.unique(np.linspace(0, len(files) - 1, n).round().astype(int))
    return [files[i] for i in pick]


def halves(data: Measurements, cut_deg: float) -> tuple[Measurements, Measurements]:
    """The cells of even and of odd (theta_h, theta_d) block parity, inside the cut."""
    keep = np.flatnonzero(keep_mask(data, cut_deg))
    prep = prepare(data, get_metric("low_e2"), keep=keep)
    i, j = block_cells(prep)
    parity = (i + j) % 2
    out = []
    for side in (0, 1):
        k = keep[parity == side]
        out.append(
            Measurements.from_directions(
                data.wi[k], data.wo[k], data.values[k], source=f"{data.source} half {side}"
            )
        )
    return out[0], out[1]


def z_scores(model, a: Measurements, b: Measurements, metric: str, kind: str) -> np.ndarray:
    """z of every free scalar for one kind of error (NaN where an error is missing)."""
    ra = fit(model, a, metric, errors=kind, cut_deg=None, throw=False)
    rb = fit(model, b, metric, errors=kind, cut_deg=None, throw=False)
    if ra.stderr is None or rb.stderr is None:
        return np.full(sum(np.size(v) for v in ra.params.values()), np.nan)
    z = []
    for name in ra.params:
        va, vb = np.ravel(ra.params[name]), np.ravel(rb.params[name])
        sa, sb = np.ravel(ra.stderr[name]), np.ravel(rb.stderr[name])
        with np.errstate(invalid="ignore", divide="ignore"):
            z.extend((va - vb) / np.sqrt(sa**2 + sb**2))
    return np.asarray(z, float)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", default="walter")
    ap.add_argument("--metric", default="low_e2")
    ap.add_argument("--stride", type=int, nargs=3, default=(3, 3, 5))
    ap.add_argument("--n", type=int, default=24)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    import jax

    brdffit.enable_compilation_cache()
    model = models.from_spec(args.model)
    t0 = time.perf_counter()
    rows, allz = [], {k: [] for k in KINDS}
    for path in materials(args.n):
        data = load_measurements(path, stride=tuple(args.stride))
        a, b = halves(data, 80.0)
        cells = []
        for kind in KINDS:
            z = z_scores(model, a, b, args.metric, kind)
            allz[kind].append(z)
            ok = np.isfinite(z)
            cells.append(f"{np.mean(np.abs(z[ok]) <= 1.96):.0%}" if ok.any() else "n/a")
            cells.append(f"{np.median(np.abs(z[ok])):.2f}" if ok.any() else "n/a")
        rows.append(f"| {path.stem} | {a.n} / {b.n} | " + " | ".join(cells) + " |")
        print(rows[-1], flush=True)
    head = " | ".join(f"{k} within | {k} median abs z" for k in KINDS)
    lines = [
        f"# Split halves: {models.label(model)}, {args.metric}, stride {tuple(args.stride)}",
        "",
        f"Command: `python3 benchmarks/split_halves.py --model {args.model} --metric "
        f"{args.metric} --stride {' '.join(map(str, args.stride))} --n {args.n}`",
        f"Machine: {platform.processor() or platform.machine()}, {jax.devices()[0]}; "
        f"{time.perf_counter() - t0:.0f} s.",
        "",
        "Share of free scalars whose two half-fits agree within their stated 95% interval",
        "(|z| <= 1.96; 95% if the intervals are right) and the median |z| (0.67 if right).",
        "",
        f"| material | cells (halves) | {head} |",
        "|---" * (2 + 2 * len(KINDS)) + "|",
        *rows,
    ]
    total = []
    for kind in KINDS:
        z = np.concatenate(allz[kind])
        ok = np.isfinite(z)
        total.append(
            f"- **{kind}**: {np.mean(np.abs(z[ok]) <= 1.96):.1%} of {ok.sum()} scalars within "
            f"(median |z| {np.median(np.abs(z[ok])):.2f}; {np.sum(~ok)} without an error)"
        )
    lines += ["", "All materials:", "", *total, ""]
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
