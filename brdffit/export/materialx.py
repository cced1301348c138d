"""Export to MaterialX: a document with one ``open_pbr_surface`` (OpenPBR 1.1) and its
``surfacematerial``, for every model.

The written material is evaluated as MaterialX's GLSL evaluates it: by the ``openpbr``
model (:mod:`brdffit.models.openpbr`, checked pointwise against an interpreter of
MaterialX's own ``open_pbr_surface`` node graph in ``tests/models/test_openpbr.py``), so
every error reported here is the error against what MaterialX renders (under direct light).

* ``openpbr``, the material itself: every parameter is written as it is, with the
  features its options turn on; exact by construction, except where the metal lobe
  meets MaterialX's F82 Fresnel below 0 (a ``specular_color`` below about 0.5 over a dark
  ``base_color``), which the model floors at 0 and MaterialX renders negative: there
  ``specular_color`` starts at the least value that keeps it >= 0 (:func:`f82_tint_floor`)
  and is fitted, the error measured against what MaterialX renders.
* Every other model: an OpenPBR form is fitted to the model's BRDF (least squares on the
  log error, :func:`brdffit.export._match.match`), with a coat where the model has a clear
  coat, a fuzz where it has a sheen and anisotropy where it is anisotropic; the start is a
  closed-form reading of the model's parameters (:func:`candidates`), the error measured.

No other model maps exactly. MaterialX's dielectric lobe takes a throughput ``1 - E(c_v)
comp`` from the diffuse under it, and its albedo fit ``E = F0 A + F90 B`` keeps ``B > 0``
even at ``specular_weight = 0`` (``F0 = 0``, ``F90 = 1``), so a Lambertian ``kd / pi`` is
dimmed by ``1 - B(cos_o, alpha)`` (0.25% at normal view with a mirror-smooth lobe, up
to 60% at grazing views; least with a rough lobe, where the closed-form reading,
``specular_weight`` 0 and ``specular_roughness`` 1, has a relative error 0.0031);
OpenPBR's metal carries Turquin's energy compensation ``1 + F (1 - E_ss) / E_ss``, so a
single-scattering GGX metal (walter) renders brighter (the closed-form reading,
``base_metalness`` 1, ``base_color = f0``: relative error 0.098 at alpha 0.2, 0.81 at
alpha 0.8; ``tests/export/test_openpbr_export.py``). Both are therefore fitted, and their
error measured, like every other model.

Roughness: OpenPBR's ``specular_roughness`` is perceptual (``alpha = r^2``, stretched by
``specular_roughness_anisotropy`` ``a``: ``alpha_x = r^2 sqrt(2 / (1 + (1 - a)^2))``,
``alpha_y = (1 - a) alpha_x``); a GGX ``alpha`` starts as ``sqrt(alpha)``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from brdffit.core.abstract_model import AbstractModel, eval_compiled
from brdffit.core.result import FitResult
from brdffit.export._match import Family, Match, Slot, first_of, generic_alpha, walter_lobes
from brdffit.models import label
from brdffit.models.openpbr import OpenPbr

Start = tuple[Family, dict[str, object]]
VERSION = "1.39"
CHUNK = 1024
"""Direction pairs per compiled call of the OpenPBR evaluation (the last chunk padded): one
compilation per feature set serves every direction count."""
PERCEPTUAL = ("gltf", "disney", "filament", "principled", "course_cook_torrance", "openpbr")
"""Models whose ``roughness`` is perceptual already (``alpha = roughness^2``)."""


def roughness_of(ax: float, ay: float) -> dict[str, float]:
    """OpenPBR ``specular_roughness`` (and ``specular_roughness_anisotropy`` when ``ax !=
    ay``) of GGX alphas; OpenPBR stretches along the tangent only, so the larger alpha is
    taken as ``alpha_x`` (exact for ``ax >= ay``)."""
    hi, lo = max(ax, ay), min(ax, ay)
    a = float(np.clip(1.0 - lo / hi, 0.0, 1.0)) if hi > 0 else 0.0
    r = float(np.sqrt(hi / np.sqrt(2.0 / (1.0 + (1.0 - a) ** 2))))
    return {"specular_roughness": r} | ({"specular_roughness_anisotropy": a} if ax != ay else {})


def openpbr_family(model: OpenPbr) -> Family:
    """OpenPBR with the features of ``model`` (an ``openpbr`` model) as a family: its
    parameters are the slots (the model's bounds), evaluated in float64 as MaterialX
    renders them: by the model with ``negative_f82`` (MaterialX's metal Fresnel, negative
    where a low ``specular_color`` meets a dark ``base_color``)."""
    slots = tuple(Slot(p.name, p.size, *p.bounds) for p in model.parameters)
    name = f"open_pbr_surface ({label(model)})"
    model = OpenPbr(**(model.options() | {"negative_f82": True}))

    def evaluate(p: Mapping[str, object], wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        params = {
            q.name: np.broadcast_to(np.asarray(p[q.name], float), q.shape) for q in model.parameters
        }
        n = len(wi)
        up = np.tile([0.0, 0.0, 1.0], (-n % CHUNK, 1))
        wi, wo = np.vstack([wi, up]), np.vstack([wo, up])
        ends = range(0, n, CHUNK)
        parts = [eval_compiled(model, params, wi[k : k + CHUNK], wo[k : k + CHUNK]) for k in ends]
        return np.concatenate([np.asarray(f, float) for f in parts])[:n]

    def build(p: Mapping[str, object]) -> dict:
        return {"base_weight": 1.0} | {s.name: p[s.name] for s in slots}

    return Family(name, slots, evaluate, build)


def f82_tint_floor(f0: np.ndarray) -> np.ndarray:
    """The least ``specular_color`` per channel at which the F82 Fresnel of ``base_color``
    ``f0`` (3,) is >= 0 at every angle (:func:`~brdffit.models._terms.f82_schlick`: ``(1 -
    tint) <= min over c of F_s(c) mu (1 - mu)^6 / (c (1 - c)^6 F_s(mu))``), on 2001
    cosines, rounded up by 1e-9; 0 where none is needed (0.51 at ``f0 = 0``)."""
    c = np.linspace(1e-6, 1.0 - 1e-6, 2001)[:, None]
    f0 = np.asarray(f0, float)[None, :]
    mu = 1.0 / 7.0
    schlick = f0 + (1.0 - f0) * (1.0 - c) ** 5
    at_mu = f0 + (1.0 - f0) * (1.0 - mu) ** 5
    ratio = np.min(schlick / (c * (1.0 - c) ** 6), axis=0) * mu * (1.0 - mu) ** 6 / at_mu[0]
    return np.clip(1.0 - ratio + 1e-9, 0.0, 1.0)


def _features(model: AbstractModel) -> dict[str, bool]:
    """The OpenPBR options that hold what ``model`` has: a coat for a clear coat, a fuzz for
    a sheen, a thin film for a thin film (iridescence), anisotropy for an anisotropic
    model."""
    has = model.options()
    coat = bool(has.get("clearcoat") or has.get("coat"))
    fuzz = bool(has.get("sheen") or has.get("fuzz") or getattr(model, "shading", "") == "cloth")
    film = bool(has.get("thin_film") or has.get("iridescence"))
    return {"anisotropic": not model.isotropic, "coat": coat, "fuzz": fuzz, "thin_film": film}


def _ior(f0: object) -> float:
    """The index of refraction of a normal reflectance (mean of RGB), within [1, 3]."""
    s = float(np.sqrt(np.clip(np.mean(f0), 0.0, 0.25)))
    return (1.0 + s) / (1.0 - s)


def _start(model: AbstractModel, p: Mapping[str, np.ndarray], **values: object) -> Start:
    """OpenPBR with the model's features, started from ``values`` over neutral defaults."""
    features = _features(model)
    target = OpenPbr(**features)
    start: dict[str, object] = {
        "base_color": np.full(3, 0.5),
        "base_metalness": 0.0,
        "base_diffuse_roughness": 0.0,
        "specular_weight": 1.0,
        "specular_color": np.ones(3),
        "specular_roughness": 0.5,
        "specular_ior": 1.5,
        "specular_roughness_anisotropy": 0.0,
    }
    if features["coat"]:
        weight = first_of(p, ("clearcoat", "clear_coat", "coat_weight"), 0.5)
        alpha = first_of(p, ("clearcoat_alpha",), None)
        if "clearcoat_gloss" in p:  # Disney, Mitsuba: GTR1 of lerp(.1, .001, gloss), 1/4 F
            alpha, weight = 0.1 - 0.099 * float(p["clearcoat_gloss"]), 0.25 * float(weight)
        rough = np.sqrt(alpha) if alpha is not None else 0.1
        rough = first_of(p, ("clear_coat_roughness", "clearcoat_roughness"), rough)
        start |= {"coat_weight": weight, "coat_roughness": rough, "coat_ior": 1.5}
    if features["fuzz"]:
        color = first_of(p, ("sheen_color", "fuzz_color"), np.full(3, 0.5))
        rough = first_of(p, ("sheen_roughness", "fuzz_roughness"), 0.5)
        start |= {"fuzz_weight": 1.0, "fuzz_color": color, "fuzz_roughness": rough}
    if features["thin_film"]:
        nm = first_of(p, ("film_thickness", "iridescence_thickness"), 500.0)
        start |= {
            "thin_film_weight": first_of(p, ("film_weight", "iridescence"), 0.5),
            "thin_film_thickness": float(np.clip(nm / 1000.0, 0.01, 2.0)),
            "thin_film_ior": first_of(p, ("film_ior", "iridescence_ior"), 1.4),
        }
    start |= values
    return openpbr_family(target), {k: v for k, v in start.items() if k in _names(target)}


def _names(model: AbstractModel) -> set[str]:
    return {q.name for q in model.parameters}


def _openpbr(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    """The identity: the model is this material, exactly unless its metal lobe meets
    MaterialX's negative F82 (the model floors it at 0): then the start raises
    ``specular_color`` to :func:`f82_tint_floor` (a metal MaterialX renders >= 0) and
    least squares refines it against the fit."""
    start = dict(p)
    metal = float(p["base_metalness"]) > 0.0 and float(p["specular_weight"]) > 0.0
    floor = f82_tint_floor(p["base_color"])
    if metal and np.any(np.asarray(p["specular_color"]) < floor):
        start["specular_color"] = np.maximum(p["specular_color"], floor)
    return [(openpbr_family(model), start)]  # type: ignore[arg-type]


def _walter(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    """One start per specular lobe: a metal (``base_color = f0``, ``specular_weight = ks``)
    without a diffuse, else a dielectric whose index gives ``f0`` and whose
    ``specular_color`` carries ``ks``, over ``base_color = kd``."""
    out = []
    for ax, ay, ks, f0 in walter_lobes(model, p):
        rough = roughness_of(ax, ay)
        if model.diffuse:
            values = {"base_color": p["kd"], "specular_color": np.clip(ks, 0.0, 1.0)}
            values |= {"specular_ior": _ior(f0)}
        else:
            values = {"base_color": f0, "base_metalness": 1.0}
            values |= {"specular_weight": float(np.clip(np.mean(ks), 0.0, 1.0))}
        out.append(_start(model, p, **values, **rough))
    return out


def _generic(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    """The base colour, metalness and roughness read by their usual names."""
    color = first_of(p, ("base_color", "kd", "rd", "rho", "albedo", "color"), np.full(3, 0.5))
    values: dict[str, object] = {"base_color": np.clip(color, 0.0, 1.0)}
    values["base_metalness"] = float(np.clip(first_of(p, ("metallic",), 0.0), 0.0, 1.0))
    if model.name in PERCEPTUAL and "roughness" in p:
        values["specular_roughness"] = float(np.clip(p["roughness"], 0.01, 1.0))
    else:
        alpha = float(np.clip(generic_alpha(p), 1e-4, 1.0))
        values["specular_roughness"] = float(np.sqrt(alpha))
    if model.name == "lambert":  # no specular lobe: the least a dielectric can add
        values |= {"specular_weight": 0.0, "specular_roughness": 1.0}
    f0 = first_of(p, ("f0", "specular_f0"), None)
    if f0 is not None and values["base_metalness"] < 1.0:
        values["specular_ior"] = _ior(f0)
    return [_start(model, p, **values)]


def candidates(model: AbstractModel, p: Mapping[str, np.ndarray]) -> list[Start]:
    """The OpenPBR material for ``model`` (not a grey wrapper) with RGB parameters ``p``:
    the identity for ``openpbr``, else closed-form starts that least squares refines."""
    table = {"openpbr": _openpbr, "walter": _walter}
    return table.get(model.name, _generic)(model, p)


def _value(v: object) -> tuple[str, str]:
    arr = np.atleast_1d(np.asarray(v, float))
    kind = "color3" if arr.size == 3 else "float"
    return kind, ", ".join(f"{x:.9g}" for x in arr)


def to_mtlx(inputs: Mapping[str, object], name: str, comment: str) -> str:
    """The MaterialX document text: ``open_pbr_surface`` inputs and a ``surfacematerial``.
    Numbers have 9 significant digits, which a float32 reader reads back exactly."""
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


FEATURES = (
    ("specular_roughness_anisotropy", "anisotropic"),
    ("coat_weight", "coat"),
    ("fuzz_weight", "fuzz"),
    ("thin_film_weight", "thin film"),
)


def written(inputs: Mapping[str, object]) -> str:
    """What a MaterialX export holds: ``open_pbr_surface`` and the features it uses."""
    used = [name for key, name in FEATURES if key in inputs]
    return "open_pbr_surface" + (f" ({', '.join(used)})" if used else "")


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
        "alpha starts as sqrt(alpha)",
        f"{kind}: "
        + (
            "the openpbr model is OpenPBR as MaterialX's GLSL evaluates it"
            if m.exact
            else f"{model.name}'s BRDF fitted by OpenPBR as MaterialX's GLSL evaluates it "
            "(energy-compensated GGX, EON diffuse under the dielectric's throughput)"
        ),
        "measured under direct light; MaterialX's environment lighting (prefiltered or "
        "sampled) is not part of the BRDF",
    ]
    json_ready = {
        k: (np.asarray(v).tolist() if np.ndim(v) else float(v)) for k, v in inputs.items()
    }
    return json_ready, {".mtlx": text}, notes
