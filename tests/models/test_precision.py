"""No silently wrong value inside the documented bounds: every model against a 40-digit reference.

For every registered model and every option row of ``tests/cases.py`` (a model without a row
is checked with its default options and parameters), ``model.eval`` in float64 is compared
with an independent transcription of the model's published formula evaluated in mpmath at 40
digits (``tests/references.py`` and any ``tests/references_<name>.py``), on

- directions: the 11 pairs of :func:`brdffit.models.check.extreme_pairs` (normal, grazing at
  cos 1e-6, wi = wo, mirror), 9 more near-mirror and grazing-mirror pairs (below) and 12
  uniform random pairs;
- parameters: the row's values, every parameter at its lower bound, every one at its upper
  bound, each parameter alone at each of its bounds with the others at the row's values
  (an infinite bound stands in as 1e6, as in ``brdffit.models.check``), and per-model extra sets
  (:data:`EXTRA_SETS`).

Rules, per RGB value (``verdict``):
- reference exactly 0 -> the model returns exactly 0;
- reference beyond float64's largest value -> the model returns +inf (or raises);
- otherwise the model is finite and within ``RTOL |ref| + ATOL`` of the reference, or, where
  it is not, within what rounding the float64 inputs by a couple of ulps moves the reference
  (``input_floor``: the conditioning of the formula itself, never the model's algorithm).
"""

from __future__ import annotations

import importlib
import math
import time
from collections.abc import Callable, Mapping
from pathlib import Path

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest

from brdffit import models
from brdffit.core.geometry import spherical_to_vector
from brdffit.models.check import GRAZING_COS, extreme_pair_names, extreme_pairs, params_at_bounds
from tests import references
from tests.cases import CASES, Case
from tests.helpers import random_pairs

RTOL = 1e-9
"""Relative tolerance. Inputs (directions and parameters) reach model and reference as the same
float64 numbers, so the only error is the model's own rounding: ~1e-16 per operation, amplified
by the formula's sensitivities. The largest legitimate ones inside the bounds: a power ``b^n``
with ``n`` up to 1e5 turns a rounding of ``b`` into ``n eps = 1.1e-11``; ``exp(x)`` with
``|x|`` up to ~745 turns one of ``x`` into ``745 eps = 8e-14``; a few dozen further roundings
add ~1e-14. 1e-9 leaves a factor ~100 above the worst of these and is 10^7 below the O(1)
errors the test exists for (Lafortune's old exponent cap: factors 0.38 to 1e-37)."""
MODEL_RTOL = {"sgd": 1e-7}
"""Models with an error of their own method above :data:`RTOL`: SGD reads Smith's Lambda
from a cubic Hermite table (``models/sgd.py``), within 2e-8 of its quadrature relative in
each of G1(wi) and G1(wo); ``tests/models/test_sgd.py`` holds it to the same 1e-7."""
ATOL = 1e-280
"""Absolute floor in 1/sr. Log-space guards floor exponents at -700 (``exp(-700) = 1e-304``,
just above float64's smallest normal number 2.2e-308), and the value is then multiplied by
geometric factors up to ~1e18 (``1/(cos_i cos_o)`` and ``1/(wi.h)`` at cos 1e-6): ~1e-286 where
the true value is far smaller. Below 1e-280 1/sr float64 is in its underflow regime and the
value is physically 0; nothing above it is excused."""
INPUT_ULPS = 4.0
"""Size, in units of 2^-52, of the relative perturbations of every input for the input floor."""
FLOOR_FACTOR = 2.0
"""Where a value misses ``RTOL |ref| + ATOL``, the model may still differ from the reference by
this many times the largest change of the reference when every float64 input (direction
components and parameters) is moved by :data:`INPUT_ULPS` ulps (4 draws: all up, all down, two
random signs). A float64 direction is a unit vector only to an ulp or two in length and angle,
so such a change is not determined by the inputs at all: e.g. ``(1 - cos_d)^5`` of Schlick's
Fresnel at ``wi = wo`` (``cos_d`` is the input's length there) or at a 1e-7 rad pair, where
``1 - cos_d = 1e-15`` is known to ~1e-16. The floor follows the formula's conditioning, not the
model's algorithm: a cancelling algorithm (``1 - cos^2`` for ``sin^2`` at the peak, a capped
exponent) errs far beyond it and still fails."""
FLOAT64_MAX = mp.mpf(float(np.finfo(np.float64).max))
FLOAT64_OVERFLOW = FLOAT64_MAX * (1 + RTOL)
"""A reference above this must come out as +inf (between it and FLOAT64_MAX, RTOL decides)."""
BATCH = 32
"""Parameter sets per batched evaluation: one fixed shape, so that the eager JAX kernels compiled
for one model serve the next."""
N_RANDOM = 6
N_RANDOM_SLOW = 48
MAX_LISTED = 30


# --- the references: tests/references.py plus every tests/references_<name>.py -----------
def collect_references() -> dict[str, Callable]:
    """Registry name -> reference, from ``tests/references.py`` and ``tests/references_*.py``."""
    found = dict(references.REFERENCES)
    for path in sorted(Path(__file__).parents[1].glob("references_*.py")):
        module = importlib.import_module(f"tests.{path.stem}")
        for name, fn in module.REFERENCES.items():
            if name in found:
                raise ValueError(f"tests/{path.name}: a reference for {name!r} exists already")
            found[name] = fn
    return found


REFERENCES = collect_references()


# --- the grid -------------------------------------------------------------------------------
def _mirror(w: np.ndarray) -> np.ndarray:
    """The mirror direction about the normal, exact in float64."""
    return w * np.array([-1.0, -1.0, 1.0])


def direction_pairs(n_random: int = N_RANDOM) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """(names, wi, wo): the extreme pairs, near-mirror, grazing-mirror and cos 1e-10 pairs, and
    ``n_random`` uniform random pairs."""
    names, (wi, wo) = list(extreme_pair_names()), extreme_pairs()
    th_g, th_3, th_2 = math.acos(GRAZING_COS), math.acos(1e-3), math.acos(1e-2)
    th_10 = math.acos(1e-10)
    sv = spherical_to_vector
    extra = [  # (name, wi, wo)
        ("grazing/mirror y", spherical_to_vector(th_g, np.pi / 2), None),
        ("grazing/mirror diagonal", spherical_to_vector(th_g, 0.7), None),
        ("cos1e-3/mirror", spherical_to_vector(th_3, 2.0), None),
        ("cos1e-2/mirror", spherical_to_vector(th_2, 0.0), None),
        (
            "grazing/near-mirror 1e-3",
            spherical_to_vector(th_g, 0.0),
            spherical_to_vector(th_g, np.pi + 1e-3),
        ),
        ("34deg/near-mirror 1e-6", sv(0.6, 0.3), sv(0.6 + 1e-6, 0.3 + np.pi)),
        ("34deg/near-mirror 1e-4", sv(0.6, 0.3), sv(0.6 - 1e-4, 0.3 + np.pi)),
        ("34deg/near-mirror 1e-2", sv(0.6, 0.3), sv(0.6, 0.31 + np.pi)),
        ("normal/1e-7", np.array([0.0, 0.0, 1.0]), spherical_to_vector(1e-7, 1.0)),
        ("normal/cos1e-10", np.array([0.0, 0.0, 1.0]), spherical_to_vector(th_10, 0.4)),
        ("cos1e-10=cos1e-10", spherical_to_vector(th_10, 0.4), spherical_to_vector(th_10, 0.4)),
        ("cos1e-10/mirror", spherical_to_vector(th_10, 0.4), None),
        ("34deg/cos1e-10", spherical_to_vector(0.6, 0.3), spherical_to_vector(th_10, 2.5)),
    ]  # fmt: skip
    wi_x = [a for _, a, _ in extra]
    wo_x = [_mirror(a) if b is None else b for _, a, b in extra]
    wi_r, wo_r = random_pairs(20250611, n_random)
    names += [n for n, _, _ in extra] + [f"random {k}" for k in range(n_random)]
    wi = np.concatenate([wi, np.array(wi_x), wi_r])
    wo = np.concatenate([wo, np.array(wo_x), wo_r])
    assert np.all(wi[:, 2] > 0) and np.all(wo[:, 2] > 0)
    return tuple(names), wi, wo


def _lafortune_sets(model, base: dict) -> dict[str, dict]:
    """Lobe 1 at ratios -2.2..-1.4 and exponents 137..264, where ``base^n`` at grazing mirror
    pairs is 1e20..1e90: the old exponent cap (60) returned 0.4x down to 1e-65x of the value."""
    ratios = ("cx_1", "cy_1") if model.anisotropic else ("cxy_1",)
    out = {}
    for c in (-2.2, -1.8, -1.4):
        for n in (137.0, 181.0, 264.0):
            s = {**base, "n_1": np.asarray(n)}
            s.update({r: np.asarray(c) for r in ratios})
            out[f"lobe 1 c={c} n={n:g}"] = s
    return out


EXTRA_SETS: dict[str, Callable[..., dict[str, dict]]] = {"lafortune": _lafortune_sets}
"""Registry name -> ``f(model, base) -> {label: params}``: sets beyond the bounds grid."""


def _clip(bound: float) -> float:
    return float(min(max(bound, -1e6), 1e6))


def parameter_sets(model, base: Mapping[str, object]) -> dict[str, dict[str, np.ndarray]]:
    """Labelled natural parameter dicts: the row, all low, all high, each alone at a bound."""
    base = {k: np.asarray(v, float) for k, v in base.items()}
    sets = {"case": base}
    for which in ("low", "high"):
        sets[f"all {which}"] = {
            k: np.asarray(v, float) for k, v in params_at_bounds(model, which).items()
        }
    for p in model.parameters:
        for side, bound in zip(("low", "high"), p.bounds, strict=True):
            sets[f"{p.name} {side}"] = {**base, p.name: np.full(p.shape, _clip(bound))}
    if model.name in EXTRA_SETS:
        sets.update(EXTRA_SETS[model.name](model, base))
    return sets


# --- the comparison -------------------------------------------------------------------------
def model_values(model, sets: dict, wi: np.ndarray, wo: np.ndarray) -> dict[str, object]:
    """label -> (N, 3) float64 values, or the exception ``model.eval`` raised."""
    labels = list(sets)
    try:
        out = {}
        for start in range(0, len(labels), BATCH):
            chunk = labels[start : start + BATCH]
            chunk += [chunk[0]] * (BATCH - len(chunk))  # pad to the fixed batch
            stacked = {
                k: jnp.stack([jnp.asarray(sets[s][k]) for s in chunk]) for k in sets[labels[0]]
            }
            f = np.asarray(jax.vmap(lambda p: model.eval(p, wi, wo))(stacked))
            out.update(zip(chunk, f, strict=True))
        return out
    except Exception:  # noqa: BLE001 (find the set that raised, below)
        pass
    out = {}
    for s in labels:
        try:
            out[s] = np.asarray(model.eval(sets[s], wi, wo))
        except Exception as err:  # noqa: BLE001 (raising is allowed where the value overflows)
            out[s] = err
    return out


def to_mpf(x) -> mp.mpf:
    """A reference value (mpf, int, float, np.longdouble) as an mpf."""
    if isinstance(x, np.longdouble):
        return mp.mpf(np.format_float_scientific(x, unique=True))
    return mp.mpf(x)


def verdict(f: float, ref: mp.mpf, rtol: float = RTOL) -> tuple[str | None, float]:
    """(what is wrong or None, relative error) of one float64 value against the reference."""
    if not math.isnan(f) and abs(ref) > FLOAT64_OVERFLOW:
        ok = f == math.copysign(math.inf, ref)
        return (None if ok else "not inf where the reference overflows float64"), float(not ok)
    if not math.isfinite(f):
        return "non-finite", math.inf
    if ref == 0:
        return (None if f == 0 else "nonzero where the reference is 0"), math.inf * (f != 0)
    r = float(ref)  # within float64's range here; rounding it costs 1e-16 of RTOL's 1e-9
    err = abs(f - r)
    rel = err / abs(r) if abs(r) > ATOL / rtol else 0.0  # ATOL's regime: not scored
    return (None if err <= rtol * abs(r) + ATOL else "error"), rel


def input_floor(reference, model, params: dict, wi, wo, ref: np.ndarray, seed: int) -> np.ndarray:
    """Largest change of the reference at ``wi``, ``wo`` (rows of the grid) when every float64
    input moves by :data:`INPUT_ULPS` ulps (:data:`FLOOR_FACTOR`), (N, 3) mpf."""
    rng = np.random.default_rng(seed)
    eps = INPUT_ULPS * 2.0**-52
    spread = np.full(ref.shape, mp.mpf(0), dtype=object)
    for draw in ("up", "down", "random", "random"):

        def jiggle(x, draw=draw):
            x = np.asarray(x, float)
            sign = {"up": 1.0, "down": -1.0}.get(draw)
            u = rng.choice([-1.0, 1.0], x.shape) if sign is None else np.full(x.shape, sign)
            return x * (1.0 + eps * u)

        p = {k: jiggle(v) for k, v in params.items()}
        r = reference(model, p, jiggle(wi), jiggle(wo))
        for idx in np.ndindex(ref.shape):
            spread[idx] = max(spread[idx], abs(to_mpf(r[idx]) - ref[idx]))
    return spread


def precision_failures(
    model, base: Mapping[str, object], reference, pairs: tuple | None = None
) -> tuple[list, dict]:
    """Compare one model with its reference on the whole grid.

    Returns the failures, rows ``(set, pair, channel, kind, model value, reference, relative
    error)``, and a summary: the worst relative error within the tolerance (:data:`RTOL`, or
    the model's :data:`MODEL_RTOL`) (``"worst"``, with its set
    and pair) and the number and worst relative error of the values that needed the input
    floor (``"floored"``, ``"worst_floored"``).
    """
    names, wi, wo = PAIRS if pairs is None else pairs
    rtol = MODEL_RTOL.get(model.name, RTOL)
    sets = parameter_sets(model, base)
    values = model_values(model, sets, jnp.asarray(wi), jnp.asarray(wo))
    failures: list = []
    summary = {"sets": len(sets), "worst": (0.0, "-", "-"), "floored": 0, "worst_floored": 0.0}
    with mp.workdps(references.DPS):
        for k, (label, params) in enumerate(sets.items()):
            raw = reference(model, params, wi, wo)
            ref = np.empty(raw.shape, dtype=object)
            for idx in np.ndindex(raw.shape):
                ref[idx] = to_mpf(raw[idx])
            f = values[label]
            if isinstance(f, Exception):  # allowed only where the true value overflows
                if not any(abs(r) > FLOAT64_MAX for r in ref.ravel()):
                    failures.append((label, "-", "-", f"raised {f!r}", math.nan, "-", math.inf))
                continue
            bad = []
            for i, c in np.ndindex(f.shape):
                kind, rel = verdict(float(f[i, c]), ref[i, c], rtol)
                if kind is None:
                    summary["worst"] = max(summary["worst"], (rel, label, names[i]))
                else:
                    bad.append((i, c, kind, rel))
            floorable = ("error", "nonzero where the reference is 0")
            rows = sorted({i for i, _, kind, _ in bad if kind in floorable})
            spread = input_floor(reference, model, params, wi[rows], wo[rows], ref[rows], k)
            floor = dict(zip(rows, spread, strict=True))
            for i, c, kind, rel in bad:
                if kind in floorable:
                    allowed = rtol * abs(ref[i, c]) + ATOL + FLOOR_FACTOR * floor[i][c]
                    if abs(mp.mpf(float(f[i, c])) - ref[i, c]) <= allowed:
                        summary["floored"] += 1
                        summary["worst_floored"] = max(summary["worst_floored"], rel)
                        continue
                failures.append(
                    (label, names[i], "RGB"[c], kind, float(f[i, c]), mp.nstr(ref[i, c], 12), rel)
                )
    return failures, summary


def describe(failures: list) -> str:
    """The failures as text: a count per (parameter set, kind), then the worst values."""
    groups: dict[tuple[str, str], list] = {}
    for row in failures:
        groups.setdefault((row[0], row[3].split(":")[0]), []).append(row)
    lines = [f"{len(failures)} values wrong; per parameter set:"]
    for (label, kind), rows in groups.items():
        pairs = sorted({r[1] for r in rows})
        lines.append(
            f"  [{label}] {kind}: {len(rows)} values, worst rel {max(r[-1] for r in rows):.3g}, "
            f"pairs {', '.join(pairs[:6])}{' ...' if len(pairs) > 6 else ''}"
        )
    lines.append(f"worst first (at most {MAX_LISTED}):")
    for label, pair, ch, kind, f, ref, rel in sorted(failures, key=lambda r: -r[-1])[:MAX_LISTED]:
        lines.append(
            f"  [{label}] {pair} {ch}: {kind}: model {f:.6g}, reference {ref}, rel {rel:.3g}"
        )
    return "\n".join(lines)


PAIRS = direction_pairs()
_WITH_ROWS = {c.model for c in CASES}
ALL_CASES = CASES + [Case(name) for name in models.available() if name not in _WITH_ROWS]


def test_every_registered_model_has_a_reference():
    missing = sorted(set(models.available()) - set(REFERENCES))
    assert not missing, (
        f"models without a high-precision reference: {missing}; add one to tests/references.py "
        "or to a tests/references_<name>.py that defines REFERENCES"
    )


def _check(case: Case, pairs: tuple) -> None:
    model, params = case.build()
    reference = REFERENCES.get(model.name)
    assert reference is not None, f"no reference for {model.name!r} (tests/references*.py)"
    start = time.perf_counter()
    failures, summary = precision_failures(model, params, reference, pairs)
    rel, label, pair = summary["worst"]
    print(
        f"{case.id}: {summary['sets']} sets x {len(pairs[0])} pairs, worst relative error "
        f"{rel:.3g} ([{label}] {pair}); {summary['floored']} values within the input floor only "
        f"(worst {summary['worst_floored']:.3g}); {time.perf_counter() - start:.1f} s"
    )
    assert not failures, describe(failures)


def _first_row_per_model() -> list:
    """The first row of each model runs in the default suite, further option rows are
    ``slow`` (``bash benchmarks/slow_checks.sh``), as in ``tests/models/test_identifiability.py``:
    a 40-digit reference costs up to a minute a row (SGD's two Smith integrals)."""
    seen, out = {"sgd"}, []  # SGD's rows (73 s): tests/models/test_sgd.py checks it against
    for c in ALL_CASES:  # the same 40-digit reference on the extreme pairs, in 23 s
        out.append(pytest.param(c, id=c.id, marks=() if c.model not in seen else pytest.mark.slow))
        seen.add(c.model)
    return out


@pytest.mark.parametrize("case", _first_row_per_model())
def test_float64_matches_high_precision_reference(case):
    _check(case, PAIRS)


@pytest.mark.slow
@pytest.mark.parametrize("case", ALL_CASES, ids=[c.id for c in ALL_CASES])
def test_float64_matches_high_precision_reference_many_random_pairs(case):
    _check(case, direction_pairs(N_RANDOM_SLOW))
