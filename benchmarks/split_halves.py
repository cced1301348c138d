"""Do the reported intervals hold on measured data? Two fits to two disjoint halves.

Each data set (``--nbrdf N`` NBRDF materials spread over the alphabetical list of
``../shared/data/merl_nbrdf``, and the RGL-EPFL ``.bsdf`` files given with ``--rgl``) is
evaluated on a strided MERL grid, and its cells are split into two halves by the parity of
their 10-degree (theta_h, theta_d) block (:data:`SPLIT_DEG`): a checkerboard, so each
half sees every region of the BRDF but no block of the other. The same model is fitted to
each half, and each free scalar gives

    z = (a - b) / sqrt(se_a^2 + se_b^2)

for every kind of standard error below, all computed at the same two optima. If the
intervals mean what they say, 95% of the scalars have ``|z| <= 1.96``. For ``blocks``,
whose intervals are Student-t ones (``t_0.975(nu)`` CR2 errors wide), ``z`` is the CR2
difference ``(a - b) / sqrt(v_a + v_b)`` over ``t_0.975(nu_ab) / 1.96``, ``nu_ab`` the
Welch-Satterthwaite degrees of freedom of the summed variance,
``(v_a + v_b)^2 / (v_a^2 / nu_a + v_b^2 / nu_b)`` (Welch 1947): the difference of two
estimates has more degrees of freedom than either, so adding the two t-widened errors
in quadrature would overstate its spread by ``t(nu) / t(2 nu)``, 1.30 at ``nu = 3``. The table's
**factor** is the 95th percentile of ``|z|`` over 1.96: the number the stated intervals
would have to be multiplied by to hold 95% of the half differences (1 if calibrated,
above 1 overconfident, below 1 conservative).

Kinds (:mod:`brdffit.engine.block_errors`; ``--block-deg`` sets their blocks, the split
stays at :data:`SPLIT_DEG`):

- ``sandwich``: independent residuals (the default for synthetic data);
- ``CR1``: plain cluster sandwich; ``CR3``: one-step cluster jackknife; ``CR2``:
  bias-reduced cluster sandwich, normal quantiles;
- ``blocks``: what ``errors="blocks"`` reports (the default for measured data): CR2
  widened to the Student-t interval of Bell and McCaffrey's degrees of freedom
  (``z`` by Welch, above).

Scalars without an error (held on a bound, or no covariance) are left out and counted.

Run: python -m benchmarks.split_halves [--model walter] [--metric low_e2]
     [--stride 3 3 5] [--nbrdf 24] [--rgl FILE ...] [--block-deg 10] [--out F.md]
     [--z-out F.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np

import brdffit
from brdffit import fit, models
from brdffit.core.measurements import Measurements
from brdffit.engine import objective as objective_mod
from brdffit.engine.block_errors import (
    block_cells,
    block_chunks,
    block_covariance,
    coverage_factor,
    effective_dof,
)
from brdffit.engine.metrics import get_metric, keep_mask, prepare
from brdffit.engine.objective import Objective
from brdffit.engine.uncertainty import covariance, errors_at
from brdffit.io.load import load_measurements
from brdffit.util.atomic import write_text

NBRDF = Path(__file__).resolve().parents[2] / "shared" / "data" / "merl_nbrdf"
KINDS = ("sandwich", "CR1", "CR2", "CR3", "blocks")
SPLIT_DEG = 10.0
"""Side of the checkerboard's blocks, degrees: fixed, whatever blocks the errors use."""
CUT_DEG = 80.0


def materials(n: int) -> list[Path]:
    """``n`` materials evenly spread over the sorted NBRDF list."""
    files = sorted(NBRDF.glob("*.json"))
    pick = np.unique(np.linspace(0, len(files) - 1, n).round().astype(int))
    return [files[i] for i in pick]


def halves(data: Measurements) -> tuple[Measurements, Measurements]:
    """The cells of even and of odd :data:`SPLIT_DEG` block parity, inside the cut."""
    keep = np.flatnonzero(keep_mask(data, CUT_DEG))
    prep = prepare(data, get_metric("low_e2"), keep=keep)
    i, j = block_cells(prep, SPLIT_DEG)
    parity = (i + j) % 2
    return tuple(
        Measurements.from_directions(
            data.wi[k], data.wo[k], data.values[k], source=f"{data.source} half {side}"
        )
        for side in (0, 1)
        for k in [keep[parity == side]]
    )


def errors_at_optimum(model, data: Measurements, metric: str, block_deg: float) -> tuple:
    """Fit ``data``; the free scalars' values and each kind's standard errors (NaN where a
    scalar is held on a bound or a kind gives none), each from the covariance over the
    scalars the fit's own errors use (those held loosely on a bound included:
    :func:`brdffit.engine.uncertainty.errors_at`, with the blocks' errors)."""
    r = fit(model, data, metric, errors="blocks", cut_deg=None, throw=False)
    obj = Objective.build(model)
    z = jnp.asarray(obj.layout.solver_vector(r.params))
    prep = prepare(data, get_metric(metric), cut_deg=None)
    x = obj.layout.natural_vector(r.params)
    out = {k: np.full(x.size, np.nan) for k in KINDS}
    nu = np.full(x.size, np.nan)
    if r.stderr is None:  # no covariance at this optimum (singular J^T J): no scalar
        return x, out, nu, r
    free = np.isfinite(np.concatenate([np.ravel(r.stderr[p]) for p in r.params]))
    chunks = block_chunks(prep, block_deg)
    moments = objective_mod.natural_block_moments(obj, z, prep, chunks)
    _, _, scores, grams = (np.asarray(a) for a in moments)
    # the scalars the covariance is over, as the fit's own errors choose them
    act = errors_at(obj, z, prep, ~free, "blocks", "blocks", chunks, moments, 3 * prep.n).scalars
    jtj, meat, ee, _, _ = (np.asarray(a) for a in objective_mod.natural_moments(obj, z, prep))
    ix = np.ix_(act, act)
    cov = covariance(jtj[ix], meat[ix], float(ee), 3 * prep.n, "sandwich")[0]
    if cov is not None:
        out["sandwich"][act] = np.sqrt(np.diag(cov))
    jtj, scores, grams = jtj[ix], scores[:, act], grams[:, act][:, :, act]
    for kind, power in (("CR1", 0.0), ("CR2", 0.5), ("CR3", 1.0)):
        cov = block_covariance(jtj, scores, grams, power)[0]
        if cov is not None:
            out[kind][act] = np.sqrt(np.diag(cov))
    dof = effective_dof(jtj, grams)
    if dof is not None:
        out["blocks"][act] = out["CR2"][act] * coverage_factor(dof)
        nu[act] = dof
    for se in (*out.values(), nu):
        se[~free] = np.nan
    return x, out, nu, r


def welch_z(xa, xb, se_a, se_b, nu_a, nu_b) -> np.ndarray:
    """The CR2 difference ``(a - b) / sqrt(v_a + v_b)`` over the Welch-Satterthwaite
    coverage factor ``t_0.975(nu_ab) / 1.96`` (module docstring)."""
    va, vb = se_a**2, se_b**2
    with np.errstate(invalid="ignore", divide="ignore"):
        nu_ab = (va + vb) ** 2 / (va**2 / nu_a + vb**2 / nu_b)
        return (xa - xb) / np.sqrt(va + vb) / coverage_factor(nu_ab)


def _files(paths: list[Path]) -> str:
    """``paths`` as typed: ``folder/*.bsdf`` when they are all of one folder's files."""
    folders = {p.parent for p in paths}
    if len(folders) == 1 and len(paths) == len(list(next(iter(folders)).glob("*.bsdf"))):
        return f"{next(iter(folders))}/*.bsdf"
    return " ".join(map(str, paths))


def factor(z: np.ndarray) -> float:
    """95th percentile of ``|z|`` over 1.96 (module docstring)."""
    z = np.abs(z[np.isfinite(z)])
    return float(np.quantile(z, 0.95) / 1.96) if z.size else float("nan")


def within(z: np.ndarray) -> float:
    z = np.abs(z[np.isfinite(z)])
    return float(np.mean(z <= 1.96)) if z.size else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", default="walter")
    ap.add_argument("--metric", default="low_e2")
    ap.add_argument("--stride", type=int, nargs=3, default=(3, 3, 5))
    ap.add_argument("--nbrdf", type=int, default=24, help="NBRDF materials (0: none)")
    ap.add_argument("--rgl", type=Path, nargs="*", default=[], help="RGL-EPFL .bsdf files")
    ap.add_argument("--block-deg", type=float, default=10.0, help="the errors' blocks")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--z-out", type=Path, default=None, help="values and errors (JSON)")
    args = ap.parse_args()
    import jax

    brdffit.enable_compilation_cache()
    model = models.from_spec(args.model)
    t0 = time.perf_counter()
    sources = [("NBRDF", p) for p in (materials(args.nbrdf) if args.nbrdf else [])]
    sources += [("RGL", p) for p in args.rgl]
    rows, zs, labels, dump = [], {}, {}, {}
    for group, path in sources:
        data = load_measurements(path, stride=tuple(args.stride))
        a, b = halves(data)
        xa, ea, nua, ra = errors_at_optimum(model, a, args.metric, args.block_deg)
        xb, eb, nub, _ = errors_at_optimum(model, b, args.metric, args.block_deg)
        z = {k: (xa - xb) / np.sqrt(ea[k] ** 2 + eb[k] ** 2) for k in KINDS}
        z["blocks"] = welch_z(xa, xb, ea["CR2"], eb["CR2"], nua, nub)
        zs[(group, path.stem)] = z
        dump[f"{group}/{path.stem}"] = {
            "labels": list(ra.labels), "a": xa.tolist(), "b": xb.tolist(),
            "se_a": {k: ea[k].tolist() for k in KINDS}, "se_b": {k: eb[k].tolist() for k in KINDS},
            "dof_a": nua.tolist(), "dof_b": nub.tolist(),
        }  # fmt: skip
        labels[(group, path.stem)] = [lab.split("[")[0] for lab in ra.labels]
        cells = [f"{within(z[k]):.0%} / {factor(z[k]):.2f}" for k in KINDS]
        rows.append(f"| {group} | {path.stem} | {a.n} / {b.n} | " + " | ".join(cells) + " |")
        print(rows[-1], flush=True)

    def pooled(keys, kind, name=None):
        z = [zs[k][kind][[lab == name for lab in labels[k]]] if name else zs[k][kind] for k in keys]
        return np.concatenate(z) if z else np.empty(0)

    groups = {g: [k for k in zs if k[0] == g] for g in ("NBRDF", "RGL")}
    groups = {g: v for g, v in groups.items() if v} | {"all": list(zs)}
    summary = []
    for g, keys in groups.items():
        for kind in KINDS:
            z = pooled(keys, kind)
            summary.append(
                f"| {g} | {kind} | {np.isfinite(z).sum()} | {within(z):.1%} | "
                f"{factor(z):.2f} | {np.median(np.abs(z[np.isfinite(z)])):.2f} |"
            )
    names = list(dict.fromkeys(lab for k in zs for lab in labels[k]))
    per_param = [
        f"| {kind} | "
        + " | ".join(f"{factor(pooled(list(zs), kind, n)):.2f}" for n in names)
        + " |"
        for kind in KINDS
    ]
    cmd = (
        f"python -m benchmarks.split_halves --model {args.model} --metric {args.metric} "
        f"--stride {' '.join(map(str, args.stride))} --nbrdf {args.nbrdf}"
        + (f" --rgl {_files(args.rgl)}" if args.rgl else "")
        + f" --block-deg {args.block_deg:g}"
    )
    lines = [
        f"# Split halves: {models.label(model)}, {args.metric}, stride {tuple(args.stride)}, "
        f"{args.block_deg:g}-degree error blocks",
        "",
        f"Command: `{cmd}`",
        f"Machine: {platform.processor() or platform.machine()}, {jax.devices()[0]}; "
        f"{time.perf_counter() - t0:.0f} s.",
        "",
        "Pooled over data sets. within: share of free scalars whose two half-fits agree",
        "within their stated 95% intervals (95% if right). factor: 95th percentile of |z|",
        "over 1.96 (1 if right; above 1 the intervals are too narrow by that factor, below 1",
        "too wide). median |z| is 0.67 for normal z with correct errors (smaller for",
        "Student-t intervals, which are wider in the tails). blocks: the CR2 difference",
        "against Welch's t quantile for the two halves' summed variance (module docstring).",
        "",
        "| data | errors | scalars | within 95% | factor | median abs z |",
        "|---|---|---|---|---|---|",
        *summary,
        "",
        "Factor per parameter, all data sets:",
        "",
        "| errors | " + " | ".join(names) + " |",
        "|---" * (1 + len(names)) + "|",
        *per_param,
        "",
        "Per data set (within 95% / factor):",
        "",
        "| data | name | cells (halves) | " + " | ".join(KINDS) + " |",
        "|---" * (3 + len(KINDS)) + "|",
        *rows,
        "",
    ]
    text = "\n".join(lines)
    print(text)
    if args.out:
        write_text(args.out, text)
    if args.z_out:
        write_text(args.z_out, json.dumps(dump))


if __name__ == "__main__":
    main()
