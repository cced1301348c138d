"""The glTF 2.0 metallic-roughness BRDF and its material extensions, in numpy.

From the glTF 2.0 specification, Appendix B ("BRDF Implementation"), and the extension
specifications ``KHR_materials_specular``, ``_ior``, ``_anisotropy``, ``_clearcoat``,
``_sheen``, ``_iridescence`` (Khronos). brdffit's convention: ``wi`` = L toward the light,
``wo`` = V toward the viewer, f in 1/sr without the cosine, (N, 3).

    alpha = roughness^2                                 (perceptual roughness squared once)
    D = GGX, V = height-correlated Smith G / (4 |N.L| |N.V|)          (Appendix B)
    w = (1 - |V.H|)^5
    F_d = f0_d + (f90_d - f0_d) w,  f0_d = min(((ior - 1)/(ior + 1))^2 specularColor, 1)
          * specular,  f90_d = specular                       (KHR_materials_specular, _ior)
    F_m = baseColor + (1 - baseColor) w
    dielectric = F_d D V + (1 - max(F_d)) baseColor / pi
    metal      = F_m D V
    material   = (1 - metallic) dielectric + metallic metal

* Anisotropy: ``alpha_t = mix(alpha, 1, strength^2)`` along the direction at
  ``anisotropyRotation`` from the tangent, ``alpha_b = alpha``; anisotropic GGX D and V.
* Sheen: ``sheenColor D_charlie V_sheen`` added on top, ``D_charlie = (2 + 1/a)
  sin(theta_h)^(1/a) / (2 pi)``, ``a = sheenRoughness^2``, with the Ashikhmin visibility
  ``1 / (4 (N.L + N.V - N.L N.V))`` the extension allows; the base is NOT scaled by the
  albedo-scaling term (it needs Conty and Kulla's tabulated E), as brdffit's Filament model.
* Iridescence: ``F_d = mix(F_d, F_film(f0_d), iridescence)`` (so the diffuse weight is
  ``1 - max`` of the mixed Fresnel) and ``F_m = mix(F_m, F_film(baseColor), iridescence)``,
  ``F_film`` the thin film's reflectance at ``|V.H|`` on a base of that normal
  reflectance (:func:`brdffit.models._films.thin_film_fresnel`, evaluated through JAX in
  float64), thickness ``iridescenceThicknessMaximum`` (no texture), as
  :mod:`brdffit.models.gltf_pbr` documents (the extension's text; the sample viewer
  evaluates ``F_film`` at ``N.V`` instead).
* Clear coat: ``mix(material, clearcoat_brdf, clearcoat F_c)``, ``F_c = 0.04 + 0.96
  (1 - |V.N|)^5`` (the extension's implementation section; not reciprocal), coat GGX
  with ``alpha = clearcoatRoughness^2``.

Here ``specular_f0`` stands for ``min(R0(ior) specularColor, 1)``: :mod:`brdffit.export.gltf`
writes it back as ``ior`` and ``specularColorFactor``.
"""

from __future__ import annotations

from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from brdffit.models import _films

INV_PI = 1.0 / np.pi
_THIN_FILM = jax.jit(_films.thin_film_fresnel)


def _dot2(v: np.ndarray, u: np.ndarray) -> np.ndarray:
    return v[:, 0] * u[0] + v[:, 1] * u[1]


def specular_dv(
    wi: np.ndarray, wo: np.ndarray, alpha_t: float, alpha_b: float, rotation: float = 0.0
) -> np.ndarray:
    """``D V`` of anisotropic GGX with height-correlated Smith (1/sr), (N,).

    ``alpha_t`` along the direction at ``rotation`` radians from the tangent x (toward
    y), ``alpha_b`` across it; equal alphas give Appendix B's isotropic ``specular_brdf``.
    """
    t = np.array([np.cos(rotation), np.sin(rotation)])
    b = np.array([-t[1], t[0]])
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    q = (_dot2(h, t) / alpha_t) ** 2 + (_dot2(h, b) / alpha_b) ** 2 + h[:, 2] ** 2
    d = INV_PI / (alpha_t * alpha_b * q**2)
    lam_v = wi[:, 2] * np.sqrt(
        (alpha_t * _dot2(wo, t)) ** 2 + (alpha_b * _dot2(wo, b)) ** 2 + wo[:, 2] ** 2
    )
    lam_l = wo[:, 2] * np.sqrt(
        (alpha_t * _dot2(wi, t)) ** 2 + (alpha_b * _dot2(wi, b)) ** 2 + wi[:, 2] ** 2
    )
    return d * 0.5 / (lam_v + lam_l)


def charlie_sheen(wi: np.ndarray, wo: np.ndarray, roughness: float) -> np.ndarray:
    """``D_charlie V_ashikhmin`` (1/sr), (N,), ``a = roughness^2``."""
    a = roughness**2
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    sin2 = np.maximum(1.0 - h[:, 2] ** 2, 0.0)
    d = (2.0 + 1.0 / a) * sin2 ** (0.5 / a) / (2.0 * np.pi)
    nl, nv = wi[:, 2], wo[:, 2]
    return d / (4.0 * (nl + nv - nl * nv))


def thin_film(cos: np.ndarray, thickness: float, ior: float, f0: np.ndarray) -> np.ndarray:
    """The film's reflectance (N, 3) at incidence cosines ``cos`` (N,) on a base of normal
    reflectance ``f0`` (3,), ``thickness`` in nm, index ``ior``
    (:func:`brdffit.models._films.thin_film_fresnel`, compiled once per shape)."""
    args = (cos, float(thickness), float(ior), np.asarray(f0, float))
    return np.asarray(_THIN_FILM(*(jnp.asarray(a, jnp.float64) for a in args)))


def material(p: Mapping[str, object], wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """The glTF material BRDF (module docstring), (N, 3).

    ``p``: ``base_color`` (3,), ``metallic``, ``roughness``, ``specular``,
    ``specular_f0`` (3,); optional ``anisotropy_strength`` with ``anisotropy_rotation``,
    ``clearcoat`` with ``clearcoat_roughness``, ``sheen_color`` (3,) with
    ``sheen_roughness``, ``iridescence`` with ``iridescence_ior`` and
    ``iridescence_thickness`` (nm).
    """
    base = np.asarray(p["base_color"], float)
    m, alpha = float(p["metallic"]), float(p["roughness"]) ** 2
    s = float(p.get("anisotropy_strength", 0.0))
    alpha_t = alpha + (1.0 - alpha) * s**2
    dv = specular_dv(wi, wo, alpha_t, alpha, float(p.get("anisotropy_rotation", 0.0)))
    h = wi + wo
    v_dot_h = np.abs(np.sum(wo * h, axis=-1) / np.linalg.norm(h, axis=-1))
    w = ((1.0 - v_dot_h) ** 5)[:, None]
    spec = float(p["specular"])
    f0 = np.asarray(p["specular_f0"], float) * spec
    f_d = f0 + (spec - f0) * w
    f_m = base + (1.0 - base) * w
    if "iridescence" in p:
        k, film = float(p["iridescence"]), (p["iridescence_thickness"], p["iridescence_ior"])
        f_d = f_d + k * (thin_film(v_dot_h, *film, f0) - f_d)
        f_m = f_m + k * (thin_film(v_dot_h, *film, base) - f_m)
    dielectric = f_d * dv[:, None] + (1.0 - np.max(f_d, axis=1, keepdims=True)) * base * INV_PI
    metal = f_m * dv[:, None]
    out = (1.0 - m) * dielectric + m * metal
    if "sheen_color" in p:
        sheen = charlie_sheen(wi, wo, float(p["sheen_roughness"]))
        out = out + np.asarray(p["sheen_color"], float) * sheen[:, None]
    if "clearcoat" in p:
        a_c = float(p["clearcoat_roughness"]) ** 2
        f_c = float(p["clearcoat"]) * (0.04 + 0.96 * (1.0 - wo[:, 2]) ** 5)
        coat = specular_dv(wi, wo, a_c, a_c)
        out = out * (1.0 - f_c)[:, None] + (f_c * coat)[:, None]
    return out
