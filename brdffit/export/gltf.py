"""Export to glTF 2.0: a document holding one material (``pbrMetallicRoughness`` and the
``KHR_materials_specular``, ``_ior``, ``_anisotropy``, ``_clearcoat``, ``_sheen``,
``_iridescence`` extensions where they apply), evaluated with
:mod:`brdffit.export.gltf_brdf`, on a unit sphere (:mod:`brdffit.export.gltf_mesh`) so
that a viewer shows it.

Roughness convention: glTF's ``roughnessFactor`` is perceptual, ``alpha = roughness^2``
(as in Filament, Disney and MaterialX). A GGX ``alpha`` (walter) is written as
``sqrt(alpha)``; a perceptual roughness (filament, disney, course_cook_torrance) as it
is; never squared twice. glTF caps roughness at 1, i.e. ``alpha <= 1``.

Exact mappings (measured by :func:`brdffit.export.export`):

* ``lambert``: ``specularFactor = 0`` removes the specular lobe and its Fresnel
  weighting, leaving ``baseColor / pi``;
* ``walter`` with GGX, height-correlated masking (glTF's Smith form), no diffuse and a
  grey ``ks`` (or none): ``metallic = 0``, ``baseColor = 0``, ``specularFactor = ks``,
  ``f0`` through ``ior`` and ``specularColorFactor`` (``min(R0(ior) specularColor, 1) =
  f0``), ``alpha <= 1``; anisotropic ``alpha_x``, ``alpha_y`` through ``alpha_b =
  min``, ``anisotropyStrength = sqrt((max - min)/(1 - min))``, rotation 0 or pi/2;
  with ``thin_film`` and ``ks = 1`` (or no specular weight) the film as
  ``KHR_materials_iridescence`` (``iridescenceFactor = film_weight``, ``iridescenceIor =
  film_ior``, the thickness ``film_thickness``): walter mixes each lobe's Schlick Fresnel
  with the film's on ``f0`` at ``V.H`` by ``film_weight``, as the extension's dielectric
  with ``specularFactor`` 1 does (:mod:`brdffit.models.gltf_pbr`). With ``ks < 1`` it is
  not exact (glTF's film is not scaled by ``specularFactor`` and sits on ``specularFactor
  f0``) and is fitted;
* ``gltf`` (:mod:`brdffit.models.gltf_pbr`), the material itself: every parameter is
  written as it is (``specular_f0`` through ``ior`` and ``specularColorFactor``, the
  film's thickness as ``iridescenceThicknessMaximum``, the thickness of a material
  without a thickness texture; ``iridescenceThicknessMinimum`` only maps a texture's 0,
  and the Khronos validator reports it written without one), the extensions its options
  turn on; exact by construction,
  but for one case: a fitted ``base_color`` or ``specular specular_f0`` channel within
  1e-9 of 0 is written as 0 (:mod:`brdffit.export._numbers`), and a film on it reads
  ``sqrt(f0)``, so the written material departs by ~1e-7 relative and the export says
  approximate (seen on an RGL cc_nothern_aurora fit with ``base_color[r] = 8e-10``).

Everything else is approximate, chiefly because glTF couples its diffuse to the
specular (``(1 - max F) baseColor / pi``) where brdffit's models add an uncoupled
Lambert; those materials are fitted by least squares.
"""

from __future__ import annotations

import json
from collections.abc import Mapping

import numpy as np

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.result import FitResult
from brdffit.export import gltf_brdf
from brdffit.export._match import Family, Match, Slot, generic_alpha, walter_lobes
from brdffit.export.gltf_mesh import add_sphere
from brdffit.models import label
from brdffit.util.version import __version__

Start = tuple[Family, dict[str, object]]


def gltf_family(
    rotation: float | None, clearcoat: bool, sheen: bool, iridescence: bool = False
) -> Family:
    """The glTF material with the extensions chosen statically.

    ``rotation``: None (isotropic) or the anisotropy rotation (radians, 0 or pi/2).
    """
    slots = (
        Slot("base_color", 3, 0.0, 1.0),
        Slot("metallic", 1, 0.0, 1.0),
        Slot("roughness", 1, 1e-3, 1.0),
        Slot("specular", 1, 0.0, 1.0),
        Slot("specular_f0", 3, 0.0, 1.0),
    )
    if rotation is not None:
        slots += (Slot("anisotropy_strength", 1, 0.0, 1.0),)
    if clearcoat:
        slots += (Slot("clearcoat", 1, 0.0, 1.0), Slot("clearcoat_roughness", 1, 1e-3, 1.0))
    if sheen:
        slots += (Slot("sheen_color", 3, 0.0, 1.0), Slot("sheen_roughness", 1, 0.045, 1.0))
    if iridescence:  # the bounds of the gltf model's (and walter's film's) parameters
        slots += (
            Slot("iridescence", 1, 0.0, 1.0),
            Slot("iridescence_ior", 1, 1.0, 2.5),
            Slot("iridescence_thickness", 1, 0.0, 1200.0),
        )

    def values(p: Mapping[str, object]) -> dict[str, object]:
        return dict(p) | ({} if rotation is None else {"anisotropy_rotation": rotation})

    def evaluate(p: Mapping[str, object], wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return gltf_brdf.material(values(p), wi, wo)

    return Family("glTF metallic-roughness", slots, evaluate, lambda p: to_material(values(p)))


def ior_and_color(f0: np.ndarray) -> tuple[float, np.ndarray]:
    """``(ior, specularColorFactor)`` with ``min(((ior - 1)/(ior + 1))^2 color, 1) = f0``.

    The IOR carries the largest channel (so the colour stays in [0, 1]) while that is
    below 0.99; beyond, ``ior = 1.5`` and the colour goes above 1, which
    ``KHR_materials_specular`` allows. An IOR within 1e-12 of 1.5 (``f0 = 0.04`` gives
    1.4999999999999998) is written as 1.5, the default, so that no extension is written
    for it; ``f0`` moves by 1e-12 relative, far inside the exact tolerance.
    """
    f0 = np.asarray(f0, float)
    top = float(np.max(f0))
    if top <= 0.0:
        return 1.5, np.zeros(3)
    if top < 0.99:
        s = np.sqrt(top)
        ior = float((1 + s) / (1 - s))
        return (1.5 if abs(ior - 1.5) <= 1.5e-12 else ior), f0 / top
    return 1.5, f0 / 0.04


def _floats(v: object) -> list[float]:
    return [float(x) for x in np.atleast_1d(v)]


def to_material(p: Mapping[str, object]) -> dict:
    """glTF material JSON (a dict) of the parameters :func:`gltf_brdf.material` takes."""
    pbr = {
        "baseColorFactor": _floats(p["base_color"]) + [1.0],
        "metallicFactor": float(p["metallic"]),
        "roughnessFactor": float(p["roughness"]),
    }
    ext: dict[str, dict] = {}
    ior, color = ior_and_color(p["specular_f0"])
    if float(p["specular"]) != 1.0 or not np.allclose(color, 1.0, rtol=0, atol=1e-15):
        ext["KHR_materials_specular"] = {
            "specularFactor": float(p["specular"]),
            "specularColorFactor": _floats(color),
        }
    if ior != 1.5:
        ext["KHR_materials_ior"] = {"ior": ior}
    if "anisotropy_strength" in p:
        ext["KHR_materials_anisotropy"] = {
            "anisotropyStrength": float(p["anisotropy_strength"]),
            "anisotropyRotation": float(p.get("anisotropy_rotation", 0.0)),
        }
    if "clearcoat" in p:
        ext["KHR_materials_clearcoat"] = {
            "clearcoatFactor": float(p["clearcoat"]),
            "clearcoatRoughnessFactor": float(p["clearcoat_roughness"]),
        }
    if "sheen_color" in p:
        ext["KHR_materials_sheen"] = {
            "sheenColorFactor": _floats(p["sheen_color"]),
            "sheenRoughnessFactor": float(p["sheen_roughness"]),
        }
    if "iridescence" in p:  # no texture: the thickness is the maximum (module docstring)
        ext["KHR_materials_iridescence"] = {
            "iridescenceFactor": float(p["iridescence"]),
            "iridescenceIor": float(p["iridescence_ior"]),
            "iridescenceThicknessMaximum": float(p["iridescence_thickness"]),
        }
    out: dict = {"pbrMetallicRoughness": pbr}
    return out | ({"extensions": ext} if ext else {})


def _roughness(ax: float, ay: float) -> tuple[float | None, dict[str, float]]:
    """Rotation and glTF roughness slots for GGX alphas (module docstring)."""
    lo, hi = min(ax, ay), max(ax, ay)
    out = {"roughness": float(np.sqrt(lo))}
    if ax == ay:
        return None, out
    strength = np.sqrt(np.clip((hi - lo) / max(1.0 - lo, 1e-12), 0.0, 1.0))
    return (0.0 if ax >= ay else np.pi / 2), out | {"anisotropy_strength": float(strength)}


def _start(
    ax: float,
    ay: float,
    cc: bool = False,
    sheen: bool = False,
    film: bool = False,
    **values: object,
) -> Start:
    rotation, rough = _roughness(ax, ay)
    start = {"metallic": 0.0, "specular": 1.0, "specular_f0": np.full(3, 0.04)} | rough
    return gltf_family(rotation, cc, sheen, film), start | values


def _walter(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    """One start per specular lobe (glTF holds one), with the sheen as
    ``KHR_materials_sheen``, the clear coat as ``KHR_materials_clearcoat`` and the thin
    film as ``KHR_materials_iridescence``: walter's are those extensions' formulas
    (:mod:`brdffit.models.walter`; the film's exactly when ``ks = 1``)."""
    layers: dict[str, object] = {"base_color": p.get("kd", np.zeros(3))}
    if model.sheen:
        layers |= {"sheen_color": p["sheen_color"], "sheen_roughness": p["sheen_roughness"]}
    if model.clearcoat:
        layers |= {"clearcoat": p["clearcoat"]}
        layers["clearcoat_roughness"] = float(np.sqrt(p["clearcoat_alpha"]))
    if model.thin_film:
        layers |= {
            "iridescence": p["film_weight"],
            "iridescence_ior": p["film_ior"],
            "iridescence_thickness": p["film_thickness"],
        }
    return [
        _start(
            ax,
            ay,
            model.clearcoat,
            model.sheen,
            model.thin_film,
            **layers,
            specular=float(np.mean(ks)),
            specular_f0=f0,
        )
        for ax, ay, ks, f0 in walter_lobes(model, p)
    ]


def _filament(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    if model.shading == "cloth":
        return _generic(model, p)
    alpha = float(p["roughness"]) ** 2
    a = float(p.get("anisotropy", 0.0))
    values: dict[str, object] = {"base_color": p["base_color"], "metallic": p["metallic"]}
    values["specular_f0"] = np.full(3, 0.16 * float(p["reflectance"]) ** 2)
    if model.clearcoat:
        values |= {"clearcoat": p["clear_coat"], "clearcoat_roughness": p["clear_coat_roughness"]}
    if model.sheen:
        values |= {"sheen_color": p["sheen_color"], "sheen_roughness": p["sheen_roughness"]}
    ax, ay = alpha * (1 + a), alpha * (1 - a)
    if not model.anisotropy:
        ax = ay = alpha
    return [_start(ax, ay, model.clearcoat, model.sheen, **values)]


def _disney(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    c, r2 = p["base_color"], float(p["roughness"]) ** 2
    aspect = np.sqrt(1.0 - 0.9 * float(p.get("anisotropic", 0.0)))
    lum = 0.3 * c[0] + 0.6 * c[1] + 0.1 * c[2]
    tint = c / lum if lum > 0 else np.ones(3)
    f0 = 0.08 * float(p["specular"]) * (1.0 + float(p.get("specular_tint", 0.0)) * (tint - 1.0))
    values = {"base_color": c, "metallic": float(p.get("metallic", 0.0))}
    values["specular_f0"] = np.clip(f0, 0.0, 1.0)
    if model.clearcoat:
        gloss_alpha = 0.1 + float(p["clearcoat_gloss"]) * (0.001 - 0.1)
        values |= {"clearcoat": 0.25 * float(p["clearcoat"])}
        values["clearcoat_roughness"] = float(np.sqrt(gloss_alpha))
    if model.sheen:
        values |= {"sheen_color": np.full(3, 0.1 * float(p["sheen"])), "sheen_roughness": 1.0}
    ax, ay = max(0.001, r2 / aspect), max(0.001, r2 * aspect)
    return [_start(ax, ay, model.clearcoat, model.sheen, **values)]


def _course(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    alpha = float(p["roughness"]) ** 2
    values: dict[str, object] = {"base_color": p["albedo"]}
    if "metallic" in p:
        values["metallic"] = float(p["metallic"])
    else:
        values["specular_f0"] = p["f0"]
    return [_start(alpha, alpha, **values)]


def _gltf(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    """The identity: the model is this material (:mod:`brdffit.models.gltf_pbr`)."""
    core = {"specular": 1.0, "specular_f0": np.full(3, 0.04)}  # without KHR_materials_specular
    family = gltf_family(None, model.clearcoat, model.sheen, model.iridescence)
    return [(family, core | dict(p))]


def _generic(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    names = ("kd", "rd", "rho", "albedo", "base_color")
    kd = next((p[n] for n in names if n in p), np.full(3, 0.5))
    alpha = float(np.clip(generic_alpha(p), 1e-4, 1.0))
    ks = next((p[n] for n in ("ks", "rs", "ks_1", "rho_1") if n in p), np.ones(3))
    return [_start(alpha, alpha, base_color=kd, specular=float(np.clip(np.mean(ks), 0, 1)))]


def candidates(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    """The glTF material for ``model`` (not a grey wrapper) with RGB parameters ``p``,
    started from the closed-form mapping."""
    if model.name == "lambert":
        values = {"base_color": p["kd"], "specular": 0.0, "roughness": 1.0}
        return [_start(1.0, 1.0, **values)]
    table = {
        "walter": _walter,
        "filament": _filament,
        "disney": _disney,
        "course_cook_torrance": _course,
        "gltf": _gltf,
    }
    return table.get(model.name, _generic)(model, p)


LOSSES = {
    "walter": "Lambert kd / pi becomes glTF's coupled (1 - max F) baseColor / pi; RGB ks "
    "becomes one specularFactor; Beckmann or uncorrelated masking become GGX with "
    "height-correlated Smith; a thin film under ks < 1 becomes glTF's film, which "
    "specularFactor does not scale",
    "filament": "the diffuse becomes glTF's (1 - max F)-weighted Lambert; Filament's clear "
    "coat (Kelemen visibility, base f0 and roughness changes) and sheen base scaling differ",
    "disney": "Disney's retro-reflective diffuse, subsurface, grazing sheen and GTR1 clear "
    "coat have no glTF counterpart and are approximated by fitted glTF lobes",
}


def written(doc: Mapping[str, object]) -> str:
    """What a glTF document holds: ``pbrMetallicRoughness`` and the extensions used."""
    used = doc.get("extensionsUsed", [])
    return "glTF pbrMetallicRoughness" + (f" + {', '.join(used)}" if used else "")


def finish(result: FitResult, model: AbstractModel, m: Match) -> tuple[dict, dict, list[str]]:
    """The glTF document, its file and the notes of a chosen match."""
    mat = m.family.build(m.params)
    name = label(result.model, result.options)
    kind = "exact" if m.exact else "approximate"
    mat = {"name": f"brdffit {name}"} | mat
    mat["extras"] = {
        "brdffit": {"model": name, "source": result.source, "exact": m.exact, "error": m.error}
    }
    doc = {"asset": {"version": "2.0", "generator": f"brdffit {__version__}"}}
    used = sorted(mat.get("extensions", {}))
    doc |= ({"extensionsUsed": used} if used else {}) | {"materials": [mat]}
    doc = add_sphere(doc)  # a viewer shows the material on a unit sphere
    notes = [
        "roughness: glTF roughnessFactor is perceptual, alpha = roughness^2; a GGX alpha is "
        "written as sqrt(alpha), a perceptual roughness as it is",
        f"{kind}: "
        + (
            "the glTF BRDF (Appendix B and its extensions) reproduces the model"
            if m.exact
            else LOSSES.get(model.name, f"{model.name}'s lobes become glTF's GGX lobes")
        ),
    ]
    if "KHR_materials_sheen" in used:
        notes.append("sheen: evaluated with the Ashikhmin visibility and no albedo scaling")
    if "KHR_materials_iridescence" in used:
        notes.append(
            "iridescence: the film's Fresnel evaluated at V.H, as the extension's text mixes "
            "it with the Fresnel at V.H; the glTF sample viewer and three.js evaluate it once "
            "per pixel at N.V, which agrees at the mirror direction only (on RGL cc_* fits "
            "that moves f cos by 1-2% RMS); the thickness is iridescenceThicknessMaximum"
        )
    return doc, {".gltf": json.dumps(doc, indent=2) + "\n"}, notes
