"""Export to MaterialX: a document with one ``open_pbr_surface`` (OpenPBR 1.x) and its
``surfacematerial``, for the models whose mapping to OpenPBR is clean.

Clean means every parameter has an OpenPBR counterpart with the same meaning:

* ``lambert``: ``base_color = kd``, ``base_diffuse_roughness = 0`` (OpenPBR's EON
  diffuse is Lambertian at roughness 0, its energy compensation vanishing there) and
  ``specular_weight = 0`` (no dielectric coat, so no Fresnel darkening): exactly
  ``kd / pi``.
* ``walter`` with GGX and no diffuse (a metal): ``base_metalness = 1``, ``base_color =
  f0``, ``specular_color = 1`` (OpenPBR's F82-tint Fresnel is then exactly Schlick's),
  ``specular_weight = ks`` (grey, mean of RGB otherwise), ``specular_roughness =
  sqrt(alpha)`` (OpenPBR squares it, as glTF), anisotropy through
  ``specular_roughness_anisotropy`` a: ``alpha_t = r^2 sqrt(2 / (1 + (1 - a)^2))``,
  ``alpha_b = (1 - a) alpha_t`` along the tangent. Measured against OpenPBR's
  single-scattering microfacet BRDF with height-correlated Smith masking (Heitz 2014).
  OpenPBR asks renderers to add multiple-scattering compensation, which brightens rough
  metals beyond it; so such an export is exact only against that single-scattering
  reading, and its notes say so.

Any other model raises :class:`~brdffit.export.ExportError` through :func:`unsupported`:
OpenPBR's layered, energy-compensated dielectric has no closed form to compare with, so
no error could be measured. Use the glTF or Mitsuba export, which measure theirs.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from brdffit.core.abstract_model import AbstractModel
from brdffit.core.result import FitResult
from brdffit.export import gltf_brdf, mitsuba_bsdf
from brdffit.export._match import Family, Match, Slot
from brdffit.models import label

Start = tuple[Family, dict[str, object]]
VERSION = "1.39"


def unsupported(model: AbstractModel) -> str | None:
    """Why ``model`` has no clean OpenPBR mapping, or None when it has one."""
    if model.name == "lambert":
        return None
    if model.name == "walter" and not model.diffuse and model.distribution == "ggx":
        return None
    return (
        f"no clean OpenPBR mapping for {label(model)}; MaterialX is written for lambert and "
        "walter[diffuse=false] (GGX) only; use gltf or mitsuba, which measure their error"
    )


def openpbr_alphas(roughness: float, anisotropy: float) -> tuple[float, float]:
    """``(alpha_t, alpha_b)`` of OpenPBR's ``specular_roughness`` and its anisotropy."""
    alpha_t = roughness**2 * np.sqrt(2.0 / (1.0 + (1.0 - anisotropy) ** 2))
    return alpha_t, (1.0 - anisotropy) * alpha_t


def diffuse_family() -> Family:
    """OpenPBR with ``specular_weight = 0``: ``base_color / pi``."""
    return Family(
        "open_pbr_surface (diffuse)",
        (Slot("base_color", 3, 0.0, 1.0),),
        lambda p, wi, wo: mitsuba_bsdf.diffuse(p["base_color"], wi, wo),
        lambda p: {
            "base_weight": 1.0,
            "base_color": p["base_color"],
            "base_metalness": 0.0,
            "base_diffuse_roughness": 0.0,
            "specular_weight": 0.0,
        },
    )


def metal_family(aniso: bool) -> Family:
    """OpenPBR metal, white ``specular_color``: ``w F_schlick(base_color) D V`` (GGX)."""

    def evaluate(p: Mapping[str, object], wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        at, ab = openpbr_alphas(float(p["roughness"]), float(p.get("anisotropy", 0.0)))
        dv = gltf_brdf.specular_dv(wi, wo, at, ab)
        h = mitsuba_bsdf.half_vector(wi, wo)
        f = mitsuba_bsdf.schlick(np.asarray(p["base_color"]), np.sum(wo * h, axis=-1))
        return float(p["weight"]) * f * dv[:, None]

    def build(p: Mapping[str, object]) -> dict:
        out = {
            "base_weight": 1.0,
            "base_color": p["base_color"],
            "base_metalness": 1.0,
            "specular_weight": float(p["weight"]),
            "specular_color": np.ones(3),
            "specular_roughness": float(p["roughness"]),
        }
        return out | ({"specular_roughness_anisotropy": float(p["anisotropy"])} if aniso else {})

    slots = (
        Slot("base_color", 3, 0.0, 1.0),
        Slot("weight", 1, 0.0, 1.0),
        Slot("roughness", 1, 1e-3, 1.0),
    )
    slots += (Slot("anisotropy", 1, 0.0, 1.0),) if aniso else ()
    return Family("open_pbr_surface (metal)", slots, evaluate, build)


def candidates(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    """The OpenPBR material of a supported ``model`` (see :func:`unsupported`)."""
    if model.name == "lambert":
        return [(diffuse_family(), {"base_color": p["kd"]})]
    ax, ay = (p["alpha_x"], p["alpha_y"]) if model.anisotropic else (p["alpha"], p["alpha"])
    start: dict[str, object] = {"base_color": p["f0"], "weight": np.mean(p.get("ks", 1.0))}
    if not model.anisotropic:
        return [(metal_family(False), start | {"roughness": np.sqrt(float(ax))})]
    a = float(np.clip(1.0 - ay / ax, 0.0, 1.0))
    r = np.sqrt(ax / np.sqrt(2.0 / (1.0 + (1.0 - a) ** 2)))
    return [(metal_family(True), start | {"roughness": float(r), "anisotropy": a})]


def _value(v: object) -> tuple[str, str]:
    arr = np.atleast_1d(np.asarray(v, float))
    kind = "color3" if arr.size == 3 else "float"
    return kind, ", ".join(f"{x:.9g}" for x in arr)


def to_mtlx(inputs: Mapping[str, object], name: str, comment: str) -> str:
    """The MaterialX document text: ``open_pbr_surface`` inputs and a ``surfacematerial``."""
    lines = [
        '<?xml version="1.0"?>',
        f'<materialx version="{VERSION}">',
        f"  <!-- {comment.replace('--', '- -')} -->",
        f'  <open_pbr_surface name="SR_{name}" type="surfaceshader">',
    ]
    for key, v in inputs.items():
        kind, text = _value(v)
        lines.append(f'    <input name="{key}" type="{kind}" value="{text}" />')
    lines += [
        "  </open_pbr_surface>",
        f'  <surfacematerial name="M_{name}" type="material">',
        f'    <input name="surfaceshader" type="surfaceshader" nodename="SR_{name}" />',
        "  </surfacematerial>",
        "</materialx>",
    ]
    return "\n".join(lines) + "\n"


def written(inputs: Mapping[str, object]) -> str:
    """What a MaterialX export holds: an ``open_pbr_surface``, metal or diffuse."""
    metal = float(inputs.get("base_metalness", 0.0)) == 1.0
    return f"open_pbr_surface ({'metal' if metal else 'diffuse'})"


def finish(result: FitResult, model: AbstractModel, m: Match) -> tuple[dict, dict, list[str]]:
    """The OpenPBR inputs, the ``.mtlx`` file and the notes of a chosen match."""
    inputs = m.family.build(m.params)
    kind = "exact" if m.exact else "approximate"
    spec = label(result.model, result.options)
    comment = f"brdffit: {spec} fitted to {result.source}; {kind}, error {m.error:.3g}"
    ident = "".join(c if c.isalnum() else "_" for c in spec).strip("_")
    text = to_mtlx(inputs, f"brdffit_{ident}", comment)
    notes = [
        "roughness: OpenPBR specular_roughness is perceptual, alpha = roughness^2; a GGX "
        "alpha is written as sqrt(alpha)"
    ]
    if model.name != "lambert":
        notes.append(
            "measured against OpenPBR's single-scattering GGX metal with height-correlated "
            "Smith masking; renderers that add OpenPBR's multiple-scattering compensation "
            "render rough metals brighter; an RGB ks becomes one specular_weight"
        )
    json_ready = {
        k: (np.asarray(v).tolist() if np.ndim(v) else float(v)) for k, v in inputs.items()
    }
    return json_ready, {".mtlx": text}, notes
