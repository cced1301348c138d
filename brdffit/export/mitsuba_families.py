"""Mitsuba 3's BSDF forms an export can write, as families to fit.

Each family (:class:`~brdffit.export._match.Family`) has named slots with bounds, its
evaluation in numpy (:mod:`brdffit.export.mitsuba_bsdf`) and a ``build`` that returns the
dict for ``mi.load_dict``: :func:`diffuse_family`; :func:`conductor_family`
(``roughconductor``, GGX or Beckmann, alone or blended with a ``diffuse``);
:func:`principled_family` (with the features of :data:`PRINCIPLED_FEATURES`, or
``metallic = 1`` blended with a ``diffuse``); :func:`layered_family`
(``blendbsdf(principled, roughconductor)``). A blend with a ``diffuse`` is
``(1 - w) reflectance / pi + w lobe``. Which family a model maps to, from which start
and with what loss: :mod:`brdffit.export.mitsuba`.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from brdffit.export import mitsuba_bsdf as mb
from brdffit.export._match import Family, Slot


def _rgb(v: object) -> dict:
    return {"type": "rgb", "value": [float(x) for x in np.broadcast_to(v, (3,))]}


def _blend(p: Mapping[str, object], lobe: dict) -> dict:
    if "weight" not in p or float(p["weight"]) >= 1.0:
        return lobe
    return {
        "type": "blendbsdf",
        "weight": float(p["weight"]),
        "bsdf_0": {"type": "diffuse", "reflectance": _rgb(p["reflectance"])},
        "bsdf_1": lobe,
    }


def _with_diffuse(p: Mapping[str, object], lobe: np.ndarray, wi: np.ndarray) -> np.ndarray:
    if "weight" not in p:
        return lobe
    w = float(p["weight"])
    return (1.0 - w) * mb.diffuse(p["reflectance"], wi, wi) + w * lobe


def _diffuse_slots(on: bool) -> tuple[Slot, ...]:
    return (Slot("weight", 1, 0.0, 1.0), Slot("reflectance", 3, 0.0, 1.0)) if on else ()


def _alpha_slots(aniso: bool, lo: float = 1e-4) -> tuple[Slot, ...]:
    if aniso:
        return (Slot("alpha_u", 1, lo, 2.0), Slot("alpha_v", 1, lo, 2.0))
    return (Slot("alpha", 1, lo, 2.0),)


def diffuse_family() -> Family:
    """``diffuse`` with RGB ``reflectance``."""

    def build(p: Mapping[str, object]) -> dict:
        return {"type": "diffuse", "reflectance": _rgb(p["reflectance"])}

    return Family(
        "diffuse",
        (Slot("reflectance", 3, 0.0, 1.0),),
        lambda p, wi, wo: mb.diffuse(p["reflectance"], wi, wo),
        build,
    )


def conductor_family(kind: str, aniso: bool, with_diffuse: bool) -> Family:
    """``roughconductor`` (``kind`` ggx or beckmann), optionally blended with a diffuse."""

    def alphas(p: Mapping[str, object]) -> tuple[float, float]:
        return (p["alpha_u"], p["alpha_v"]) if aniso else (p["alpha"], p["alpha"])

    def evaluate(p: Mapping[str, object], wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        ax, ay = alphas(p)
        lobe = mb.roughconductor(kind, ax, ay, p["eta"], p["k"], p["specular"], wi, wo)
        return _with_diffuse(p, lobe, wi)

    def build(p: Mapping[str, object]) -> dict:
        ax, ay = alphas(p)
        rough = {"alpha_u": float(ax), "alpha_v": float(ay)} if aniso else {"alpha": float(ax)}
        lobe = {"type": "roughconductor", "distribution": kind, **rough}
        lobe |= {"eta": _rgb(p["eta"]), "k": _rgb(p["k"])}
        lobe["specular_reflectance"] = _rgb(p["specular"])
        return _blend(p, lobe)

    slots = _diffuse_slots(with_diffuse) + _alpha_slots(aniso)
    slots += (Slot("eta", 3, 0.0, 10.0), Slot("k", 3, 0.0, 20.0), Slot("specular", 3, 0.0, 1.0))
    name = f"roughconductor[distribution={kind}]"
    return Family(f"blendbsdf(diffuse, {name})" if with_diffuse else name, slots, evaluate, build)


PRINCIPLED_FEATURES = (
    "metallic",
    "anisotropic",
    "spec_tint",
    "sheen",
    "sheen_tint",
    "flatness",
    "clearcoat",
    "clearcoat_gloss",
)


def principled_family(
    features: tuple[str, ...], with_diffuse: bool = False, specular_low: float = 1e-3
) -> Family:
    """``principled`` with ``base_color``, ``roughness``, ``specular`` and ``features``.

    ``features`` is a subset of :data:`PRINCIPLED_FEATURES`; the others stay 0 (off).
    ``with_diffuse``: blended with a ``diffuse`` (used with ``metallic`` fixed at 1).
    ``specular_low``: the lower bound of ``specular``; 1e-3 keeps a fit off 0, where
    Mitsuba drops the whole specular lobe (``eta = 1``); the ``principled`` model's own
    mapping passes 0, which Mitsuba accepts.
    """
    metal = with_diffuse

    def values(p: Mapping[str, object]) -> dict[str, object]:
        q = {k: p[k] for k in ("base_color", "roughness", "specular", *features) if k in p}
        return q | {"metallic": 1.0} if metal else q

    def evaluate(p: Mapping[str, object], wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return _with_diffuse(p, mb.principled(values(p), wi, wo), wi)

    def build(p: Mapping[str, object]) -> dict:
        q = {k: _rgb(v) if k == "base_color" else float(v) for k, v in values(p).items()}
        return _blend(p, {"type": "principled", **q})

    slots = _diffuse_slots(with_diffuse) + (
        Slot("base_color", 3, 0.0, 1.0),
        Slot("roughness", 1, 0.0, 1.0),
    )
    slots += () if metal else (Slot("specular", 1, specular_low, 1.0),)
    slots += tuple(Slot(f, 1, 0.0, 1.0) for f in features)
    name = "blendbsdf(diffuse, principled[metallic=1])" if metal else "principled"
    return Family(name, slots, evaluate, build)


def layered_family() -> Family:
    """``blendbsdf(principled, roughconductor[distribution=ggx])``: body and lobe colours apart.

    ``(1 - w) principled(base_color, roughness, specular) + w roughconductor``, the
    conductor with ``alpha = roughness^2`` and Gulbrandsen's index of an RGB ``f0``
    (white edge tint). ``principled`` alone ties its lobe's colour to ``base_color``
    (``spec_tint``, ``metallic``); here the white dielectric lobe keeps the Fresnel rise to
    grazing and the conductor carries the lobe's colour, while the body is not darkened
    by more than ``1 - w``.
    """

    def parts(p: Mapping[str, object]) -> tuple[dict[str, object], float]:
        body = {"base_color": p["base_color"], "roughness": p["roughness"]}
        return body | {"specular": p["specular"]}, max(float(p["roughness"]) ** 2, 1e-4)

    def evaluate(p: Mapping[str, object], wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        body, a = parts(p)
        eta, k = gulbrandsen(p["f0"])
        w = float(p["weight"])
        lobe = mb.roughconductor("ggx", a, a, eta, k, np.ones(3), wi, wo)
        return (1.0 - w) * mb.principled(body, wi, wo) + w * lobe

    def build(p: Mapping[str, object]) -> dict:
        body, a = parts(p)
        eta, k = gulbrandsen(p["f0"])
        first = {"type": "principled", "base_color": _rgb(body["base_color"])}
        first |= {"roughness": float(body["roughness"]), "specular": float(body["specular"])}
        lobe = {"type": "roughconductor", "distribution": "ggx", "alpha": a}
        lobe |= {"eta": _rgb(eta), "k": _rgb(k)}
        return {"type": "blendbsdf", "weight": float(p["weight"]), "bsdf_0": first, "bsdf_1": lobe}

    slots = (
        Slot("weight", 1, 0.0, 1.0),
        Slot("base_color", 3, 0.0, 1.0),
        Slot("roughness", 1, 0.01, 1.0),
        Slot("specular", 1, 1e-3, 1.0),
        Slot("f0", 3, 0.0, 1.0),
    )
    name = "blendbsdf(principled, roughconductor[distribution=ggx])"
    return Family(name, slots, evaluate, build)


def gulbrandsen(f0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Conductor index ``(eta, k)`` with normal reflectance ``f0`` and white edge tint.

    Gulbrandsen 2014 (JCGT 3(4)) with ``g = 1``: ``eta = (1 - f0)/(1 + f0)``,
    ``k = 2 sqrt(f0)/(1 + f0)``; ``f0 = 1`` gives Mitsuba's perfect mirror (0, 1).
    """
    r = np.clip(np.asarray(f0, float), 0.0, 1.0)
    return (1.0 - r) / (1.0 + r), 2.0 * np.sqrt(r) / (1.0 + r)
