"""High-precision reference for ``brdffit/models/gltf_pbr.py``: the glTF 2.0 spec in mpmath,
and the glTF material JSON read as the spec defines it.

Transcribed from the glTF 2.0 specification, Appendix B (``D_GGX``, ``V_GGX``, ``fresnel_mix``
with KHR_materials_specular/_ior, ``conductor_fresnel``, ``mix`` by metallic), the
KHR_materials_sheen text (``D_Charlie``, the Ashikhmin visibility, no albedo scaling),
KHR_materials_clearcoat (``fresnel_coat`` at ``N.V``, IOR 1.5), KHR_materials_iridescence
(``iridescent_dielectric_layer`` with KHR_materials_specular, ``iridescent_conductor_layer``,
``iridescent_fresnel``) and, for walter's anisotropic lobes written to glTF,
KHR_materials_anisotropy (``D_GGX_anisotropic``, ``V_GGX_anisotropic``), as written there:
``D = a^2 / (pi ((N.H)^2 (a^2 - 1) + 1)^2)``, ``V = 1 / (N.L sqrt(N.V^2 (1 - a^2) + a^2) +
N.V sqrt(N.L^2 (1 - a^2) + a^2)) / 2``, the Fresnel weight at ``|V.H|``. Evaluated one pair at
a time at the caller's working precision (tests/references.py); nothing here calls
``brdffit/models/``.

* :func:`iridescent_fresnel` is the extension's GLSL (its README, "Iridescence Fresnel"),
  with the guards of the glTF sample viewer's ``iridescence.glsl`` (film index to 1 by a
  smoothstep over 0.03 nm of thickness, base ``f0`` clamped to 0.9999, where the README adds
  1e-4), OPD with ``cos(theta_2)``; at the working precision, or at mpmath's default 53 bits
  when called with floats (``tests/models/test_lobes.py`` checks ``_terms.thin_film_fresnel``
  with it).
* :func:`gltf_ref` evaluates the film's Fresnel at ``V.H`` (the cosine the text's ``fr``
  uses, and Belcour and Barla's), the dielectric's base weighted by ``1 - max`` of the
  mixed Fresnel, its film on ``specular * f0`` (the README's form with KHR_materials_specular).
  :func:`wrong_ref` is the same with one of :data:`WRONG` changes, for the tests that show a
  check can fail.
* :func:`material_values` reads a glTF material (the JSON, nothing else) into the values
  :func:`gltf_ref` takes, and :func:`document_brdf` evaluates it.
"""

from __future__ import annotations

from types import SimpleNamespace

import mpmath as mp
import numpy as np

from tests.references import Reference, dot, num, per_pair, rgb

F0_FLOOR = 1e-12
"""The floor brdffit's ``thin_film_fresnel`` documents on the base ``f0`` (so that ``d sqrt
f0`` stays finite at 0): the reference of the model applies it too; the sample viewer's clamp
starts at 0 (changing the film by ~1e-6 relative at ``f0 = 0`` only)."""

_XYZ_TO_REC709 = (
    ("3.2404542", "-1.5371385", "-0.4985314"),
    ("-0.9692660", "1.8760108", "0.0415560"),
    ("0.0556434", "-0.2040259", "1.0572252"),
)
_VAL = ("5.4856e-13", "4.4201e-13", "5.2481e-13")
_POS = ("1.6810e+06", "1.7953e+06", "2.2084e+06")
_VAR = ("4.3278e+09", "9.3046e+09", "6.6121e+09")


def _sensitivity(opd, shift: list) -> list:
    """``evalSensitivity(OPD, shift)`` of the README: XYZ in Fourier space, in Rec. 709 RGB.
    ``shift`` has one phase per XYZ component (the GLSL's ``vec3``)."""
    phase = 2 * mp.pi * opd * num("1e-9")
    xyz = [
        num(v)
        * mp.sqrt(2 * mp.pi * num(s))
        * mp.cos(num(p) * phase + sh)
        * mp.exp(-(phase**2) * num(s))
        for v, p, s, sh in zip(_VAL, _POS, _VAR, shift, strict=True)
    ]
    var_x, pos_x = num("4.5282e+09"), num("2.2399e+06")
    peak_x = num("9.7470e-14") * mp.sqrt(2 * mp.pi * var_x)
    xyz[0] += peak_x * mp.cos(pos_x * phase + shift[0]) * mp.exp(-var_x * phase**2)
    xyz = [x / num("1.0685e-7") for x in xyz]
    return [sum(num(m) * x for m, x in zip(row, xyz, strict=True)) for row in _XYZ_TO_REC709]


def _schlick(f0, c):
    return f0 + (1 - f0) * (1 - c) ** 5


def iridescent_fresnel(cos1, thickness, film_ior, base_f0, *, f0_floor=0.0, opd_cos1=False):
    """The README's ``iridescent_fresnel(1, film_ior, base_f0, thickness, cos1)``, outside
    IOR 1 (module docstring): three reflectances (R, G, B) of the film on a base of normal
    reflectance ``base_f0`` (three values) at the incidence cosine ``cos1``; ``thickness``
    in nm. ``f0_floor``: the lower end of the clamp of ``base_f0`` (the sample viewer's 0, or
    :data:`F0_FLOOR`). ``opd_cos1``: the OPD with ``cos(theta_1)``, the README before 2024
    (a wrong formula, for tests)."""
    cos1, thickness, film_ior = mp.mpf(cos1), mp.mpf(thickness), mp.mpf(film_ior)
    s = min(max(thickness / num("0.03"), mp.mpf(0)), mp.mpf(1))
    ior = 1 + (film_ior - 1) * s * s * (3 - 2 * s)  # smoothstep(0, 0.03, thickness)
    cos2 = mp.sqrt(1 - (1 / ior) ** 2 * (1 - cos1**2))
    r12 = _schlick(((ior - 1) / (ior + 1)) ** 2, cos1)
    t121 = 1 - r12
    phi21 = mp.pi - (mp.pi if ior < 1 else 0)
    opd = 2 * ior * thickness * (cos1 if opd_cos1 else cos2)
    lo, hi = num("1e-5"), num("0.9999")
    r23, phi = [], []
    for f0 in base_f0:
        root = mp.sqrt(min(max(mp.mpf(f0), mp.mpf(f0_floor)), hi))
        base_ior = (1 + root) / (1 - root)
        r23.append(_schlick(((base_ior - ior) / (base_ior + ior)) ** 2, cos2))
        phi.append(phi21 + (mp.pi if base_ior < ior else 0))
    r123 = [min(max(r12 * r, lo), hi) for r in r23]
    rs = [t121**2 * r / (1 - q) for r, q in zip(r23, r123, strict=True)]
    out = [r12 + x for x in rs]
    cm = [x - t121 for x in rs]
    for m in (1, 2):
        cm = [c * mp.sqrt(q) for c, q in zip(cm, r123, strict=True)]
        sens = _sensitivity(m * opd, [m * x for x in phi])
        out = [i + c * 2 * x for i, c, x in zip(out, cm, sens, strict=True)]
    return [max(i, mp.mpf(0)) for i in out]


def _dv(alpha, g):
    a2 = alpha**2
    d = a2 / (mp.pi * (g.ch**2 * (a2 - 1) + 1) ** 2)
    v = 1 / (g.ci * mp.sqrt(g.co**2 * (1 - a2) + a2) + g.co * mp.sqrt(g.ci**2 * (1 - a2) + a2))
    return d * v / 2


def _dv_anisotropic(alpha, strength, rotation, g):
    """KHR_materials_anisotropy: ``D_GGX_anisotropic V_GGX_anisotropic`` with ``a_t =
    mix(alpha, 1, strength^2)`` along ``t = (cos r, sin r, 0)``, ``a_b = alpha`` along ``b =
    N x t``."""
    at, ab = alpha + (1 - alpha) * strength**2, alpha
    t, b = (mp.cos(rotation), mp.sin(rotation), 0), (-mp.sin(rotation), mp.cos(rotation), 0)
    a2 = at * ab
    f2 = (ab * dot(g.h, t)) ** 2 + (at * dot(g.h, b)) ** 2 + (a2 * g.ch) ** 2
    d = a2 * (a2 / f2) ** 2 / mp.pi
    ggx_v = g.ci * mp.sqrt((at * dot(g.wo, t)) ** 2 + (ab * dot(g.wo, b)) ** 2 + g.co**2)
    ggx_l = g.co * mp.sqrt((at * dot(g.wi, t)) ** 2 + (ab * dot(g.wi, b)) ** 2 + g.ci**2)
    return d / (2 * (ggx_v + ggx_l))


WRONG = (
    "opd_cos1",  # the OPD with cos(theta_1) (the README before 2024)
    "n_dot_v",  # the film's Fresnel at N.V, once per pixel (the sample viewer)
    "metal_only",  # the film on the metal alone
    "dielectric_only",  # the film on the dielectric alone
    "unweighted_base",  # the dielectric's film on f0, not specular * f0 (the sample viewer)
    "weights_mixed",  # base weight mix(1 - max(specular fr), 1 - max F_film, k)
)
"""The changes :func:`wrong_ref` makes, each a plausible misreading of the sources."""


def _gltf(model, p, g, wrong: frozenset = frozenset()):
    """glTF 2.0 metallic-roughness with the extensions the model's options turn on (a
    material read by :func:`material_values` may add anisotropy)."""
    if "anisotropy_strength" in p:
        args = (p["anisotropy_strength"], p["anisotropy_rotation"])
        dv = _dv_anisotropic(p["roughness"] ** 2, *args, g)
    else:
        dv = _dv(p["roughness"] ** 2, g)
    w = (1 - abs(dot(g.wo, g.h))) ** 5
    if model.specular:
        s, f0 = p["specular"], rgb(p["specular_f0"])
    else:
        s, f0 = mp.mpf(1), rgb(num("0.04"))
    base = rgb(p["base_color"])
    f_d = [s * x + (s - s * x) * w for x in f0]  # mix(f0 specular, specular, w)
    f_m = [b + (1 - b) * w for b in base]  # conductor_fresnel
    weight = 1 - max(f_d)
    if getattr(model, "iridescence", False):
        k = p["iridescence"]
        cos = g.co if "n_dot_v" in wrong else abs(dot(g.wo, g.h))

        def film(b):
            thick, ior = p["iridescence_thickness"], p["iridescence_ior"]
            fl = F0_FLOOR
            return iridescent_fresnel(cos, thick, ior, b, f0_floor=fl, opd_cos1="opd_cos1" in wrong)

        if "metal_only" not in wrong:
            on = f0 if "unweighted_base" in wrong else [s * x for x in f0]
            mixed = [x + k * (y - x) for x, y in zip(f_d, film(on), strict=True)]
            if "weights_mixed" in wrong:
                weight = (1 - k) * weight + k * (1 - max(film(on)))
            else:
                weight = 1 - max(mixed)
            f_d = mixed
        if "dielectric_only" not in wrong:
            f_m = [x + k * (y - x) for x, y in zip(f_m, film(base), strict=True)]
    out = []
    for b, fd, fm in zip(base, f_d, f_m, strict=True):
        dielectric = fd * dv + weight * b / mp.pi
        out.append((1 - p["metallic"]) * dielectric + p["metallic"] * fm * dv)
    if model.sheen:
        a = p["sheen_roughness"] ** 2
        sin_h = mp.sqrt(g.h[0] ** 2 + g.h[1] ** 2)
        d = (2 + 1 / a) * sin_h ** (1 / a) / (2 * mp.pi)
        lobe = d / (4 * (g.ci + g.co - g.ci * g.co))
        out = [x + lobe * c for x, c in zip(out, rgb(p["sheen_color"]), strict=True)]
    if model.clearcoat:
        fc = p["clearcoat"] * (num("0.04") + num("0.96") * (1 - g.co) ** 5)
        coat = _dv(p["clearcoat_roughness"] ** 2, g)
        out = [x * (1 - fc) + fc * coat for x in out]
    return out


gltf_ref = per_pair(_gltf)


def wrong_ref(change: str) -> Reference:
    """:func:`gltf_ref` with one of the changes in :data:`WRONG`."""
    if change not in WRONG:
        raise ValueError(f"unknown change {change!r}; one of {WRONG}")
    return per_pair(lambda model, p, g: _gltf(model, p, g, frozenset({change})))


EXTENSIONS = (
    "KHR_materials_specular",
    "KHR_materials_ior",
    "KHR_materials_anisotropy",
    "KHR_materials_clearcoat",
    "KHR_materials_sheen",
    "KHR_materials_iridescence",
)
"""The extensions :func:`material_values` reads."""


def material_values(mat: dict) -> tuple[SimpleNamespace, dict]:
    """A glTF material (JSON as a dict) -> ``(options, values)`` for :func:`gltf_ref`, by the
    spec's definitions and defaults alone: ``specular_f0 = min(((ior - 1)/(ior + 1))^2
    specularColorFactor, 1)``; without a thickness texture the film's thickness is
    ``iridescenceThicknessMaximum``."""
    pbr, ext = mat["pbrMetallicRoughness"], mat.get("extensions", {})
    unknown = set(ext) - set(EXTENSIONS)
    if unknown:
        raise ValueError(f"material_values reads {EXTENSIONS}, not {sorted(unknown)}")
    out = {
        "base_color": np.asarray(pbr.get("baseColorFactor", [1.0] * 4)[:3], float),
        "metallic": np.asarray(pbr.get("metallicFactor", 1.0), float),
        "roughness": np.asarray(pbr.get("roughnessFactor", 1.0), float),
    }
    spec = ext.get("KHR_materials_specular", {})
    ior = ext.get("KHR_materials_ior", {}).get("ior", 1.5)
    color = np.asarray(spec.get("specularColorFactor", [1.0, 1.0, 1.0]), float)
    out["specular"] = np.asarray(spec.get("specularFactor", 1.0), float)
    out["specular_f0"] = np.minimum(((ior - 1) / (ior + 1)) ** 2 * color, 1.0)
    if "KHR_materials_anisotropy" in ext:  # walter's anisotropic lobes; not the gltf model's
        an = ext["KHR_materials_anisotropy"]
        out["anisotropy_strength"] = np.asarray(an.get("anisotropyStrength", 0.0), float)
        out["anisotropy_rotation"] = np.asarray(an.get("anisotropyRotation", 0.0), float)
    if "KHR_materials_clearcoat" in ext:
        cc = ext["KHR_materials_clearcoat"]
        out["clearcoat"] = np.asarray(cc.get("clearcoatFactor", 0.0), float)
        out["clearcoat_roughness"] = np.asarray(cc.get("clearcoatRoughnessFactor", 0.0), float)
    if "KHR_materials_sheen" in ext:
        sh = ext["KHR_materials_sheen"]
        out["sheen_color"] = np.asarray(sh.get("sheenColorFactor", [0.0] * 3), float)
        out["sheen_roughness"] = np.asarray(sh.get("sheenRoughnessFactor", 0.0), float)
    if "KHR_materials_iridescence" in ext:
        ir = ext["KHR_materials_iridescence"]
        out["iridescence"] = np.asarray(ir.get("iridescenceFactor", 0.0), float)
        out["iridescence_ior"] = np.asarray(ir.get("iridescenceIor", 1.3), float)
        thickness = ir.get("iridescenceThicknessMaximum", 400.0)
        out["iridescence_thickness"] = np.asarray(thickness, float)
    options = SimpleNamespace(
        specular=True,
        clearcoat="clearcoat" in out,
        sheen="sheen_color" in out,
        iridescence="iridescence" in out,
    )
    return options, out


def document_brdf(mat: dict, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """The spec's BRDF (N, 3) of a glTF material, from its JSON alone (:func:`material_values`,
    :func:`gltf_ref` at mpmath's working precision, 53 bits by default)."""
    options, values = material_values(mat)
    return np.asarray(gltf_ref(options, values, wi, wo), dtype=float)


REFERENCES: dict[str, Reference] = {"gltf": gltf_ref}
