"""Independent reference for OpenPBR: MaterialX's ``open_pbr_surface``, read from its library.

Nothing here calls ``brdffit/``. The node graph ``NG_open_pbr_surface_surfaceshader`` (the
implementation of ``ND_open_pbr_surface_surfaceshader``, ``libraries/bxdf/open_pbr_surface.mtlx``
in the ``materialx`` wheel) is loaded with the MaterialX Python API and interpreted node by node
for constant inputs, so the wiring (which closure lies over which, every weight, the coat
darkening, the metal/dielectric mix, the fuzz layer) comes from the library, not from a reading of
the spec. The nodes are evaluated generically:

* data nodes (float, color3, vector2/3, boolean) by category from their inputs (``add``,
  ``subtract``, ``multiply``, ``divide``, ``power``, ``min``, ``max``, ``mix``, ``clamp``,
  ``sqrt``, ``sign``, ``ln``, ``invert``, ``ifgreater``, ``extract``, ``combine2/3``, ``convert``
  from boolean); a node whose GLSL implementation is itself a node graph (``open_pbr_anisotropy``,
  ``convert`` float/color3 -> color3/vector3, ``separate3``) is interpreted recursively; an input
  not set on a node takes its nodedef default;
* closure nodes by numpy (float64) transcriptions of MaterialX 1.39.5's genglsl sources, reflection
  context (``CLOSURE_TYPE_REFLECTION``, one light): ``mx_oren_nayar_diffuse_bsdf.glsl``,
  ``mx_dielectric_bsdf.glsl``, ``mx_generalized_schlick_bsdf.glsl``, ``mx_sheen_bsdf.glsl``,
  ``mx_translucent_bsdf.glsl``, ``mx_subsurface_bsdf.glsl``, ``mx_layer_bsdf.glsl``,
  ``mx_layer_vdf.glsl``, ``mx_anisotropic_vdf.glsl``, ``mx_mix_bsdf.glsl``, ``mx_add_bsdf.glsl``,
  ``mx_multiply_bsdf_float.glsl``, ``mx_multiply_bsdf_color3.glsl``, and the helpers of
  ``lib/mx_microfacet.glsl``, ``lib/mx_microfacet_specular.glsl`` (GGX D, height-correlated
  Smith G2, the analytic GGX directional albedo fit, Turquin energy compensation, dielectric /
  conductor / Hoffman-Schlick F82 Fresnel, Belcour-Barla Airy thin film),
  ``lib/mx_microfacet_diffuse.glsl`` (EON: energy-compensated Fujii Oren-Nayar; the qualitative
  Oren-Nayar; the Burley diffusion integral) and ``lib/mx_microfacet_sheen.glsl`` (Zeltner LTC
  sheen).

A BSDF value is MaterialX's ``BSDF {response, throughput}``, initialised to ``(0, 1)`` as the
generated code does. ``response`` is outgoing radiance per unit light intensity, so it carries
the cosine: the BRDF returned is ``opacity * response / wi.z`` (the ``surface`` node multiplies by
``geometry_opacity``). Settings, the defaults of the GLSL generator of MaterialX 1.39.5
(checked in its generated code): ``DIRECTIONAL_ALBEDO_METHOD 0`` (analytic fits),
``AIRY_FRESNEL_ITERATIONS 2``, ``M_FLOAT_EPS 1e-8``, the sheen ``mode`` of the graph
(``zeltner``), occlusion 1, and the generator's ``premultipliedBsdfAdd`` graph rewrite (on by
default): a BSDF ``mix(fg, bg, w)`` whose ``w`` is connected becomes ``add(fg', bg')`` where a side
whose node has a ``weight`` input gets that weight multiplied by ``w`` (``1 - w`` for ``bg``) and
any other side is wrapped in ``multiply(side, w)`` (which clamps ``w`` to [0, 1]); a mix with a
constant weight stays ``mx_mix_bsdf``. For weights in [0, 1] the response equals the plain
``mx_mix_bsdf`` one (``premultiplied_add=False`` in :func:`evaluate`); outside it, it does not.

Where the GLSL depends on the rasteriser: ``subsurface_bsdf`` reads the curvature
``length(fwidth(N)) / length(fwidth(P))``; here the surface is a flat patch (curvature 0, so the
GLSL's radius ``1 / max(0, 0.01) = 100``). ``translucent_bsdf`` has a reflection response
``color * max(dot(-N, L), 0) / pi``, zero for a light above the surface. The transmission
closures (``dielectric_bsdf`` with ``scatter_mode T``, ``anisotropic_vdf``) contribute nothing in
the reflection context, so ``transmission_weight > 0`` gives the reflection the graph gives: the
opaque base scaled by ``1 - transmission_weight``. EDFs (emission) are not part of a BRDF and are
skipped.

Checked against MaterialX itself in ``tests/models/test_openpbr_glsl.py``: the fragment shader
MaterialX's GLSL generator emits for ``open_pbr_surface``, fed one light direction and one view
direction per pixel and run on an OpenGL context (:mod:`tests.materialx_glsl`), for each feature
alone and all together. When this file was written, on Mesa llvmpipe, 18 chosen settings and 25
random ones (~4000 direction pairs each) agreed to 1.2e-5 relative once llvmpipe's ``acos`` (off
by 1.6e-4) was replaced by an ``atan`` form, except where float32 cancels in the Airy terms as
``thin_film_ior -> 1`` (6e-4 at 1.00024). GLSL is float32 and this float64: compare at ~1e-5.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence

import MaterialX as mx
import mpmath as mp
import numpy as np

from tests.references import Pair, dot, num, per_pair, rgb

NODEDEF = "ND_open_pbr_surface_surfaceshader"
EPS = 1e-8  # M_FLOAT_EPS, libraries/stdlib/genglsl/lib/mx_math.glsl
AIRY_FRESNEL_ITERATIONS = 2  # GenOptions.hwAiryFresnelIterations default, as emitted
_GEOMPROP = {"Nworld": (0.0, 0.0, 1.0), "Tworld": (1.0, 0.0, 0.0)}  # the local frame


# ---------------------------------------------------------------------------------------------
# The library and the values of its ports


@functools.cache
def library() -> mx.Document:
    """MaterialX's standard data libraries, loaded once."""
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    return lib


def _parse(text: str, typ: str):
    """A MaterialX value string of type ``typ`` in float64 (``getValue`` rounds to float32)."""
    if typ == "float":
        return np.float64(text)
    if typ in ("color3", "vector3", "vector2", "color4", "vector4"):
        return np.array([float(x) for x in text.split(",")])
    if typ == "boolean":
        return text.strip() == "true"
    if typ == "integer":
        return int(text)
    if typ == "string":
        return text
    raise NotImplementedError(f"values of type {typ!r} ({text!r})")


def _default(port: mx.Input):
    """A nodedef input's default: its geomprop (frame vector) or its value; None for closures."""
    if port.hasDefaultGeomPropString():
        return np.array(_GEOMPROP[port.getDefaultGeomPropString()])
    return _parse(port.getValueString(), port.getType()) if port.hasValueString() else None


def default_inputs() -> dict:
    """The ``open_pbr_surface`` inputs with their nodedef defaults (colours as 3-tuples)."""
    out = {}
    for port in library().getNodeDef(NODEDEF).getActiveInputs():
        v = _default(port)
        if isinstance(v, np.ndarray):
            v = tuple(float(x) for x in v)
        elif isinstance(v, np.floating):
            v = float(v)
        out[port.getName()] = v
    return out


def _coerce(name: str, value, typ: str):
    if typ == "float":
        return np.float64(value)
    if typ in ("color3", "vector3"):
        return np.broadcast_to(np.asarray(value, dtype=np.float64), (3,)).copy()
    if typ == "boolean":
        return bool(value)
    raise NotImplementedError(f"input {name!r} of type {typ!r}")


# ---------------------------------------------------------------------------------------------
# GLSL helpers (lib/mx_microfacet*.glsl); per-sample arrays have shape (n,) or (n, 3)


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def _normalize(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _mix(x, y, a):  # GLSL mix
    return x * (1.0 - a) + y * a


def _forward_facing(N, V):  # mx_forward_facing_normal
    return np.where((_dot(N, V) < 0.0)[..., None], -N, N * np.ones_like(V))


def _ggx_ndf(Ht, alpha):  # mx_ggx_NDF, H in the (X, Y, N) frame
    hx, hy = Ht[..., 0] / alpha[0], Ht[..., 1] / alpha[1]
    denom = hx * hx + hy * hy + Ht[..., 2] ** 2
    return 1.0 / (np.pi * alpha[0] * alpha[1] * denom**2)


def _ggx_smith_g2(NdotL, NdotV, alpha):  # mx_ggx_smith_G2 (height-correlated)
    a2 = alpha * alpha
    lam_l = np.sqrt(a2 + (1.0 - a2) * NdotL**2)
    lam_v = np.sqrt(a2 + (1.0 - a2) * NdotV**2)
    return 2.0 * NdotL * NdotV / (lam_l * NdotV + lam_v * NdotL)


_GGX_FIT = np.array(  # mx_ggx_dir_albedo_analytic: rows are the terms, columns r.xyzw
    [
        [0.1003, 0.9345, 1.0, 1.0],  # 1
        [-0.6303, -2.323, -1.765, 0.2281],  # x
        [9.748, 2.229, 8.263, 15.94],  # y
        [-2.038, -3.748, 11.53, -55.83],  # x y
        [29.34, 1.424, 28.96, 13.08],  # x^2
        [-8.245, -0.7684, -7.507, 41.26],  # y^2
        [-26.44, 1.436, -36.11, 54.9],  # x^2 y
        [19.99, 0.2913, 15.86, 300.2],  # x y^2
        [-5.448, 0.6286, 33.37, -285.1],  # x^2 y^2
    ]
)


def _ggx_dir_albedo(NdotV, alpha, F0, F90):
    """mx_ggx_dir_albedo, DIRECTIONAL_ALBEDO_METHOD 0: (n, 3) ``F0 A + F90 B``."""
    x, y = NdotV, alpha
    terms = np.stack(np.broadcast_arrays(1.0, x, y, x * y, x * x, y * y, x * x * y, x * y * y,
                                         x * x * y * y), axis=-1)  # fmt: skip
    r = terms @ _GGX_FIT
    a = np.clip(r[..., 0] / r[..., 2], 0.0, 1.0)[..., None]
    b = np.clip(r[..., 1] / r[..., 3], 0.0, 1.0)[..., None]
    return np.asarray(F0) * a + np.asarray(F90) * b


def _ggx_energy_compensation(NdotV, alpha, Fss):  # mx_ggx_energy_compensation
    Ess = _ggx_dir_albedo(NdotV, alpha, 1.0, 1.0)[..., :1]
    return 1.0 + Fss * (1.0 - Ess) / Ess


def _ior_to_f0(ior):
    return ((ior - 1.0) / (ior + 1.0)) ** 2


def _f0_to_ior(F0):
    s = np.sqrt(np.clip(F0, 0.01, 0.99))
    return (1.0 + s) / (1.0 - s)


def _fresnel_dielectric(c, ior):  # mx_fresnel_dielectric (1.0 on total internal reflection)
    g2 = ior * ior + c * c - 1.0
    g = np.sqrt(np.maximum(g2, 0.0))
    f = 0.5 * ((g - c) / (g + c)) ** 2 * (1.0 + (((g + c) * c - 1.0) / ((g - c) * c + 1.0)) ** 2)
    return np.where(g2 < 0.0, 1.0, f)


def _fresnel_dielectric_polarized(c, ior):  # mx_fresnel_dielectric_polarized -> (Rp, Rs)
    cos2 = np.clip(c, 0.0, 1.0) ** 2
    sin2 = 1.0 - cos2
    t0 = np.maximum(ior * ior - sin2, 0.0)
    t1 = t0 + cos2
    t2 = 2.0 * np.sqrt(t0) * c
    rs = (t1 - t2) / (t1 + t2)
    t3 = cos2 * t0 + sin2 * sin2
    t4 = t2 * sin2
    return rs * (t3 - t4) / (t3 + t4), rs


def _fresnel_conductor_polarized(c, n, k):  # mx_fresnel_conductor_polarized -> (Rp, Rs)
    cos2 = (np.clip(c, 0.0, 1.0) ** 2)[..., None]
    sin2 = 1.0 - cos2
    c = np.asarray(c)[..., None]
    n2, k2 = n * n, k * k
    t0 = n2 - k2 - sin2
    a2pb2 = np.sqrt(t0 * t0 + 4.0 * n2 * k2)
    t1 = a2pb2 + cos2
    a = np.sqrt(np.maximum(0.5 * (a2pb2 + t0), 0.0))
    t2 = 2.0 * a * c
    rs = (t1 - t2) / (t1 + t2)
    t3 = cos2 * a2pb2 + sin2 * sin2
    t4 = t2 * sin2
    return rs * (t3 - t4) / (t3 + t4), rs


def _fresnel_conductor_phase_polarized(c, eta1, eta2, kappa2):  # -> (phiP, phiS)
    c = np.asarray(c)[..., None]
    k2 = kappa2 / eta2
    sin2 = 1.0 - c * c
    A = eta2 * eta2 * (1.0 - k2 * k2) - eta1 * eta1 * sin2
    B = np.sqrt(A * A + (2.0 * eta2 * eta2 * k2) ** 2)
    U = np.sqrt((A + B) / 2.0)
    V = np.fmax(0.0, np.sqrt((B - A) / 2.0))
    phi_s = np.arctan2(2.0 * eta1 * V * c, U * U + V * V - (eta1 * c) ** 2)
    phi_p = np.arctan2(
        2.0 * eta1 * eta2 * eta2 * c * (2.0 * k2 * U - (1.0 - k2 * k2) * V),
        (eta2 * eta2 * (1.0 + k2 * k2) * c) ** 2 - eta1 * eta1 * (U * U + V * V),
    )
    return phi_p, phi_s


def _fresnel_hoffman_schlick(c, fd):  # mx_fresnel_hoffman_schlick (F82 tint)
    cmax = 1.0 / 7.0
    factor = 1.0 / (cmax * (1.0 - cmax) ** 6)
    x = np.clip(c, 0.0, 1.0)[..., None]
    a = _mix(fd["F0"], fd["F90"], (1.0 - cmax) ** fd["exponent"]) * (1.0 - fd["F82"]) * factor
    return _mix(fd["F0"], fd["F90"], (1.0 - x) ** fd["exponent"]) - a * x * (1.0 - x) ** 6


_XYZ_TO_RGB = np.array(  # GLSL mat3 is column-major: these are the columns
    [2.3706743, -0.5138850, 0.0052982, -0.9000405, 1.4253036, -0.0146949,
     -0.4706338, 0.0885814, 1.0093968]
).reshape(3, 3).T  # fmt: skip


def _eval_sensitivity(opd, shift):  # mx_eval_sensitivity
    phase = (2.0 * np.pi * opd)[..., None]
    val = np.array([5.4856e-13, 4.4201e-13, 5.2481e-13])
    pos = np.array([1.6810e06, 1.7953e06, 2.2084e06])
    var = np.array([4.3278e09, 9.3046e09, 6.6121e09])
    xyz = val * np.sqrt(2.0 * np.pi * var) * np.cos(pos * phase + shift) * np.exp(-var * phase**2)
    extra = (9.7470e-14 * np.sqrt(2.0 * np.pi * 4.5282e09) * np.cos(2.2399e06 * phase[..., 0]
             + shift[..., 0]) * np.exp(-4.5282e09 * phase[..., 0] ** 2))  # fmt: skip
    xyz[..., 0] += extra
    return xyz / 1.0685e-7


def _fresnel_airy(c, fd):  # mx_fresnel_airy (Belcour & Barla 2017), eta1 = 1 outside
    eta1 = 1.0
    eta2 = max(fd["tf_ior"], eta1)
    schlick = fd["model"] == "schlick"
    eta3 = _f0_to_ior(fd["F0"]) if schlick else fd["ior"]
    kappa3 = np.zeros(3) if schlick else fd["extinction"]
    cos_t = np.sqrt(1.0 - (1.0 - c * c) * (eta1 / eta2) ** 2)
    r12p, r12s = _fresnel_dielectric_polarized(c, eta2 / eta1)
    r12p, r12s = np.where(cos_t <= 0.0, 1.0, r12p), np.where(cos_t <= 0.0, 1.0, r12s)
    t121p, t121s = 1.0 - r12p, 1.0 - r12s
    if schlick:
        r23p = r23s = 0.5 * _fresnel_hoffman_schlick(cos_t, fd)
        phi23p = phi23s = np.where(eta3 < eta2, np.pi, 0.0) * np.ones_like(r23p)
    else:
        r23p, r23s = _fresnel_conductor_polarized(cos_t, eta3 / eta2, kappa3 / eta2)
        phi23p, phi23s = _fresnel_conductor_phase_polarized(cos_t, eta2, eta3, kappa3)
    cos_b = np.cos(np.arctan(eta2 / eta1))
    phi21p = np.where(c < cos_b, 0.0, np.pi)[..., None]
    phi21s = np.pi
    r12p, r12s, t121p, t121s = (v[..., None] for v in (r12p, r12s, t121p, t121s))
    r123p = np.fmax(np.sqrt(r12p * r23p), 0.0)  # GLSL max(NaN, 0) = 0 on GPUs
    r123s = np.fmax(np.sqrt(r12s * r23s), 0.0)
    opd = 2.0 * eta2 * cos_t * fd["tf_thickness"] * 1.0e-9
    total = np.zeros_like(r23p)
    for r12, t121, r23, r123, phi in (
        (r12p, t121p, r23p, r123p, phi23p + phi21p),
        (r12s, t121s, r23s, r123s, phi23s + phi21s),
    ):
        rr = t121**2 * r23 / (1.0 - r12 * r23)
        total = total + r12 + rr
        cm = rr - t121
        for m in range(1, AIRY_FRESNEL_ITERATIONS + 1):
            cm = cm * r123
            total = total + cm * 2.0 * _eval_sensitivity(m * opd, m * phi)
    return np.clip(0.5 * total @ _XYZ_TO_RGB.T, 0.0, 1.0)


def _compute_fresnel(c, fd):  # mx_compute_fresnel -> (n, 3)
    if fd["tf_thickness"] > 0.0:
        return _fresnel_airy(c, fd)
    if fd["model"] == "dielectric":
        return np.repeat(_fresnel_dielectric(c, fd["ior"][0])[..., None], 3, axis=-1)
    return _fresnel_hoffman_schlick(c, fd)


# ---------------------------------------------------------------------------------------------
# Closures, reflection context. g: {"L": (n, 3), "V": (n, 3)}; a: the node's inputs.


def _empty(g):
    n = g["L"].shape[0]
    return np.zeros((n, 3)), np.ones((n, 3))


def _enum(nodedef, name, value):
    return [s.strip() for s in nodedef.getActiveInput(name).getAttribute("enum").split(",")].index(
        value
    )


def _microfacet(g, a, nodedef, fd):
    """The part shared by mx_dielectric_bsdf and mx_generalized_schlick_bsdf (reflection)."""
    L, V = g["L"], g["V"]
    N = np.asarray(a["normal"], dtype=np.float64)
    if a["retroreflective"]:
        V = -V + 2.0 * _dot(N, V)[..., None] * N  # reflect(-V, N)
    N = _forward_facing(N, V)
    NdotV = np.clip(_dot(N, V), EPS, 1.0)
    alpha = np.clip(a["roughness"], EPS, 1.0)
    avg = np.sqrt(alpha[0] * alpha[1])  # mx_average_alpha
    X = a["tangent"] - _dot(a["tangent"], N)[..., None] * N
    X = _normalize(X)
    Y = np.cross(N, X)
    H = _normalize(L + V)
    NdotL = np.clip(_dot(N, L), EPS, 1.0)
    VdotH = np.clip(_dot(V, H), EPS, 1.0)
    Ht = np.stack([_dot(H, X), _dot(H, Y), _dot(H, N)], axis=-1)
    F = _compute_fresnel(VdotH, fd)
    D = _ggx_ndf(Ht, alpha)[..., None]
    G = _ggx_smith_g2(NdotL, NdotV, avg)[..., None]
    comp = _ggx_energy_compensation(NdotV, avg, F)
    return NdotV, avg, D * F * G * comp / (4.0 * NdotV[..., None]), comp


def _dielectric_bsdf(g, a, nodedef):  # mx_dielectric_bsdf.glsl
    resp, tp = _empty(g)
    if a["weight"] < EPS or _enum(nodedef, "scatter_mode", a["scatter_mode"]) == 1:
        return resp, tp
    ior = np.float64(a["ior"])
    fd = {"model": "dielectric", "ior": np.full(3, ior), "extinction": np.zeros(3),
          "tf_thickness": a["thinfilm_thickness"], "tf_ior": a["thinfilm_ior"]}  # fmt: skip
    NdotV, avg, ss, comp = _microfacet(g, a, nodedef, fd)
    dir_albedo = _ggx_dir_albedo(NdotV, avg, _ior_to_f0(ior), 1.0)[..., :1] * comp
    tint = np.maximum(a["tint"], 0.0)
    return ss * tint * a["weight"], 1.0 - dir_albedo * a["weight"]


def _generalized_schlick_bsdf(g, a, nodedef):  # mx_generalized_schlick_bsdf.glsl
    resp, tp = _empty(g)
    if a["weight"] < EPS or _enum(nodedef, "scatter_mode", a["scatter_mode"]) == 1:
        return resp, tp
    c0, c82, c90 = (np.maximum(a[k], 0.0) for k in ("color0", "color82", "color90"))
    fd = {"model": "schlick", "F0": c0, "F82": c82, "F90": c90, "exponent": a["exponent"],
          "tf_thickness": a["thinfilm_thickness"], "tf_ior": a["thinfilm_ior"]}  # fmt: skip
    NdotV, avg, ss, comp = _microfacet(g, a, nodedef, fd)
    dir_albedo = _ggx_dir_albedo(NdotV, avg, c0, c90) * comp
    avg_albedo = np.mean(dir_albedo, axis=-1, keepdims=True)
    return ss * a["weight"], np.broadcast_to(1.0 - avg_albedo * a["weight"], tp.shape)


_FUJII_1 = 0.5 - 2.0 / (3.0 * np.pi)
_FUJII_2 = 2.0 / 3.0 - 28.0 / (15.0 * np.pi)


def _fujii_dir_albedo(c, r):  # mx_oren_nayar_fujii_diffuse_dir_albedo
    A = 1.0 / (1.0 + _FUJII_1 * r)
    B = r * A
    si = np.sqrt(np.maximum(0.0, 1.0 - c * c))
    G = (
        si * (np.arccos(np.clip(c, -1.0, 1.0)) - si * c)
        + 2.0 * ((si / c) * (1.0 - si**3) - si) / 3.0
    )
    return A + B * G / np.pi


def _oren_nayar_diffuse_bsdf(g, a, nodedef):  # mx_oren_nayar_diffuse_bsdf.glsl
    resp, _ = _empty(g)
    tp = np.zeros_like(resp)  # set before the weight test
    if a["weight"] < EPS:
        return resp, tp
    L, V = g["L"], g["V"]
    N = _forward_facing(np.asarray(a["normal"], dtype=np.float64), V)
    NdotV = np.clip(_dot(N, V), EPS, 1.0)
    NdotL = np.clip(_dot(N, L), EPS, 1.0)
    LdotV = np.clip(_dot(L, V), EPS, 1.0)
    r, color = a["roughness"], np.asarray(a["color"])
    s = LdotV - NdotL * NdotV
    if a["energy_compensation"]:  # mx_oren_nayar_compensated_diffuse (EON)
        stinv = np.where(s > 0.0, s / np.maximum(NdotL, NdotV), s)
        A = 1.0 / (1.0 + _FUJII_1 * r)
        single = color * (A * (1.0 + r * stinv))[..., None]
        ev, el = _fujii_dir_albedo(NdotV, r), _fujii_dir_albedo(NdotL, r)
        avg = A * (1.0 + _FUJII_2 * r)
        ms_color = color**2 * avg / (1.0 - color * max(0.0, 1.0 - avg))
        multi = ms_color * (np.maximum(EPS, 1.0 - ev) * np.maximum(EPS, 1.0 - el))[..., None]
        diffuse = single + multi / max(EPS, 1.0 - avg)
    else:  # mx_oren_nayar_diffuse (qualitative)
        stinv = np.where(s > 0.0, s / np.maximum(NdotL, NdotV), 0.0)
        sigma2 = r * r
        A = 1.0 - 0.5 * (sigma2 / (sigma2 + 0.33))
        B = 0.45 * sigma2 / (sigma2 + 0.09)
        diffuse = (A + B * stinv)[..., None] * color
    return diffuse * a["weight"] * (NdotL / np.pi)[..., None], tp


def _zeltner_dir_albedo(x, y):  # mx_zeltner_sheen_dir_albedo
    s = y * (0.0206607 + 1.58491 * y) / (0.0379424 + y * (1.32227 + y))
    m = y * (-0.193854 + y * (-1.14885 + y * (1.7932 - 0.95943 * y * y))) / (0.046391 + y)
    o = y * (0.000654023 + (-0.0207818 + 0.119681 * y) * y) / (1.26264 + y * (-1.92021 + y))
    return np.exp(-0.5 * ((x - m) / s) ** 2) / (s * np.sqrt(2.0 * np.pi)) + o


def _orthonormal_basis(N):  # mx_orthonormal_basis (Duff et al.), columns X, Y
    sign = np.where(N[..., 2] < 0.0, -1.0, 1.0)
    a = -1.0 / (sign + N[..., 2])
    b = N[..., 0] * N[..., 1] * a
    X = np.stack([1.0 + sign * N[..., 0] ** 2 * a, sign * b, -sign * N[..., 0]], axis=-1)
    Y = np.stack([b, sign + N[..., 1] ** 2 * a, -N[..., 1]], axis=-1)
    return X, Y


def _zeltner_sheen_brdf(L, V, N, NdotV, r):  # mx_zeltner_sheen_brdf (LTC, times cos)
    X = V - N * NdotV[..., None]
    len_sqr = _dot(X, X)
    X = X / np.sqrt(np.where(len_sqr > 0.0, len_sqr, 1.0))[..., None]
    Y = np.cross(N, X)
    Xb, Yb = _orthonormal_basis(N)
    X = np.where((len_sqr > 0.0)[..., None], X, Xb)
    Y = np.where((len_sqr > 0.0)[..., None], Y, Yb)
    w = np.stack([_dot(L, X), _dot(L, Y), _dot(L, N)], axis=-1)
    x, y = NdotV, r
    a_inv = (2.58126 * x + 0.813703 * y) * y / (1.0 + 0.310327 * x * x + 2.60994 * x * y)
    b_inv = (np.sqrt(1.0 - x) * (y - 1.0) * y**3
             / (0.0000254053 + 1.71228 * x - 1.71506 * x * y + 1.34174 * y * y))  # fmt: skip
    wo = np.stack([a_inv * w[..., 0] + b_inv * w[..., 2], a_inv * w[..., 1], w[..., 2]], axis=-1)
    len_sqr = _dot(wo, wo)
    return np.maximum(wo[..., 2], 0.0) / np.pi * (a_inv / len_sqr) ** 2


def _sheen_bsdf(g, a, nodedef):  # mx_sheen_bsdf.glsl
    resp, tp = _empty(g)
    if a["weight"] < EPS:
        return resp, tp
    L, V = g["L"], g["V"]
    N = _forward_facing(np.asarray(a["normal"], dtype=np.float64), V)
    NdotV = np.clip(_dot(N, V), EPS, 1.0)
    color = np.asarray(a["color"])
    if _enum(nodedef, "mode", a["mode"]) == 0:  # conty_kulla (Imageworks)
        H = _normalize(L + V)
        NdotL = np.clip(_dot(N, L), EPS, 1.0)
        NdotH = np.clip(_dot(N, H), EPS, 1.0)
        inv_r = 1.0 / max(a["roughness"], 0.005)
        D = (2.0 + inv_r) * (1.0 - NdotH**2) ** (inv_r * 0.5) / (2.0 * np.pi)
        fr = color * (D / (4.0 * (NdotL + NdotV - NdotL * NdotV)))[..., None]
        x, y = NdotV, a["roughness"]
        num = 13.67300 - 68.78018 * x + 799.08825 * y - 905.00061 * x * y + 60.28956 * x * x
        den = 1.0 + 61.57746 * x + 442.78211 * y + 2597.49308 * x * y + 121.81241 * x * x
        num, den = num + 1086.96473 * y * y, den + 3045.55075 * y * y
        dir_albedo = np.clip(num / den, 0.0, 1.0)
        resp = fr * (NdotL * a["weight"])[..., None]
    else:  # zeltner
        r = np.clip(a["roughness"], 0.01, 1.0)
        fr = color * _zeltner_sheen_brdf(L, V, N, NdotV, r)[..., None]
        dir_albedo = _zeltner_dir_albedo(NdotV, r)
        resp = dir_albedo[..., None] * fr * a["weight"]
    return resp, np.broadcast_to((1.0 - dir_albedo * a["weight"])[..., None], tp.shape)


def _translucent_bsdf(g, a, nodedef):  # mx_translucent_bsdf.glsl
    resp, _ = _empty(g)
    tp = np.zeros_like(resp)
    if a["weight"] < EPS:
        return resp, tp
    NdotL = np.clip(_dot(-np.asarray(a["normal"], dtype=np.float64), g["L"]), 0.0, 1.0)
    return np.asarray(a["color"]) * (a["weight"] * NdotL / np.pi)[..., None], tp


def _subsurface_bsdf(g, a, nodedef):  # mx_subsurface_bsdf.glsl, flat patch (curvature 0)
    resp, _ = _empty(g)
    tp = np.zeros_like(resp)
    if a["weight"] < EPS:
        return resp, tp
    L, V = g["L"], g["V"]
    N = _forward_facing(np.asarray(a["normal"], dtype=np.float64), V)
    radius = 1.0 / max(0.0, 0.01)  # curvature = length(fwidth(N)) / length(fwidth(P)) = 0
    theta = np.arccos(np.clip(_dot(N, L), -1.0, 1.0))  # mx_integrate_burley_diffusion
    shape = 1.0 / np.maximum(np.asarray(a["radius"]), 0.1)
    sum_d, sum_r = np.zeros_like(resp), np.zeros(3)
    count = 32
    for i in range(count):
        x = -np.pi + (i + 0.5) * (2.0 * np.pi / count)
        dist = radius * abs(2.0 * np.sin(x * 0.5))
        R = (np.exp(-shape * dist) + np.exp(-shape * dist / 3.0)) / max(dist, EPS)
        sum_d = sum_d + R * np.maximum(np.cos(theta + x), 0.0)[..., None]
        sum_r = sum_r + R
    sss = np.asarray(a["color"]) * sum_d / sum_r / np.pi
    NdotL = np.clip(_dot(N, L), EPS, 1.0)
    visible_occlusion = 1.0 - NdotL * (1.0 - 1.0)  # occlusion 1
    return sss * (visible_occlusion * a["weight"])[..., None], tp


def _anisotropic_vdf(g, a, nodedef):  # mx_anisotropic_vdf.glsl: nothing outside TRANSMISSION
    return _empty(g)


_CLOSURES = {
    "dielectric_bsdf": _dielectric_bsdf,
    "generalized_schlick_bsdf": _generalized_schlick_bsdf,
    "oren_nayar_diffuse_bsdf": _oren_nayar_diffuse_bsdf,
    "sheen_bsdf": _sheen_bsdf,
    "translucent_bsdf": _translucent_bsdf,
    "subsurface_bsdf": _subsurface_bsdf,
    "anisotropic_vdf": _anisotropic_vdf,
}


def _multiply_bsdf(bsdf, factor):  # mx_multiply_bsdf_float / _color3: clamped tint
    return bsdf[0] * np.clip(factor, 0.0, 1.0), bsdf[1]


def _add_bsdf(x, y):  # mx_add_bsdf.glsl
    return x[0] + y[0], np.maximum(x[1] + y[1] - 1.0, 0.0)


# ---------------------------------------------------------------------------------------------
# Data nodes, by category (their GLSL is an inline expression of the inputs)

_OPS = {
    "add": lambda a: a["in1"] + a["in2"],
    "subtract": lambda a: a["in1"] - a["in2"],
    "multiply": lambda a: a["in1"] * a["in2"],
    "divide": lambda a: a["in1"] / a["in2"],
    "power": lambda a: np.power(a["in1"], a["in2"]),
    "min": lambda a: np.minimum(a["in1"], a["in2"]),
    "max": lambda a: np.maximum(a["in1"], a["in2"]),
    "mix": lambda a: _mix(a["bg"], a["fg"], a["mix"]),
    "clamp": lambda a: np.minimum(np.maximum(a["in"], a["low"]), a["high"]),
    "sqrt": lambda a: np.sqrt(a["in"]),
    "sign": lambda a: np.sign(a["in"]),
    "ln": lambda a: np.log(a["in"]),
    "invert": lambda a: a["amount"] - a["in"],
    "ifgreater": lambda a: np.where(a["value1"] > a["value2"], a["in1"], a["in2"]),
    "extract": lambda a: np.float64(a["in"][a["index"]]),
    "combine2": lambda a: np.array([a["in1"], a["in2"]], dtype=np.float64),
    "combine3": lambda a: np.array([a["in1"], a["in2"], a["in3"]], dtype=np.float64),
}


# ---------------------------------------------------------------------------------------------
# The interpreter


class _Scope:
    """One node graph being interpreted: its interface values and a memo of its nodes."""

    def __init__(self, graph, interface, geometry, premultiplied_add):
        self.graph, self.interface, self.g = graph, interface, geometry
        self.premultiplied_add = premultiplied_add
        self.memo = {}

    def port(self, node, port):
        """The value reaching input ``port`` (a nodedef input) of ``node``."""
        inp = node.getInput(port.getName())
        if inp is not None:
            if inp.getNodeName():
                return self.output(inp.getNodeName(), inp.getOutputString() or None)
            if inp.getInterfaceName():
                return self.interface[inp.getInterfaceName()]
            if inp.hasValueString():
                return _parse(inp.getValueString(), port.getType())
        return _default(port)

    def output(self, name, out=None, weight_factor=None):
        key = (name, out, None if weight_factor is None else float(weight_factor))
        if key not in self.memo:
            self.memo[key] = self._evaluate(name, out, weight_factor)
        return self.memo[key]

    def _connected(self, node, name):
        inp = node.getInput(name)
        return inp is not None and bool(inp.getNodeName() or inp.getInterfaceName())

    def _fold(self, node, side, factor):
        """PremultipliedBsdfAddRefactor's foldWeightIntoBsdf for one side of a BSDF mix."""
        up = node.getInput(side).getNodeName()
        if self.graph.getNode(up).getNodeDef().getActiveInput("weight") is not None:
            return self.output(up, None, factor)
        return _multiply_bsdf(self.output(up), factor)

    def _evaluate(self, name, out, weight_factor):
        node = self.graph.getNode(name)
        if node is None:
            raise NotImplementedError(f"node {name!r} not found in {self.graph.getName()}")
        nodedef = node.getNodeDef()
        if nodedef is None:
            raise NotImplementedError(f"node {name!r} ({node.getCategory()}): no nodedef")
        typ, cat = nodedef.getType(), node.getCategory()
        if typ == "EDF":
            return None  # emission is not part of a BRDF
        if typ in ("BSDF", "VDF", "surfaceshader"):
            return self._closure(node, nodedef, cat, weight_factor)
        args = {p.getName(): self.port(node, p) for p in nodedef.getActiveInputs()}
        impl = nodedef.getImplementation("genglsl")
        if isinstance(impl, mx.NodeGraph):  # e.g. open_pbr_anisotropy, convert, separate3
            scope = _Scope(impl, args, self.g, self.premultiplied_add)
            outputs = impl.getOutputs()
            port = impl.getOutput(out) if out else outputs[0]
            if port.getNodeName():
                return scope.output(port.getNodeName(), port.getOutputString() or None)
            return scope.interface[port.getInterfaceName()]
        if cat == "convert":
            value = args["in"]
            if isinstance(value, bool | np.bool_):
                return np.float64(value)
            raise NotImplementedError(f"node {name!r}: convert {nodedef.getName()}")
        if cat not in _OPS:
            raise NotImplementedError(f"node {name!r}: category {cat!r} ({nodedef.getName()})")
        return _OPS[cat](args)

    def _closure(self, node, nodedef, cat, weight_factor):
        ports = {p.getName(): p for p in nodedef.getActiveInputs()}
        if cat == "mix":
            if self.premultiplied_add and self._connected(node, "mix"):
                w = self.port(node, ports["mix"])
                return _add_bsdf(self._fold(node, "fg", w), self._fold(node, "bg", 1.0 - w))
            fg, bg, w = (self.port(node, ports[k]) for k in ("fg", "bg", "mix"))
            return _mix(bg[0], fg[0], w), _mix(bg[1], fg[1], w)  # mx_mix_bsdf.glsl
        args = {k: self.port(node, p) for k, p in ports.items()}
        if cat == "surface":
            return args["bsdf"][0] * args["opacity"]
        if cat == "layer":
            top, base = args["top"], args["base"]
            if nodedef.getName() == "ND_layer_vdf":  # mx_layer_vdf.glsl
                return top[0] * base[1], top[1] * base[1]
            return top[0] + base[0] * top[1], top[1] * base[1]  # mx_layer_bsdf.glsl
        if cat == "multiply":
            return _multiply_bsdf(args["in1"], args["in2"])
        if cat == "add":
            return _add_bsdf(args["in1"], args["in2"])
        if cat not in _CLOSURES:
            raise NotImplementedError(f"node {node.getName()!r}: closure {cat!r}")
        if weight_factor is not None:
            args["weight"] = args["weight"] * weight_factor
        return _CLOSURES[cat](self.g, args, nodedef)


def _interface(inputs: Mapping[str, float | Sequence[float]], nodedef) -> dict:
    ports = {p.getName(): p for p in nodedef.getActiveInputs()}
    unknown = sorted(set(inputs) - set(ports))
    if unknown:
        raise KeyError(f"not inputs of {NODEDEF}: {unknown}; known: {sorted(ports)}")
    values = {k: _default(p) for k, p in ports.items()}
    for k, v in inputs.items():
        values[k] = _coerce(k, v, ports[k].getType())
    return values


def evaluate(
    inputs: Mapping[str, float | Sequence[float]],
    wi: np.ndarray,
    wo: np.ndarray,
    *,
    document: mx.Document | None = None,
    premultiplied_add: bool = True,
) -> np.ndarray:
    """:func:`open_pbr_brdf` with the interpreter's options exposed.

    Arguments:
        document: the library to read the nodedef and graph from (default: MaterialX's own);
            a modified copy lets a test rewire the graph.
        premultiplied_add: apply the GLSL generator's premultipliedBsdfAdd rewrite of BSDF
            mixes (its default) or evaluate mixes as ``mx_mix_bsdf``.
    """
    doc = library() if document is None else document
    nodedef = doc.getNodeDef(NODEDEF)
    interface = _interface(inputs, nodedef)
    wi = np.asarray(wi, dtype=np.float64).reshape(-1, 3)
    wo = np.asarray(wo, dtype=np.float64).reshape(-1, 3)
    graph = nodedef.getImplementation()
    with np.errstate(all="ignore"):  # the discarded volume branch divides by depth 0
        scope = _Scope(graph, interface, {"L": wi, "V": wo}, premultiplied_add)
        out = graph.getOutput("out")
        response = scope.output(out.getNodeName(), out.getOutputString() or None)
        f = response / np.clip(wi[:, 2], EPS, 1.0)[:, None]
    above = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
    return np.where(above[:, None], f, 0.0)


def open_pbr_brdf(
    inputs: Mapping[str, float | Sequence[float]], wi: np.ndarray, wo: np.ndarray
) -> np.ndarray:
    """(N, 3) RGB BRDF in 1/sr (no cosine) of MaterialX's ``open_pbr_surface`` with these inputs.

    The reflection (direct light) response of the library's node graph, interpreted as the
    module docstring says, divided by ``wi.z``; ``geometry_opacity`` multiplies it.

    Arguments:
        inputs: ``open_pbr_surface`` input values by name (floats; colours as 3 floats or one);
            a name not given takes the nodedef default read from the library; an unknown name
            raises ``KeyError``. ``transmission_weight`` / ``subsurface_weight`` > 0 give the
            graph's reflection path (the transmission closures add nothing to it; the
            subsurface closure is MaterialX's Burley approximation on a flat patch).
        wi: (N, 3) unit vectors toward the light, local frame (normal +z, tangent +x).
        wo: (N, 3) unit vectors toward the viewer.

    Returns:
        (N, 3) float64, zero where ``wi.z <= 0`` or ``wo.z <= 0``.
    """
    return evaluate(inputs, wi, wo)


# ---------------------------------------------------------------------------------------------
# The 40-digit reference of the ``openpbr`` model (tests/models/test_precision.py)
#
# The closures above, rewritten in mpmath one direction pair at a time (tests/references.py):
# MaterialX's GLSL as the numpy transcriptions read it, every clamp to [eps, 1] of N.L, N.V,
# V.H and L.V included, composed as the node graph composes them for the inputs the model
# leaves free (its fixed inputs: base_weight 1, coat_color white, coat_darkening 1,
# coat_roughness_anisotropy 0, no transmission, subsurface or emission, opacity 1). The
# numpy interpreter above is float64 and reads the graph; this reads no library and no model.


def _mp_clamp(x, lo=None, hi=None):
    lo = num("1e-8") if lo is None else lo
    hi = mp.mpf(1) if hi is None else hi
    return min(max(x, lo), hi)


def _mp_fit(x, y) -> tuple:
    """``mx_ggx_dir_albedo_analytic``'s ``(A, B)``, each clamped to [0, 1]."""
    terms = (1, x, y, x * y, x * x, y * y, x * x * y, x * y * y, x * x * y * y)
    r = [sum(num(repr(float(_GGX_FIT[t, k]))) * terms[t] for t in range(9)) for k in range(4)]
    zero, one = mp.mpf(0), mp.mpf(1)
    return _mp_clamp(r[0] / r[2], zero, one), _mp_clamp(r[1] / r[3], zero, one)


def _mp_comp(fss, ab):
    """``mx_ggx_energy_compensation``: ``1 + F (1 - E_ss) / E_ss`` of each Fresnel."""
    ess = ab[0] + ab[1]
    return [1 + f * (1 - ess) / ess for f in fss]


def _mp_alphas(r, aniso) -> tuple:
    """``open_pbr_anisotropy`` then the closure's clamp of each alpha to [eps, 1]."""
    ax = r * r * mp.sqrt(2 / (1 + (1 - aniso) ** 2))
    return _mp_clamp(ax), _mp_clamp((1 - aniso) * ax)


def _mp_microfacet(g: Pair, ax, ay, nl, nv):
    """``D G2 / (4 N.L N.V)``: ``mx_ggx_NDF`` of H in the frame (T = x, N = z) and
    ``mx_ggx_smith_G2`` of the mean alpha, at the clamped cosines."""
    hx, hy = g.h[0] / ax, g.h[1] / ay
    d = 1 / (mp.pi * ax * ay * (hx * hx + hy * hy + g.h[2] ** 2) ** 2)
    a2 = ax * ay
    lam_l = mp.sqrt(a2 + (1 - a2) * nl**2)
    lam_v = mp.sqrt(a2 + (1 - a2) * nv**2)
    g2 = 2 * nl * nv / (lam_l * nv + lam_v * nl)
    return d * g2 / (4 * nl * nv)


def _mp_fresnel_dielectric(c, ior):
    """``mx_fresnel_dielectric`` (1 on total internal reflection)."""
    g2 = ior * ior + c * c - 1
    if g2 < 0:
        return mp.mpf(1)
    g = mp.sqrt(g2)
    return (g - c) ** 2 / (2 * (g + c) ** 2) * (1 + ((g + c) * c - 1) ** 2 / ((g - c) * c + 1) ** 2)


def _mp_hoffman(c, f0: list, f82: list) -> list:
    """``mx_fresnel_hoffman_schlick`` with ``F90 = 1``, exponent 5 (colours floored at 0)."""
    cmax = mp.mpf(1) / 7
    factor = 1 / (cmax * (1 - cmax) ** 6)
    x = _mp_clamp(c, mp.mpf(0), mp.mpf(1))
    out = []
    for a0, a82 in zip(f0, f82, strict=True):
        a0, a82 = max(a0, 0), max(a82, 0)
        a = (a0 + (1 - a0) * (1 - cmax) ** 5) * (1 - a82) * factor
        out.append(a0 + (1 - a0) * (1 - x) ** 5 - a * x * (1 - x) ** 6)
    return out


def _mp_f0_to_ior(f0):
    s = mp.sqrt(_mp_clamp(f0, num("0.01"), num("0.99")))
    return (1 + s) / (1 - s)


def _mp_polarized(c, n) -> tuple:
    """``mx_fresnel_conductor_polarized`` with ``k = 0`` (and the dielectric one, the same
    for ``n >= 1``): ``(R_p, R_s)``."""
    cos2 = _mp_clamp(c, mp.mpf(0), mp.mpf(1)) ** 2
    sin2 = 1 - cos2
    t0 = n * n - sin2
    a2pb2 = abs(t0)
    t1 = a2pb2 + cos2
    a = mp.sqrt(max((a2pb2 + t0) / 2, 0))
    t2 = 2 * a * c
    rs = (t1 - t2) / (t1 + t2)
    t3 = cos2 * a2pb2 + sin2 * sin2
    t4 = t2 * sin2
    return rs * (t3 - t4) / (t3 + t4), rs


def _mp_phase(c, eta1, eta2) -> tuple:
    """``mx_fresnel_conductor_phase_polarized`` with ``kappa = 0``: ``(phi_p, phi_s)``."""
    sin2 = 1 - c * c
    big_a = eta2 * eta2 - eta1 * eta1 * sin2
    big_b = abs(big_a)
    u = mp.sqrt((big_a + big_b) / 2)
    v = mp.sqrt((big_b - big_a) / 2)
    phi_s = mp.atan2(2 * eta1 * v * c, u * u + v * v - (eta1 * c) ** 2)
    phi_p = mp.atan2(
        2 * eta1 * eta2 * eta2 * c * (0 - v), (eta2 * eta2 * c) ** 2 - eta1 * eta1 * (u * u + v * v)
    )
    return phi_p, phi_s


_MP_XYZ_TO_RGB = (
    ("2.3706743", "-0.9000405", "-0.4706338"),
    ("-0.5138850", "1.4253036", "0.0885814"),
    ("0.0052982", "-0.0146949", "1.0093968"),
)


def _mp_sensitivity(opd, shift: list) -> list:
    """``mx_eval_sensitivity(opd, shift)``: XYZ (three shifts, one per component)."""
    phase = 2 * mp.pi * opd
    val, pos = ("5.4856e-13", "4.4201e-13", "5.2481e-13"), ("1.6810e06", "1.7953e06", "2.2084e06")
    var = ("4.3278e09", "9.3046e09", "6.6121e09")
    xyz = [
        num(v)
        * mp.sqrt(2 * mp.pi * num(s))
        * mp.cos(num(q) * phase + sh)
        * mp.exp(-num(s) * phase**2)
        for v, q, s, sh in zip(val, pos, var, shift, strict=True)
    ]
    var_x = num("4.5282e09")
    xyz[0] += (
        num("9.7470e-14")
        * mp.sqrt(2 * mp.pi * var_x)
        * mp.cos(num("2.2399e06") * phase + shift[0])
        * mp.exp(-var_x * phase**2)
    )
    return [x / num("1.0685e-7") for x in xyz]


def _mp_airy(c, tf_ior, thickness_nm, *, ior=None, f0=None, f82=None) -> list:
    """``mx_fresnel_airy`` (``AIRY_FRESNEL_ITERATIONS`` 2), air outside: a dielectric base of
    index ``ior`` or a Schlick base (``f0``, ``f82``, F90 1), RGB clamped to [0, 1]."""
    eta1 = mp.mpf(1)
    eta2 = max(tf_ior, eta1)
    schlick = f0 is not None
    cos_t = mp.sqrt(1 - (1 - c * c) * (eta1 / eta2) ** 2)
    r12p, r12s = _mp_polarized(c, eta2 / eta1)
    if cos_t <= 0:
        r12p = r12s = mp.mpf(1)
    t121p, t121s = 1 - r12p, 1 - r12s
    if schlick:
        eta3 = [_mp_f0_to_ior(x) for x in f0]
        r23p = r23s = [x / 2 for x in _mp_hoffman(cos_t, f0, f82)]
        phi23p = phi23s = [mp.pi if e3 < eta2 else mp.mpf(0) for e3 in eta3]
    else:
        pol = _mp_polarized(cos_t, ior / eta2)
        r23p, r23s = [pol[0]] * 3, [pol[1]] * 3
        ph = _mp_phase(cos_t, eta2, ior)
        phi23p, phi23s = [ph[0]] * 3, [ph[1]] * 3
    cos_b = mp.cos(mp.atan(eta2 / eta1))
    phi21p, phi21s = (mp.mpf(0) if c < cos_b else mp.pi), mp.pi
    opd = 2 * eta2 * cos_t * thickness_nm * num("1e-9")
    total = [mp.mpf(0)] * 3
    for r12, t121, r23, phi23, phi21 in (
        (r12p, t121p, r23p, phi23p, phi21p),
        (r12s, t121s, r23s, phi23s, phi21s),
    ):
        r123 = [mp.sqrt(max(r12 * x, 0)) for x in r23]
        rr = [t121**2 * x / (1 - r12 * x) for x in r23]
        total = [t + r12 + x for t, x in zip(total, rr, strict=True)]
        cm = [x - t121 for x in rr]
        phi = [x + phi21 for x in phi23]
        for m in (1, 2):
            cm = [a * b for a, b in zip(cm, r123, strict=True)]
            sens = _mp_sensitivity(m * opd, [m * x for x in phi])
            total = [t + a * 2 * s for t, a, s in zip(total, cm, sens, strict=True)]
    out = []
    for row in _MP_XYZ_TO_RGB:
        v = sum(num(m) * t / 2 for m, t in zip(row, total, strict=True))
        out.append(_mp_clamp(v, mp.mpf(0), mp.mpf(1)))
    return out


def _mp_fujii() -> tuple:
    """Fujii's constants ``(1/2 - 2/(3 pi), 2/3 - 28/(15 pi))`` at the working precision."""
    return mp.mpf(1) / 2 - 2 / (3 * mp.pi), mp.mpf(2) / 3 - 28 / (15 * mp.pi)


def _mp_fujii_albedo(c, r):
    """``mx_oren_nayar_fujii_diffuse_dir_albedo``, as printed (``1 - si^3`` and ``si / c``)."""
    c1, _ = _mp_fujii()
    a = 1 / (1 + c1 * r)
    si = mp.sqrt(max(0, 1 - c * c))
    gg = (
        si * (mp.acos(_mp_clamp(c, mp.mpf(-1), mp.mpf(1))) - si * c)
        + 2 * ((si / c) * (1 - si**3) - si) / 3
    )
    return a + r * a * gg / mp.pi


def _mp_eon(nl, nv, lv, r, color: list) -> list:
    """``mx_oren_nayar_compensated_diffuse`` (EON) times 1/pi: the BRDF of the diffuse."""
    eps = num("1e-8")
    c1, c2 = _mp_fujii()
    s = lv - nl * nv
    stinv = s / max(nl, nv) if s > 0 else s
    a = 1 / (1 + c1 * r)
    ev, el = _mp_fujii_albedo(nv, r), _mp_fujii_albedo(nl, r)
    avg = a * (1 + c2 * r)
    out = []
    for k in color:
        single = k * a * (1 + r * stinv)
        ms = k * k * avg / (1 - k * max(0, 1 - avg))
        multi = ms * max(eps, 1 - ev) * max(eps, 1 - el)
        out.append((single + multi / max(eps, 1 - avg)) / mp.pi)
    return out


def _mp_zeltner_albedo(x, y):
    """``mx_zeltner_sheen_dir_albedo``."""
    s = y * (num("0.0206607") + num("1.58491") * y) / (num("0.0379424") + y * (num("1.32227") + y))
    m = (
        y
        * (num("-0.193854") + y * (num("-1.14885") + y * (num("1.7932") - num("0.95943") * y * y)))
        / (num("0.046391") + y)
    )
    o = (
        y
        * (num("0.000654023") + (num("-0.0207818") + num("0.119681") * y) * y)
        / (num("1.26264") + y * (num("-1.92021") + y))
    )
    return mp.exp(-(((x - m) / s) ** 2) / 2) / (s * mp.sqrt(2 * mp.pi)) + o


def _mp_zeltner_ltc(g: Pair, nv, r):
    """``mx_zeltner_sheen_brdf``: the LTC lobe times the cosine (unclamped N.L), N = z."""
    x_vec = [g.wo[0], g.wo[1], g.wo[2] - nv]
    len_sqr = dot(x_vec, x_vec)
    if len_sqr > 0:
        n = mp.sqrt(len_sqr)
        x_vec = [v / n for v in x_vec]
        y_vec = [-x_vec[1], x_vec[0], mp.mpf(0)]  # cross((0, 0, 1), X)
    else:  # mx_orthonormal_basis((0, 0, 1))
        x_vec = [mp.mpf(1), mp.mpf(0), mp.mpf(0)]
        y_vec = [mp.mpf(0), mp.mpf(1), mp.mpf(0)]
    w = (dot(g.wi, x_vec), dot(g.wi, y_vec), g.wi[2])
    x, y = nv, r
    a_inv = (
        (num("2.58126") * x + num("0.813703") * y)
        * y
        / (1 + num("0.310327") * x * x + num("2.60994") * x * y)
    )
    b_inv = (
        mp.sqrt(1 - x)
        * (y - 1)
        * y**3
        / (
            num("0.0000254053")
            + num("1.71228") * x
            - num("1.71506") * x * y
            + num("1.34174") * y * y
        )
    )
    wo = (a_inv * w[0] + b_inv * w[2], a_inv * w[1], w[2])
    len_sqr = dot(wo, wo)
    return max(wo[2], 0) / mp.pi * (a_inv / len_sqr) ** 2


def _openpbr(model, p, g: Pair) -> list:
    """OpenPBR Surface (opaque) as MaterialX 1.39.5's GLSL evaluates ``open_pbr_surface``,
    with the model's options (``anisotropic``, ``coat``, ``fuzz``, ``thin_film``,
    ``negative_f82``) and fixed inputs, in 1/sr:

    ``f = fuzz + (1 - fuzz_weight E_z)(coat + T_coat k_dark B)``, ``B = m metal + (1 - m)
    (spec tint + max(0, T_d) diffuse)`` (``mx_layer_bsdf``, the premultiplied ``mx_add_bsdf``
    of the metal/dielectric mix and of the thin-film mix, whose throughput is ``max(0, t1 + t2
    - 1)``, ``mx_multiply_bsdf_color3``'s clamp of the darkening to [0, 1])."""
    eps, one, zero = num("1e-8"), mp.mpf(1), mp.mpf(0)
    nl, nv, vh = _mp_clamp(g.ci), _mp_clamp(g.co), _mp_clamp(g.cd)
    lv = _mp_clamp(dot(g.wi, g.wo))
    color, m, sw = rgb(p["base_color"]), p["base_metalness"], p["specular_weight"]
    tint, r, ior = rgb(p["specular_color"]), p["specular_roughness"], p["specular_ior"]
    coat = model.coat
    if coat:
        cw, cior, cr = p["coat_weight"], p["coat_ior"], p["coat_roughness"]
        r = r + (min(one, 2 * cr**4 + r**4) ** (one / 4) - r) * cw  # mix(r, coated, cw)
        ratio = ior / cior if ior / cior > 1 else cior / ior
        ior = ior * (1 - cw) + ratio * cw
    # the specular_weight modulation of the graph: sign(eta - 1) sqrt(clamp(w F0(eta), 0, .99999))
    f0 = ((ior - 1) / (ior + 1)) ** 2
    e = mp.sign(ior - 1) * mp.sqrt(_mp_clamp(sw * f0, zero, num("0.99999")))
    eta = (1 + e) / (1 - e)
    aniso = p["specular_roughness_anisotropy"] if model.anisotropic else zero
    ax, ay = _mp_alphas(r, aniso)
    dg = _mp_microfacet(g, ax, ay, nl, nv)
    ab = _mp_fit(nv, mp.sqrt(ax * ay))

    def dielectric(fss: list, weight) -> tuple:  # mx_dielectric_bsdf: (BRDF, throughput)
        if weight < eps:
            return [zero] * 3, [one] * 3
        comp = _mp_comp(fss, ab)
        spec = [weight * dg * f * c * t for f, c, t in zip(fss, comp, tint, strict=True)]
        albedo = ((eta - 1) / (eta + 1)) ** 2 * ab[0] + ab[1]
        return spec, [1 - weight * albedo * c for c in comp]

    def metal(fss: list, weight) -> list:  # mx_generalized_schlick_bsdf, F90 1
        if weight < eps:
            return [zero] * 3
        comp = _mp_comp(fss, ab)
        return [weight * dg * f * c for f, c in zip(fss, comp, strict=True)]

    f_d = [_mp_fresnel_dielectric(vh, eta)] * 3
    f_m = _mp_hoffman(vh, color, tint)
    f_m = f_m if model.negative_f82 else [max(x, zero) for x in f_m]
    if model.thin_film:
        w, nm, film = p["thin_film_weight"], 1000 * p["thin_film_thickness"], p["thin_film_ior"]
        spec, tp = dielectric(f_d, 1 - w)
        spec_t, tp_t = dielectric(_mp_airy(vh, film, nm, ior=eta), w)
        spec = [a + b for a, b in zip(spec, spec_t, strict=True)]
        tp = [max(zero, a + b - 1) for a, b in zip(tp, tp_t, strict=True)]  # mx_add_bsdf
        f_mt = _mp_airy(vh, film, nm, f0=color, f82=tint)
        shine = [a + b for a, b in zip(metal(f_m, sw * (1 - w)), metal(f_mt, sw * w), strict=True)]
    else:
        spec, tp = dielectric(f_d, one)
        tp = [max(zero, t) for t in tp]  # mx_add_bsdf with the thin film's empty half
        shine = metal(f_m, sw)
    diffuse = _mp_eon(nl, nv, lv, p["base_diffuse_roughness"], color)
    base = [s + d * t for s, d, t in zip(spec, diffuse, tp, strict=True)]
    out = [m * a + (1 - m) * b for a, b in zip(shine, base, strict=True)]
    if coat:  # the darkening multiplies the base whatever the coat's weight
        f0c = ((cior - 1) / (cior + 1)) ** 2
        k = 1 - (1 - f0c) / cior**2
        e_base = [c * (1 - m) + sw * c * m for c in color]  # mix(c, sw c, m)
        dark = [_mp_clamp(1 + cw * ((1 - k) / (1 - eb * k) - 1), zero, one) for eb in e_base]
        out = [o * d for o, d in zip(out, dark, strict=True)]
        if cw >= eps:
            axc, ayc = _mp_alphas(cr, zero)
            abc = _mp_fit(nv, mp.sqrt(axc * ayc))
            fc = _mp_fresnel_dielectric(vh, cior)
            compc = _mp_comp([fc], abc)[0]
            lobe = cw * fc * compc * _mp_microfacet(g, axc, ayc, nl, nv)
            tpc = 1 - cw * (f0c * abc[0] + abc[1]) * compc
            out = [lobe + o * tpc for o in out]
    if model.fuzz and p["fuzz_weight"] >= eps:
        fw, fr = p["fuzz_weight"], _mp_clamp(p["fuzz_roughness"], num("0.01"), one)
        e_z = _mp_zeltner_albedo(nv, fr)
        lobe = fw * e_z * _mp_zeltner_ltc(g, nv, fr) / nl
        out = [
            lobe * fc + o * (1 - fw * e_z) for fc, o in zip(rgb(p["fuzz_color"]), out, strict=True)
        ]
    return out


@per_pair
def openpbr_ref(model, p, g):
    """MaterialX 1.39.5's ``open_pbr_surface`` (GLSL, reflection, one light) at the working
    precision: the closures of this module rewritten in mpmath (:func:`_openpbr`)."""
    return _openpbr(model, p, g)


REFERENCES = {"openpbr": openpbr_ref}
