"""Does :func:`brdffit.simplify` recover the feature set a material was made with? (issue 21)

For each setting, synthetic data are drawn from a known variant (the *generating set*:
which optional lobes are on, which RGB parameters are grey, how many lobes, which
parameters sit at their neutral value, such as Disney's ``specular`` 0.5) with fresh
noise per seed, and the search starts from a richer model. Per setting the script
counts the seeds whose chosen variant is exactly the generating one (``recovered``),
those that keep a feature the data were made without (``false keep``: a lobe, an
option, a colour the truth lacks, or a parameter left free that the truth has at its
neutral value) and those that drop one the data have
(``missed``), each with a Clopper-Pearson 95% interval. Targets: recovered >= 95%,
false keep <= 5%.

Data. Noise: multiplicative log-normal, 3% (``f exp(0.03 z)``, ``z ~ N(0, 1)`` per
sample and channel: a good gonioreflectometer's repeatability). Isotropic settings
(walter, lafortune): the MERL grid at stride ``(5, 9, 9)`` (18 theta_h x 10 theta_d x
20 phi_d bin centres, 2,266 cells inside the 80-degree cut). Disney settings: anisotropy
is invisible on the MERL grid (every half vector lies in the x-z plane), so the MERL
grid at stride ``(9, 9, 15)`` is measured at three azimuths of the sample, 0, 45 and 90
degrees (each pair rotated about the normal), 3,600 pairs, 2,268 inside the cut. The
directions are the same for every seed, so each variant compiles once per setting.
Metric ``low_e2``; search settings: :func:`brdffit.simplify` defaults (``criterion="cv"``,
5 folds, ``n_se`` = t_{0.95, 4} = 2.13, ``min_gain`` 1%), ``screen=8`` for the start model's fit and
``throw=False`` (a chosen variant whose final refit stops at ``max_steps`` is still
judged by its label); the
criterion is a command-line choice (``--criterion bic`` for BIC with n = residuals).

Run from the repository root: ``python3 benchmarks/simplify_recovery.py [--seeds N]
[--settings GLOB] [--criterion cv|bic] [--md OUT.md] [--cache FILE.jsonl] [--impl
FILE.py]``. With ``--cache`` every search is appended to that file (JSON lines), so a
killed run resumes where it stopped, and the table is rebuilt from it. ``--impl`` runs
the ``simplify`` of another file instead (e.g. an earlier version from git, ``git show
REV:brdffit/selection/simplify.py > /tmp/old.py``), to compare methods on the same data.

Latest numbers: ``benchmarks/results/simplify_recovery.md`` (machine, versions, seeds
and wall time are in its header).
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from brdffit import enable_compilation_cache, models, simplify, synthesize  # noqa: E402
from brdffit.io.merl_grid import merl_grid  # noqa: E402
from brdffit.models._restrict import base_of, restrictions  # noqa: E402
from brdffit.selection.variants import features  # noqa: E402

NOISE = 0.03
DISNEY_START = "disney[metallic=false,specular_tint=false]"
_DISNEY_OFF = "subsurface=false,sheen=false,clearcoat=false,anisotropic=false,metallic=false,specular_tint=false"  # noqa: E501
_DISNEY_BASE = {"base_color": [0.5, 0.25, 0.1], "specular": 0.5, "roughness": 0.4}


def _disney(on: dict, neutral: str = "specular") -> str:
    off = [w for w in _DISNEY_OFF.split(",") if w.split("=")[0] not in on]
    return f"disney[{','.join(off)}{',neutral=' + neutral if neutral else ''}]"


@dataclass(frozen=True)
class Setting:
    """One generating variant: ``truth`` (its spec), its ``params``, the ``start`` spec of
    the search and the ``grid`` (``"merl"`` or ``"azimuths"``)."""

    name: str
    truth: str
    params: dict
    start: str
    grid: str
    note: str = ""
    extra: dict = field(default_factory=dict)


SETTINGS = (
    Setting("disney_plain", _disney({}), _DISNEY_BASE, DISNEY_START, "azimuths",
            "Burley diffuse + GGX, nothing optional, specular 0.5 (F0 0.04, neutral)"),
    Setting("disney_specular", _disney({}, neutral=""), {**_DISNEY_BASE, "specular": 0.8},
            DISNEY_START, "azimuths", "as plain, specular 0.8 (F0 0.064): not neutral"),
    Setting("disney_clearcoat", _disney({"clearcoat": 1}),
            {**_DISNEY_BASE, "clearcoat": 0.5, "clearcoat_gloss": 0.7}, DISNEY_START, "azimuths",
            "clear coat 0.5, gloss 0.7 (GTR1 alpha 0.031)"),
    Setting("disney_sheen", _disney({"sheen": 1}),
            {**_DISNEY_BASE, "sheen": 0.8, "sheen_tint": 0.5}, DISNEY_START, "azimuths",
            "sheen 0.8, tint 0.5"),
    Setting("disney_aniso", _disney({"anisotropic": 1}), {**_DISNEY_BASE, "anisotropic": 0.7},
            DISNEY_START, "azimuths", "anisotropic 0.7 (alpha_x / alpha_y = 2.7)"),
    Setting("disney_all3", _disney({"clearcoat": 1, "sheen": 1, "anisotropic": 1},
                                   neutral="specular+sheen_tint"),
            {**_DISNEY_BASE, "clearcoat": 0.5, "clearcoat_gloss": 0.7, "sheen": 0.8,
             "sheen_tint": 0.0, "anisotropic": 0.7}, DISNEY_START, "azimuths",
            "clear coat, sheen and anisotropy as above, an untinted sheen (tint 0, neutral)"),
    Setting("lafortune_1lobe", "lafortune",
            {"kd": [0.3, 0.15, 0.08], "rho_1": [0.6, 0.45, 0.3], "cxy_1": -1.0, "n_1": 60.0},
            "lafortune[n_lobes=2]", "merl", "one coloured lobe, n 60"),
    Setting("lafortune_2lobes", "lafortune[n_lobes=2]",
            {"kd": [0.3, 0.15, 0.08], "rho_1": [0.6, 0.45, 0.3], "cxy_1": -1.0, "n_1": 60.0,
             "rho_2": [0.25, 0.2, 0.15], "cxy_2": -1.1, "n_2": 8.0},
            "lafortune[n_lobes=2]", "merl", "sharp lobe n 60 + broad off-specular lobe n 8"),
    Setting("walter_grey_metal", "walter[diffuse=false,specular_weight=false,grey=f0]",
            {"f0": 0.91, "alpha": 0.1}, "walter", "merl", "aluminium-like F0 0.91, alpha 0.1"),
    Setting("walter_gold", "walter[diffuse=false,specular_weight=false]",
            {"f0": [1.0, 0.71, 0.29], "alpha": 0.15}, "walter", "merl",
            "gold-like F0 (1, .71, .29), alpha 0.15"),
    Setting("walter_plastic", "walter[specular_weight=false,neutral=f0]",
            {"kd": [0.6, 0.2, 0.1], "f0": 0.04, "alpha": 0.2}, "walter", "merl",
            "red plastic: coloured kd, F0 0.04 (neutral), alpha 0.2"),
)  # fmt: skip

MERL_STRIDE = (5, 9, 9)
AZ_STRIDE = (9, 9, 15)
AZIMUTHS_DEG = (0.0, 45.0, 90.0)


def directions(grid: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The fixed measurement directions of ``grid`` (``None``: the strided MERL grid)."""
    if grid == "merl":
        return None
    g = merl_grid(AZ_STRIDE)
    wis, wos = [], []
    for deg in AZIMUTHS_DEG:
        c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        wis.append(g.wi @ rot.T)
        wos.append(g.wo @ rot.T)
    return np.concatenate(wis), np.concatenate(wos)


def make_data(st: Setting, seed: int):
    """Noisy synthetic measurements of ``st`` for ``seed``: the truth's unrestricted model
    at ``st.params``, which give the neutral parameters their neutral values."""
    pinned = restrictions(models.from_spec(st.truth))[1]
    truth = base_of(models.from_spec(st.truth))
    for name in pinned:
        assert st.params[name] == truth.parameter(name).neutral, (st.name, name)
    d = directions(st.grid)
    kw = dict(noise_mult=NOISE, seed=seed, source=f"{st.name} seed {seed}")
    if d is None:
        return synthesize(truth, st.params, stride=MERL_STRIDE, **kw)
    return synthesize(truth, st.params, grid="directions", directions=d, **kw)


def judge(st: Setting, chosen: str) -> dict:
    """``recovered``, ``false_keep`` (the truth's missing features the choice has) and
    ``missed`` (the truth's features the choice lacks), by :func:`features`."""
    truth = models.from_spec(st.truth)
    want = set(features(truth))
    got = set(features(models.from_spec(chosen)))
    return {
        "recovered": models.label(truth) == chosen,
        "false_keep": sorted(got - want),
        "missed": sorted(want - got),
    }


def run_one(st: Setting, seed: int, criterion: str, search=simplify) -> dict:
    """One search by ``search`` (:func:`brdffit.simplify`); the record the cache keeps."""
    data = make_data(st, seed)
    t0 = time.perf_counter()
    r = search(models.from_spec(st.start), data, criterion=criterion, seed=seed, screen=8,
               throw=False)  # fmt: skip
    wall = time.perf_counter() - t0
    last = [row for row in r.path if row.step == r.path[-1].step and row.decision == "kept"]
    # what the final step refused, with its held-out ratio and t (an --impl may lack them)
    kept = [[row.change, getattr(row, "held_ratio", None), getattr(row, "t", None)] for row in last]
    return {"setting": st.name, "seed": seed, "criterion": criterion, "chosen": r.chosen,
            "refused": kept,
            "n_free": r.result.n_free, "converged": r.result.converged, "wall_s": wall,
            **judge(st, r.chosen)}  # fmt: skip


def _load_impl(path: str):
    """The ``simplify`` function of the Python file ``path``."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("simplify_impl", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module.simplify


def clopper_pearson(k: int, n: int) -> tuple[float, float]:
    """Exact (Clopper-Pearson) 95% interval of a share ``k / n``."""
    from scipy.stats import binomtest

    ci = binomtest(k, n).proportion_ci(0.95, method="exact")
    return float(ci.low), float(ci.high)


def _share(k: int, n: int) -> str:
    lo, hi = clopper_pearson(k, n)
    return f"{k}/{n} = {k / n:.0%} [{lo:.0%}, {hi:.0%}]"


def table(records: list[dict], criterion: str) -> str:
    """The Markdown table per setting, then the wrong choices with their counts."""
    head = "| setting | generating variant | start | recovered (CP 95%) | false keep (CP 95%) | missed | median s |"  # noqa: E501
    lines = [head, "|---|---|---|---|---|---|---|"]
    wrong = []
    for st in SETTINGS:
        rs = [r for r in records if r["setting"] == st.name and r["criterion"] == criterion]
        if not rs:
            continue
        n = len(rs)
        rec = sum(r["recovered"] for r in rs)
        fk = sum(bool(r["false_keep"]) for r in rs)
        ms = sum(bool(r["missed"]) for r in rs)
        med = float(np.median([r["wall_s"] for r in rs]))
        lines.append(f"| {st.name} | `{models.label(models.from_spec(st.truth))}` | `{st.start}` | "
                     f"{_share(rec, n)} | {_share(fk, n)} | {ms}/{n} | {med:.1f} |")  # fmt: skip
        for r in rs:
            if not r["recovered"]:
                why = "; ".join(
                    [f"kept {', '.join(r['false_keep'])}"] * bool(r["false_keep"])
                    + [f"dropped {', '.join(r['missed'])}"] * bool(r["missed"])
                )
                wrong.append(f"- {st.name} seed {r['seed']}: `{r['chosen']}` ({why})")
    out = "\n".join(lines)
    return out + ("\n\nWrong choices:\n\n" + "\n".join(wrong) if wrong else "\n\nNo wrong choice.")


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=20, help="data sets per setting (seeds 0..N-1)")
    p.add_argument("--settings", default="*", help="glob over setting names")
    p.add_argument("--criterion", default="cv", choices=["cv", "bic"])
    p.add_argument("--cache", default=None, help="JSON lines of finished searches (resume)")
    p.add_argument("--md", default=None, help="write the table (Markdown) here")
    p.add_argument("--impl", default=None, help="a .py file whose simplify() to run instead")
    a = p.parse_args(argv)
    enable_compilation_cache()
    search = simplify if a.impl is None else _load_impl(a.impl)
    chosen = [s for s in SETTINGS if fnmatch.fnmatch(s.name, a.settings)]
    cache = Path(a.cache) if a.cache else None
    records = []
    if cache is not None and cache.exists():
        records = [json.loads(x) for x in cache.read_text().splitlines() if x]
    done = {(r["setting"], r["seed"], r["criterion"]) for r in records}
    t0 = time.perf_counter()
    for st in chosen:
        for seed in range(a.seeds):
            if (st.name, seed, a.criterion) in done:
                continue
            rec = run_one(st, seed, a.criterion, search)
            records.append(rec)
            if cache is not None:
                with cache.open("a") as fh:
                    fh.write(json.dumps(rec) + "\n")
            print(f"{st.name} seed {seed}: {rec['chosen']} recovered={rec['recovered']} "
                  f"({rec['wall_s']:.1f} s)", flush=True)  # fmt: skip
    wall = time.perf_counter() - t0
    import jax

    impl = "brdffit.simplify" if a.impl is None else f"simplify of {a.impl}"
    header = (
        f"{impl}, criterion {a.criterion}, seeds 0..{a.seeds - 1} per setting, noise {NOISE:.0%} "
        f"multiplicative; this run: {wall:.0f} s wall for the searches not cached; "
        f"{platform.processor() or platform.machine()}, jax {jax.__version__}, "
        f"{jax.default_backend()}"
    )
    text = f"{header}\n\n{table([r for r in records if r['seed'] < a.seeds], a.criterion)}\n"
    print(text)
    if a.md:
        Path(a.md).write_text(text)


if __name__ == "__main__":
    main()
