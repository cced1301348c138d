"""High-precision reference for ``brdffit/models/gltf_pbr.py``: the glTF 2.0 spec in mpmath.

Transcribed from the glTF 2.0 specification, Appendix B (``D_GGX``, ``V_GGX``, ``fresnel_mix``
with KHR_materials_specular/_ior, ``conductor_fresnel``, ``mix`` by metallic), the
KHR_materials_sheen text (``D_Charlie``, the Ashikhmin visibility, no albedo scaling) and
KHR_materials_clearcoat (``fresnel_coat`` at ``N.V``, IOR 1.5), as written there:
``D = a^2 / (pi ((N.H)^2 (a^2 - 1) + 1)^2)``, ``V = 1 / (N.L sqrt(N.V^2 (1 - a^2) + a^2) +
N.V sqrt(N.L^2 (1 - a^2) + a^2)) / 2``, the Fresnel weight at ``|V.H|``. Evaluated one pair at
a time at the test's working precision (tests/references.py); nothing here calls
``brdffit/models/``.
"""

from __future__ import annotations

import mpmath as mp

from tests.references import Reference, dot, num, per_pair, rgb


def _dv(alpha, g):
    a2 = alpha**2
    d = a2 / (mp.pi * (g.ch**2 * (a2 - 1) + 1) ** 2)
    v = 1 / (g.ci * mp.sqrt(g.co**2 * (1 - a2) + a2) + g.co * mp.sqrt(g.ci**2 * (1 - a2) + a2))
    return d * v / 2


@per_pair
def gltf_ref(model, p, g):
    """glTF 2.0 metallic-roughness with the extensions the model's options turn on."""
    dv = _dv(p["roughness"] ** 2, g)
    w = (1 - abs(dot(g.wo, g.h))) ** 5
    if model.specular:
        s, f0 = p["specular"], rgb(p["specular_f0"])
    else:
        s, f0 = mp.mpf(1), rgb(num("0.04"))
    f_d = [s * x + (s - s * x) * w for x in f0]  # mix(f0 specular, specular, w)
    out = []
    for b, f in zip(rgb(p["base_color"]), f_d, strict=True):
        dielectric = f * dv + (1 - max(f_d)) * b / mp.pi
        metal = (b + (1 - b) * w) * dv
        out.append((1 - p["metallic"]) * dielectric + p["metallic"] * metal)
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


REFERENCES: dict[str, Reference] = {"gltf": gltf_ref}
