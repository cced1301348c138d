"""Export to Mitsuba 3: a BSDF dict for ``mi.load_dict`` and the same BSDF as XML.

Targets (``mitsuba_families`` defines each as a family to fit, ``mitsuba_bsdf`` evaluates
each in numpy; the test checks it against Mitsuba):

* ``diffuse`` -- Lambert; ``lambert`` maps to it exactly.
* ``principled`` with ``metallic = 1`` (Schlick Fresnel of ``base_color``, GGX, separable
  Smith), alone or in a ``blendbsdf`` with a ``diffuse``: ``(1 - w) reflectance / pi +
  w lobe``. ``walter`` with GGX and uncorrelated masking maps to it exactly when its
  ``ks`` is grey and ``max(kd) + ks <= 1`` (``w = ks``, ``reflectance = kd / (1 - ks)``,
  ``base_color = f0``), with alpha >= 0.001 (Mitsuba's floor) and, if anisotropic,
  ``0.1 <= alpha_y / alpha_x <= 1`` (principled stretches along the tangent only).
* ``roughconductor`` (GGX or Beckmann, exact conductor Fresnel with RGB ``eta``, ``k``,
  RGB ``specular_reflectance``), alone or blended with a ``diffuse`` the same way. Exact
  only where the model's Fresnel is 1 (Mitsuba's Beckmann ``G1`` is Walter's rational fit,
  so ``walter[distribution=beckmann,smith=rational,diffuse=false]`` with ``f0 = 1`` is
  exact); a Schlick ``f0`` starts from Gulbrandsen's (2014) index with white edge tint,
  ``eta = (1 - f0)/(1 + f0)``, ``k = 2 sqrt(f0)/(1 + f0)``.
* ``principled`` with the features the model has, for ``disney``, ``filament`` and
  ``course_cook_torrance``. Mitsuba's principled differs from Disney 2012 in its exact
  dielectric Fresnel for the untinted dielectric part, its luminance weights (Rec. 709)
  and its clear coat, which Mitsuba 3 evaluates as ``0.25 clearcoat F D G1(wi) G1(wo)``
  without the microfacet ``1 / (4 cos_i cos_o)`` (4 times Disney's at normal incidence).
  So ``disney`` maps exactly only without clear coat and where the Fresnel and tint
  differences drop out (``metallic = 1``, or ``specular_tint = 1`` with a grey base
  colour; measured in the tests), approximately elsewhere.
* ``principled`` with ``metallic`` and ``spec_tint`` free, diffuse and specular *added*
  (``_dielectric_start``), for every model with a diffuse and a specular lobe: the one
  form that holds ``kd / pi + lobe`` when ``max(kd) + ks > 1``, where a ``blendbsdf``
  must darken the diffuse by ``1 - w``. On a walter fit of RGL satin_rosaline (kd 0.74,
  ks 1, f0 0.07-0.11, alpha 0.062) the blends reached errors 0.21-0.23 (the render
  12-20% too dark), this form 0.0098. Its lobe takes its colour from ``base_color``
  (``spec_tint``, ``metallic``), so a lobe coloured unlike the body shifts the body's
  colour: on that fit the directional albedo at normal view is (+13%, -9%, -8%) per
  channel against the model's (the blend's was -24%, -21%, -24%).
* ``blendbsdf(principled, roughconductor[distribution=ggx])``
  (:func:`~brdffit.export.mitsuba_families.layered_family`), tried where
  ``max(kd) + ks > 1``: the conductor carries the lobe's colour. On the
  satin fit its errors are 0.067 / 0.023 against principled's 0.0098 / 0.014, but its
  albedo error is 0.022 against 0.106, and it is kept (candidates are ranked by log
  error plus albedo error, ``_match.best``): rendered against Mitsuba's ``measured``
  plugin on the film under a white environment, rel RMSE 0.131 and colour ratios
  1.18, 1.04, 1.10, where principled gave 0.188 and 1.31, 0.92, 0.99 and the old
  ``blendbsdf(diffuse, roughconductor)`` 0.174 and 0.89, 0.81, 0.82.
* ``principled``, the model ``principled`` (:mod:`brdffit.models.mitsuba_principled`, Mitsuba's
  plugin written as a model): its parameters and switched-on features are copied, exact.
* ``roughplastic`` is never used: its diffuse part carries internal-reflection and
  transmittance factors that none of brdffit's models has.

Roughness conventions: ``roughconductor``'s ``alpha`` IS the microfacet alpha (GGX or
Beckmann; for Cook-Torrance the rms slope ``m``): copied, never squared.
``principled``'s ``roughness`` is squared by Mitsuba (``alpha = roughness^2``): a GGX
``alpha`` is exported as ``sqrt(alpha)``, a perceptual roughness (Disney, Filament) as is.

Any other model, and every inexact case, is fitted (``_match.match``): every candidate
below that Mitsuba can express is fitted and the one with the least log error plus
albedo error (``_match.best``) is written; the export's notes list each candidate's
errors, and its ``target_model`` names the BSDF tree written (:func:`written`).
Mitsuba's BSDFs are one-sided, like brdffit's models (black below the horizon).
"""

from __future__ import annotations

import json
from collections.abc import Mapping

import numpy as np

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.result import FitResult
from brdffit.export._match import Family, Match, first_of, generic_alpha, walter_lobes
from brdffit.export.mitsuba_families import (
    PRINCIPLED_FEATURES,
    conductor_family,
    diffuse_family,
    gulbrandsen,
    layered_family,
    principled_family,
)
from brdffit.export.mitsuba_lobes import lobes_start
from brdffit.export.mitsuba_xml import to_xml
from brdffit.models import label

Start = tuple[Family, dict[str, object]]


def _layered_start(alpha: float, kd: np.ndarray, f0: np.ndarray) -> Start:
    """Start of :func:`~brdffit.export.mitsuba_families.layered_family` for ``kd / pi +
    lobe`` of RGB normal reflectance ``f0`` (ks included): ``w = 1 - max(kd)`` (the body
    just fits), the rest fitted."""
    w = float(np.clip(1.0 - np.max(kd), 0.05, 0.95))
    start = {"weight": w, "base_color": np.clip(kd / (1.0 - w), 0.0, 1.0)}
    start |= {"roughness": float(np.sqrt(alpha)), "specular": 0.5}
    return layered_family(), start | {"f0": np.clip(np.asarray(f0) / w, 0.0, 1.0)}


def _split(kd: np.ndarray | None, ks: np.ndarray) -> dict[str, object]:
    """Blend weight and diffuse reflectance for ``kd / pi + ks lobe`` (lobe colour ``ks / w``)."""
    if kd is None:
        return {}
    w = float(np.clip(max(np.max(ks), 1e-3), 0.0, 1.0 - 1e-3))
    if np.max(ks) + np.max(kd) > 1.0:  # no exact split: share the excess
        w = float(np.clip(np.max(ks) / (np.max(ks) + np.max(kd)), 1e-3, 1.0 - 1e-3))
    return {"weight": w, "reflectance": np.clip(kd / (1.0 - w), 0.0, 1.0)}


def _principled_roughness(ax: float, ay: float) -> dict[str, float]:
    """``roughness`` (and ``anisotropic``) for GGX alphas: ``r^2 = sqrt(ax ay)``."""
    r = float(np.sqrt(np.sqrt(ax * ay)))
    if ax == ay:
        return {"roughness": r}
    return {"roughness": r, "anisotropic": float(np.clip((1.0 - ay / ax) / 0.9, 0.0, 1.0))}


def _alphas(p: Mapping[str, np.ndarray], name: str) -> tuple[float, float]:
    if f"{name}_x" in p:
        return float(p[f"{name}_x"]), float(p[f"{name}_y"])
    return float(p[name]), float(p[name])


def _conductor_start(
    kind: str, ax: float, ay: float, kd: np.ndarray | None, ks: np.ndarray, f0: np.ndarray
) -> Start:
    aniso = ax != ay
    split = _split(kd, ks)
    w = split.get("weight", 1.0)
    eta, k = gulbrandsen(f0)
    rough = {"alpha_u": ax, "alpha_v": ay} if aniso else {"alpha": ax}
    start = split | rough | {"eta": eta, "k": k, "specular": np.clip(ks / w, 0.0, 1.0)}
    return conductor_family(kind, aniso, kd is not None), start


def _metal_start(ax: float, ay: float, kd: np.ndarray | None, ks: np.ndarray, f0: np.ndarray):
    rough = _principled_roughness(ax, ay)
    feats = ("anisotropic",) if "anisotropic" in rough else ()
    split = _split(kd, np.full(3, np.mean(ks)))
    if kd is None:
        split = {"weight": float(np.mean(ks)), "reflectance": np.zeros(3)}
    return principled_family(feats, with_diffuse=True), split | rough | {"base_color": f0}


def _dielectric_start(ax: float, ay: float, kd: np.ndarray, f0: np.ndarray) -> Start:
    """``principled`` with its diffuse and specular lobes added, not blended.

    For ``kd / pi + lobe`` with normal reflectance ``f0`` (RGB, ks included) where
    ``blendbsdf`` cannot: a blend scales the diffuse by ``1 - w``, so ``max(kd) + ks > 1``
    darkens the body. ``principled``'s untinted specular reaches ``f0 = 0.08 specular``;
    beyond, ``metallic`` m mixes in ``m base_color`` (and takes ``m`` from the diffuse):
    ``(1 - m) 0.08 + m mean(base) = mean(f0)``, ``base_color = kd / (1 - m)``.
    ``spec_tint`` is fitted from 0. GGX only (principled's distribution).
    """
    target, body = float(np.mean(f0)), float(np.mean(kd))
    m = float(np.clip((target - 0.08) / max(body - 0.08, 1e-3), 0.0, 0.5)) if target > 0.08 else 0.0
    rough = _principled_roughness(ax, ay)
    feats = ("metallic", "spec_tint") + (("anisotropic",) if "anisotropic" in rough else ())
    start = rough | {"base_color": np.clip(kd / (1.0 - m), 0.0, 1.0), "metallic": m}
    start |= {"specular": float(np.clip(target / 0.08, 1e-3, 1.0)), "spec_tint": 0.0}
    return principled_family(feats), start


def _walter(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    if model.n_lobes > 1:  # nested blends; exact for GGX, uncorrelated, grey ks (mitsuba_lobes)
        return [lobes_start(p.get("kd"), walter_lobes(model, p))]
    ax, ay = _alphas(p, "alpha")
    kd, ks = p.get("kd"), p.get("ks", np.ones(3))
    out = [_conductor_start(model.distribution, ax, ay, kd, ks, p["f0"])]
    if model.distribution == "ggx":
        out.append(_metal_start(ax, ay, kd, ks, p["f0"]))
        if kd is not None:
            out.append(_dielectric_start(ax, ay, kd, ks * p["f0"]))
            if ax == ay and np.max(kd) + np.max(ks) > 1.0:  # where no blend can be exact
                out.append(_layered_start(ax, kd, ks * p["f0"]))
    return out


def _cook_torrance(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    m = float(p["m"])
    fam, start = _conductor_start("beckmann", m, m, p.get("kd"), p["ks"], np.ones(3))
    if model.fresnel == "schlick":
        start["eta"], start["k"] = gulbrandsen(p["f0"])
    elif model.fresnel == "dielectric":
        start["eta"], start["k"] = np.full(3, float(p["eta"])), np.zeros(3)
    else:
        start["eta"], start["k"] = p["eta"], p["k"]
    if "kd" not in p:
        return [(fam, start)]
    f0 = p["ks"] * (p["f0"] if model.fresnel == "schlick" else 0.04)
    return [(fam, start), _dielectric_start(m, m, p["kd"], f0)]


def _disney(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    names = {"spec_tint": "specular_tint", "flatness": "subsurface"}
    feats = tuple(f for f in PRINCIPLED_FEATURES if names.get(f, f) in p)
    start = {f: p[names.get(f, f)] for f in feats}
    keep = ("base_color", "roughness", "specular")
    return [(principled_family(feats), start | {k: p[k] for k in keep})]


def _principled(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    """The ``principled`` model is Mitsuba's plugin: its parameters are copied (exact)."""
    feats = tuple(f for f in PRINCIPLED_FEATURES if f in p)
    start = {k: p[k] for k in ("base_color", "roughness", "specular", *feats)}
    return [(principled_family(feats, specular_low=0.0), start)]


def _filament(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    if model.shading == "cloth":
        return _generic(model, p)
    feats = ("metallic", "flatness")
    start: dict[str, object] = {"base_color": p["base_color"], "roughness": p["roughness"]}
    start["flatness"] = 0.0
    start |= {"metallic": p["metallic"], "specular": min(2.0 * p["reflectance"] ** 2, 1.0)}
    if model.anisotropy:
        feats += ("anisotropic",)
        start["anisotropic"] = abs(p["anisotropy"])
    if model.sheen:
        feats += ("sheen",)
        start["sheen"] = float(np.mean(p["sheen_color"]))
    if model.clearcoat:
        feats += ("clearcoat", "clearcoat_gloss")
        gloss = (0.1 - p["clear_coat_roughness"] ** 2) / 0.099
        start |= {"clearcoat": p["clear_coat"], "clearcoat_gloss": np.clip(gloss, 0, 1)}
    alpha = float(p["roughness"]) ** 2
    m, bc = float(p["metallic"]), p["base_color"]
    f0 = 0.16 * p["reflectance"] ** 2 * (1.0 - m) + bc * m
    return [
        (principled_family(feats), start),
        _metal_start(alpha, alpha, bc * (1.0 - m), np.ones(3), f0),
    ]


def _course(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    r, albedo = float(p["roughness"]), p["albedo"]
    m = float(p.get("metallic", 0.0))
    f0 = p["f0"] if "f0" in p else 0.04 * (1 - m) + albedo * m
    start = {"base_color": albedo, "roughness": r, "metallic": m, "flatness": 0.0}
    start["specular"] = float(np.clip(np.mean(f0) / 0.08, 1e-3, 1.0))
    return [
        (principled_family(("metallic", "flatness")), start),
        _metal_start(r**2, r**2, albedo * (1 - m), np.ones(3), f0),
    ]


def _ward(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    ax, ay = _alphas(p, "alpha")
    out = [_conductor_start("beckmann", ax, ay, p.get("kd"), p["ks"], np.ones(3))]
    if "kd" in p:
        out.append(_dielectric_start(ax, ay, p["kd"], np.clip(p["ks"], 0.0, 1.0)))
    return out


def _generic(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    kd = np.asarray(first_of(p, ("kd", "rd", "rho", "albedo", "base_color"), np.full(3, 0.5)))
    alpha = float(np.clip(np.mean(generic_alpha(p)), 1e-3, 1.0))
    out = [(diffuse_family(), {"reflectance": kd})]
    ks = np.full(3, 0.5)
    out.append(_conductor_start("ggx", alpha, alpha, np.clip(kd, 0, 0.5), ks, np.full(3, 0.04)))
    out.append(_dielectric_start(alpha, alpha, np.clip(kd, 0, 1), np.full(3, 0.04)))
    return out


def candidates(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    """Families worth trying for ``model`` (not a grey wrapper) with RGB parameters ``p``,
    each with its closed-form start."""
    table = {
        "lambert": lambda m, q: [(diffuse_family(), {"reflectance": q["kd"]})],
        "walter": _walter,
        "cook_torrance": _cook_torrance,
        "disney": _disney,
        "principled": _principled,
        "filament": _filament,
        "course_cook_torrance": _course,
        "ward": _ward,
    }
    return table.get(model.name, _generic)(model, p)


LOSSES = {
    "walter": "Schlick Fresnel becomes the conductor Fresnel of a fitted index (roughconductor) "
    "or the RGB ks becomes one blend weight (principled); height-correlated masking and the "
    "exact Beckmann Lambda become Mitsuba's separable Smith G (rational for Beckmann)",
    "cook_torrance": "V-cavity masking becomes Mitsuba's separable Smith G (rational Beckmann); "
    "Schlick Fresnel becomes the conductor Fresnel of a fitted index",
    "ward": "Ward's elliptical Gaussian becomes a Beckmann microfacet lobe with Smith masking",
    "disney": "Disney 2012's Schlick F0 = 0.08 specular becomes exact dielectric Fresnel for "
    "the untinted part; tints divide by Rec. 709 luminance, not (.3, .6, .1); Mitsuba's clear "
    "coat lacks 1 / (4 cos_i cos_o)",
    "filament": "the Lambert diffuse becomes Disney's diffuse (flatness toward "
    "Hanrahan-Krueger); height-correlated masking becomes separable; sheen and clear coat "
    "shapes differ",
}

ROUGHNESS = {
    "roughconductor": "roughconductor alpha is the microfacet alpha itself (GGX or Beckmann, "
    "Cook-Torrance's rms slope m): copied, not squared",
    "principled": "principled roughness is squared by Mitsuba (alpha = max(0.001, "
    "roughness^2)): a GGX alpha is written as sqrt(alpha), a perceptual roughness as it is",
    "diffuse": "diffuse: no roughness",
}


def written(bsdf: Mapping[str, object]) -> str:
    """The BSDF tree of a Mitsuba dict, as the console and records name it.

    Plugin types nest as written (``blendbsdf(diffuse, roughconductor[distribution=ggx])``),
    string properties in brackets; numbers are left to the files.
    """
    strings = [f"{k}={v}" for k, v in bsdf.items() if k != "type" and isinstance(v, str)]
    children = [written(v) for v in bsdf.values() if isinstance(v, Mapping) and "type" in v]
    children = [c for c in children if c not in ("rgb", "spectrum")]
    head = str(bsdf["type"]) + (f"[{', '.join(strings)}]" if strings else "")
    return head + (f"({', '.join(children)})" if children else "")


def finish(result: FitResult, model: AbstractModel, m: Match) -> tuple[dict, dict, list[str]]:
    """The Mitsuba dict, its XML and JSON files and the notes of a chosen match."""
    bsdf = m.family.build(m.params)
    name = label(result.model, result.options)
    kind = "exact" if m.exact else "approximate"
    comment = f"brdffit: {name} fitted to {result.source}; {kind}, error {m.error:.3g}"
    files = {
        ".mitsuba.xml": to_xml(bsdf, comment=comment.replace("--", "- -")),
        ".mitsuba.json": json.dumps(bsdf, indent=2) + "\n",
    }
    lost = (
        "Mitsuba reproduces the model"
        if m.exact
        else LOSSES.get(model.name, f"{model.name}'s lobes become {m.family.name}")
    )
    rough = next(v for k, v in ROUGHNESS.items() if k in m.family.name)
    notes = [f"roughness: {rough}", f"{kind}: {lost}"]
    if "weight" in m.params:
        notes.append(
            "kd / pi + lobe is written as blendbsdf (1 - w) diffuse(kd / (1 - w)) + w lobe; "
            "Mitsuba blends convexly and caps reflectances at 1, so only max(kd) + ks <= 1 "
            "with a grey ks can be exact"
        )
    return bsdf, files, notes
