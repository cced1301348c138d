"""Several GGX lobes and a diffuse term as Mitsuba holds them: nested ``blendbsdf``.

Mitsuba has no sum of BSDFs; ``blendbsdf`` is the convex mixture ``(1 - w) bsdf_0 + w
bsdf_1``. walter's ``kd / pi + sum_k ks_k lobe_k`` with ``n`` lobes (GGX, uncorrelated
Smith, Schlick of ``f0_k``: each lobe is ``principled`` with ``metallic = 1``,
``base_color = f0_k``, ``roughness = sqrt(alpha_k)``; :mod:`brdffit.export.mitsuba`) is
the mixture ``c_0 diffuse(rho) + sum_k c_k principled_k`` with ``c_k = ks_k`` and ``c_0
rho = kd``, written as

    blendbsdf(w_1, diffuse(rho), blendbsdf(w_2, principled_1, ... blendbsdf(w_n,
              principled_{n-1}, principled_n)))

whose coefficients are ``c_0 = 1 - w_1`` and, with ``m_1 = w_1``, ``c_k = m_k (1 -
w_{k+1})``, ``m_{k+1} = m_k w_{k+1}``, ``c_n = m_n``. The slots are the nested weights
``w_k`` (each in [0, 1], so every slot value is a valid tree), ``reflectance`` and each
lobe's ``base_color_k`` and ``roughness_k``. Exact when every ``ks_k`` is grey, ``sum_k
ks_k <= 1`` and ``max(kd) + sum_k ks_k <= 1`` (so ``rho = kd / c_0 <= 1``) and every alpha
is at least Mitsuba's floor 0.001; otherwise the family is fitted like every other.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from brdffit.export import mitsuba_bsdf as mb
from brdffit.export._match import Family, Slot

Start = tuple[Family, dict[str, object]]


def coefficients(weights: np.ndarray) -> np.ndarray:
    """Mixture coefficients ``c_0 .. c_n`` of the nested weights ``w_1 .. w_n`` (module
    docstring); they are >= 0 and sum to 1."""
    c, mass = [], 1.0
    for w in weights:
        c.append(mass * (1.0 - w))
        mass *= w
    return np.array([*c, mass])


def nested_weights(c: np.ndarray) -> np.ndarray:
    """The inverse of :func:`coefficients`: ``w_k = 1 - c_{k-1} / m_{k-1}`` (a weight whose
    remaining mass is 0 is 0)."""
    out, mass = [], 1.0
    for ck in c[:-1]:
        w = 1.0 - ck / mass if mass > 0 else 0.0
        out.append(float(np.clip(w, 0.0, 1.0)))
        mass *= out[-1]
    return np.array(out)


def _lobe(p: Mapping[str, object], k: int) -> dict[str, object]:
    return {"base_color": p[f"base_color_{k}"], "roughness": p[f"roughness_{k}"], "metallic": 1.0}


def lobes_family(n: int) -> Family:
    """``n`` principled metal lobes and a diffuse, mixed by nested ``blendbsdf``."""

    def evaluate(p: Mapping[str, object], wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        c = coefficients(np.array([p[f"weight_{k}"] for k in range(1, n + 1)]))
        f = c[0] * mb.diffuse(p["reflectance"], wi, wo)
        for k in range(1, n + 1):
            f = f + c[k] * mb.principled(_lobe(p, k), wi, wo)
        return f

    def build(p: Mapping[str, object]) -> dict:
        def lobe(k: int) -> dict:
            q = _lobe(p, k)
            colour = [float(x) for x in np.broadcast_to(q["base_color"], (3,))]
            return {
                "type": "principled",
                "base_color": {"type": "rgb", "value": colour},
                "roughness": float(q["roughness"]),
                "metallic": 1.0,
            }

        tree = lobe(n)
        for k in range(n, 1, -1):
            tree = {"type": "blendbsdf", "weight": float(p[f"weight_{k}"]),
                    "bsdf_0": lobe(k - 1), "bsdf_1": tree}  # fmt: skip
        rho = [float(x) for x in np.broadcast_to(p["reflectance"], (3,))]
        diffuse = {"type": "diffuse", "reflectance": {"type": "rgb", "value": rho}}
        return {"type": "blendbsdf", "weight": float(p["weight_1"]), "bsdf_0": diffuse,
                "bsdf_1": tree}  # fmt: skip

    slots = tuple(Slot(f"weight_{k}", 1, 0.0, 1.0) for k in range(1, n + 1))
    slots += (Slot("reflectance", 3, 0.0, 1.0),)
    for k in range(1, n + 1):
        slots += (Slot(f"base_color_{k}", 3, 0.0, 1.0), Slot(f"roughness_{k}", 1, 0.0316, 1.0))
    inner = ", ".join(["principled[metallic=1]"] * n)
    return Family(f"blendbsdf(diffuse, {inner})", slots, evaluate, build)


def lobes_start(
    kd: np.ndarray | None, lobes: list[tuple[float, float, np.ndarray, np.ndarray]]
) -> Start:
    """The closed-form start (exact where the module docstring says) from walter's ``kd``
    (``None`` without a diffuse term) and its lobes ``(alpha_x, alpha_y, ks, f0)``."""
    n = len(lobes)
    ks = np.array([float(np.mean(lobe[2])) for lobe in lobes])
    c0 = 1.0 - ks.sum()
    if c0 < 0.0:  # no exact mixture: share the mass in proportion
        ks, c0 = ks / ks.sum() * 0.999, 0.001
    kd = np.zeros(3) if kd is None else np.asarray(kd, float)
    start: dict[str, object] = {"reflectance": np.clip(kd / max(c0, 1e-12), 0.0, 1.0)}
    for k, w in enumerate(nested_weights(np.array([c0, *ks])), 1):
        start[f"weight_{k}"] = float(w)
    for k, (ax, ay, _, f0) in enumerate(lobes, 1):
        start[f"base_color_{k}"] = np.asarray(f0, float)
        start[f"roughness_{k}"] = float(np.sqrt(np.sqrt(ax * ay)))
    return lobes_family(n), start
