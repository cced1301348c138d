"""The 14 published fit sets, each paired with the brdffit model that has its formula.

For every bbm fit file: the metric it was published with, the brdffit model spec that
evaluates the same function (up to how the parameters are written), and the two maps
between brdffit's parameters and the published ones. ``to_published`` writes a
brdffit fit as a bbm constructor string, so bbm's C++ scores it exactly as it scores
the published fit; ``from_published`` writes a published fit in brdffit's parameters
(to start a fit there, and to see whether a published value lies outside brdffit's
bounds). The formulas each map rests on (bbm's headers, commit 9807fb3):

* Lambertian: ``albedo / pi``; brdffit's ``kd``.
* NganWard, NganWardDuer (``ward.h``, ``wardduer.h``): ``albedo exp(-tan^2 theta_h /
  a^2) / (4 pi a^2 sqrt(cos_i cos_o))`` and the same with ``cos_i cos_o``; brdffit's
  ``ward`` with ``normalization`` ``ward`` / ``duer``: ``ks = albedo``, ``alpha = a``.
* NganBlinnPhong: bbm's ``ngan.h`` aliases it to ``phong.h``, ``albedo (n + 2) / (2 pi)
  max(0, reflect(wi) . wo)^n``, the lobe about the mirror direction. The published values
  are Blinn's half-vector lobe, as the paper names it: read as ``albedo (n + 2) / (2 pi)
  cos_h^n`` they score lower than bbm's reading on 80 of the 86 materials (0.053 against
  0.069 on gold-metallic-paint; the benchmark records both, ``published_bbm`` is bbm's), and
  their exponents are those of a half-vector lobe (blue-acrylic: 13,700, where Ward's
  roughness 0.0162 gives 2 / a^2 = 7,600; a lobe about the mirror direction is 4 times
  narrower in exponent). So this set is scored by :func:`blinn_reading` (NumPy, here),
  and brdffit's ``blinn_phong`` (normalised by ``(n + 8) / (8 pi)``) maps by ``albedo =
  ks (n + 8) / (4 (n + 2))``.
* NganLafortune (``lafortune.h`` with Ngan's factor): ``albedo (n + 2) / (2 pi) max(0,
  Cxy (ix ox + iy oy) + Cz iz oz)^n / max(Cz^2, Cxy^2)^(n/2)``; brdffit's ``lafortune``
  (one lobe, isotropic) with ``cxy = Cxy / Cz`` and ``rho = albedo (Cz / max(|Cz|,
  |Cxy|))^n``. Scored by :func:`lafortune_reading`, the same formula in log space.
* NganCookTorrance (``ngan.h``): ``albedo F_schlick(F0; h.wi) D G / (pi cos_i cos_o)``,
  Beckmann ``D`` normalised (``int D cos_h = 1``), V-groove ``G``, F0 printed as
  ``eta``; brdffit's ``cook_torrance`` (Schlick, grey ``f0``) divides by ``4``, not
  ``pi``: ``ks = 4 albedo / pi``.
* LowCookTorrance (``cooktorrance.h``): the same with Cook's exact dielectric Fresnel of
  index ``eta`` and Beckmann unnormalised (``pi`` times larger): ``ks = 4 albedo``.
* NganAshikhminShirley, LowAshikhminShirley (``ashikhminshirley.h``): ``albedo (n + 1) /
  (8 pi) cos_h^n F(h.wi) / ((h.wi) max(cos_i, cos_o))``, Schlick (F0) or Cook's Fresnel
  (``eta``, printed as ``fresnelReflectance``); brdffit's ``ashikhmin_shirley`` with a
  Lambertian diffuse term: ``ks = albedo``.
* NganHe (``he.h`` as ``ngan.h`` instantiates it): brdffit's ``he`` is written from the
  paper and that instantiation (``brdffit/models/he.py``); ``ks = albedo``, ``sigma =
  roughness``, ``tau = autocorrelation`` (micrometres), ``eta = eta``.
* LowMicrofacetFit, LowSmooth, Bagher: see their entries.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from benchmarks.published.fitfile import PublishedFit, parse_line

Params = dict[str, np.ndarray]


@dataclass(frozen=True)
class Family:
    """One published fit set and the brdffit model with its formula.

    ``to_published(params)`` the bbm string of a brdffit fit (None: the formulas differ,
    no exact map); ``from_published(fit)`` the published fit in brdffit's parameters
    (None: no map). ``note`` says what differs, if anything (printed under the table)."""

    key: str
    file: str
    metric: str
    spec: str
    to_published: Callable[[Params], str] | None
    from_published: Callable[[PublishedFit], Params] | None
    note: str = ""
    reading: Callable[[str, np.ndarray, np.ndarray], np.ndarray] | None = None
    """Evaluates a bbm string of this set where bbm's own reading is not the paper's
    (None: bbm's C++ evaluates it)."""


def _num(x) -> str:
    """A float as bbm's importer reads it, to full precision."""
    return repr(float(x))


def _vec(x) -> str:
    return "[" + ", ".join(_num(v) for v in np.broadcast_to(np.ravel(x), (3,))) + "]"


def _aggregate(kd, cls: str, **params) -> str:
    inner = ", ".join(f"{k} = {v}" for k, v in params.items())
    return f"Aggregate(Lambertian(albedo = {_vec(kd)}), {cls}({inner}))"


def _rgb(x) -> np.ndarray:
    return np.broadcast_to(np.asarray(x, float), (3,)).copy()


def _kd(fit: PublishedFit) -> np.ndarray:
    return _rgb(fit.component("Lambertian").params["albedo"])


# --- Ward and Ward-Dür -------------------------------------------------------------------


def _ward(cls: str) -> tuple[Callable, Callable]:
    def to(p: Params) -> str:
        return _aggregate(p["kd"], cls, albedo=_vec(p["ks"]), roughness=_num(p["alpha"]))

    def back(fit: PublishedFit) -> Params:
        c = fit.component(cls).params
        return {"kd": _kd(fit), "ks": _rgb(c["albedo"]), "alpha": np.float64(c["roughness"])}

    return to, back


# --- Blinn-Phong ------------------------------------------------------------------------


def blinn_reading(expression: str, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Ngan's Blinn-Phong fit ``expression`` at (N, 3) directions, (N, 3) in 1/sr:
    ``kd / pi + albedo (n + 2) / (2 pi) cos_h^n`` (0 below the horizon)."""
    fit = parse_line("x = " + expression)
    kd = _kd(fit)
    c = fit.component("NganBlinnPhong").params
    albedo, n = _rgb(c["albedo"]), float(c["sharpness"])
    h = wi + wo
    cos_h = h[:, 2] / np.linalg.norm(h, axis=1)
    lobe = (n + 2.0) / (2.0 * math.pi) * np.exp(n * np.log(np.clip(cos_h, 1e-300, 1.0)))
    f = kd[None, :] / math.pi + albedo[None, :] * lobe[:, None]
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    return np.where(above[:, None], f, 0.0)


def _blinn_to(p: Params) -> str:
    n = float(p["n"])
    albedo = _rgb(p["ks"]) * (n + 8.0) / (4.0 * (n + 2.0))
    return _aggregate(p["kd"], "NganBlinnPhong", albedo=_vec(albedo), sharpness=_num(n))


def _blinn_back(fit: PublishedFit) -> Params:
    c = fit.component("NganBlinnPhong").params
    n = float(c["sharpness"])
    ks = _rgb(c["albedo"]) * 4.0 * (n + 2.0) / (n + 8.0)
    return {"kd": _kd(fit), "ks": ks, "n": np.float64(n)}


# --- Lafortune with Ngan's normalisation ------------------------------------------------


def lafortune_reading(expression: str, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Ngan's Lafortune fit ``expression`` at (N, 3) directions, (N, 3) in 1/sr, bbm's
    formula in log space: ``albedo (n + 2) / (2 pi) exp(n (ln b - ln max(|Cz|, |Cxy|)))``
    with ``b = Cxy (ix ox + iy oy) + Cz iz oz > 0`` (0 elsewhere). bbm's C++ forms ``b^n``
    and ``max(Cz^2, Cxy^2)^(n/2)`` separately; both underflow to 0 for 33 of the 86
    published fits (``n`` in the thousands, ``|C|`` near 0.58), where it returns NaN."""
    fit = parse_line("x = " + expression)
    c = fit.component("NganLafortune").params
    albedo, n = _rgb(c["albedo"]), float(c["sharpness"])
    cxy, cz = float(c["Cxy"]), float(c["Cz"])
    b = cxy * (wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1]) + cz * wi[:, 2] * wo[:, 2]
    log_ratio = np.log(np.where(b > 0, b, 1.0)) - math.log(max(abs(cz), abs(cxy)))
    lobe = np.exp(np.where(b > 0, n * log_ratio, -np.inf))
    f = (
        _kd(fit)[None, :] / math.pi
        + albedo[None, :] * ((n + 2.0) / (2.0 * math.pi) * lobe)[:, None]
    )
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    return np.where(above[:, None], f, 0.0)


def _lafortune_to(p: Params) -> str:
    cxy, n = float(p["cxy_1"]), float(p["n_1"])
    albedo = _rgb(p["rho_1"]) * max(1.0, abs(cxy)) ** n
    return _aggregate(
        p["kd"], "NganLafortune", albedo=_vec(albedo), Cxy=_num(cxy), Cz="1.0", sharpness=_num(n)
    )


def _lafortune_back(fit: PublishedFit) -> Params:
    c = fit.component("NganLafortune").params
    cxy, cz, n = float(c["Cxy"]), float(c["Cz"]), float(c["sharpness"])
    rho = _rgb(c["albedo"]) * (cz / max(abs(cz), abs(cxy))) ** n
    return {"kd": _kd(fit), "rho_1": rho, "cxy_1": np.float64(cxy / cz), "n_1": np.float64(n)}


# --- Cook-Torrance -----------------------------------------------------------------------


def _ct(cls: str, scale: float, fresnel: str) -> tuple[Callable, Callable]:
    """``ks = scale * albedo``; Fresnel parameter ``f0`` (printed ``eta``) or ``eta``."""
    key = "f0" if fresnel == "schlick" else "eta"

    def to(p: Params) -> str:
        albedo = _rgb(p["ks"]) / scale
        f = float(np.ravel(p[key])[0])
        return _aggregate(p["kd"], cls, albedo=_vec(albedo), roughness=_num(p["m"]), eta=_num(f))

    def back(fit: PublishedFit) -> Params:
        c = fit.component(cls).params
        return {
            "kd": _kd(fit),
            "ks": scale * _rgb(c["albedo"]),
            "m": np.float64(c["roughness"]),
            key: np.float64(c["eta"]),
        }

    return to, back


# --- Ashikhmin-Shirley specular lobe with a Lambertian diffuse --------------------------


def _as(cls: str, fresnel: str) -> tuple[Callable, Callable]:
    key = "rs" if fresnel == "schlick" else "eta"

    def to(p: Params) -> str:
        f = float(np.ravel(p[key])[0])
        return _aggregate(
            p["kd"], cls, albedo=_vec(p["ks"]), sharpness=_num(p["n"]), fresnelReflectance=_num(f)
        )

    def back(fit: PublishedFit) -> Params:
        c = fit.component(cls).params
        return {
            "kd": _kd(fit),
            "ks": _rgb(c["albedo"]),
            "n": np.float64(c["sharpness"]),
            key: np.float64(c["fresnelReflectance"]),
        }

    return to, back


# --- He et al. 1991 as Ngan et al. fitted it ---------------------------------------------


def _he_to(p: Params) -> str:
    return _aggregate(
        p["kd"], "NganHe", albedo=_vec(p["ks"]), autocorrelation=_num(p["tau"]),
        roughness=_num(p["sigma"]), eta=_num(p["eta"]),
    )  # fmt: skip


def _he_back(fit: PublishedFit) -> Params:
    c = fit.component("NganHe").params
    return {
        "kd": _kd(fit),
        "ks": _rgb(c["albedo"]),
        "sigma": np.float64(c["roughness"]),
        "tau": np.float64(c["autocorrelation"]),
        "eta": np.float64(c["eta"]),
    }


# --- Löw et al.'s ABC microfacet and smooth-surface models --------------------------------


def _phi(k: float, x: float) -> float:
    """``(exp(k x) - 1) / k`` (``int_1^{1+B} u^(k-1) du`` for ``x = ln(1 + B)``)."""
    return x if abs(k * x) < 1e-12 else math.expm1(k * x) / k


def _f1(eta: float) -> float:
    """Fresnel reflectance of a dielectric at normal incidence, ``((eta - 1)/(eta + 1))^2``."""
    return ((eta - 1.0) / (eta + 1.0)) ** 2


def _low_scale(variant: str, b: float, c: float, eta: float) -> float:
    """Published ``A`` per unit of brdffit's ``ks``.

    ``abc``: bbm's LowMicrofacetFit is ``A S(h) G F / (pi cos_i cos_o)``, brdffit's
    ``ks A_n S G F / (4 F(1) cos_i cos_o)`` with ``1 / A_n = 2 pi ((1 + B) phi(1 - C) -
    phi(2 - C)) / B^2``: ``A = ks pi A_n / (4 F(1))``. ``smooth``: bbm's LowSmooth is
    ``A S F``, brdffit's ``ks A' S F / F(1)`` with ``A' = B / (pi phi(1 - C))``.
    """
    x = math.log1p(b)
    if variant == "abc":
        a_n = b**2 / (2.0 * math.pi * ((1.0 + b) * _phi(1.0 - c, x) - _phi(2.0 - c, x)))
        return math.pi * a_n / (4.0 * _f1(eta))
    return b / (math.pi * _phi(1.0 - c, x)) / _f1(eta)


def _low(cls: str, variant: str) -> tuple[Callable, Callable]:
    def to(p: Params) -> str:
        b, c, eta = float(p["B"]), float(p["C"]), float(p["eta"])
        a = _rgb(p["ks"]) * _low_scale(variant, b, c, eta)
        return _aggregate(p["kd"], cls, A=_vec(a), B=_num(b), C=_num(c), eta=_num(eta))

    def back(fit: PublishedFit) -> Params:
        q = fit.component(cls).params
        b, c, eta = float(q["B"]), float(q["C"]), float(q["eta"])
        ks = _rgb(q["A"]) / _low_scale(variant, b, c, eta)
        return {"kd": _kd(fit), "ks": ks, "B": np.float64(b), "C": np.float64(c), "eta": eta}

    return to, back


# --- Bagher et al.'s SGD ----------------------------------------------------------------


def _bagher_back(fit: PublishedFit) -> Params:
    """The published SGD in brdffit's ``sgd`` (RGB lobe): the same microfacet form
    (``albedo F D G1 G1 / (pi cos_i cos_o)``, D normalised, Fresnel ``F0 - F1 cos + (1 -
    F0)(1 - cos)^5``), but for ``G1``: the paper's per-material empirical curve, brdffit's
    exact Smith masking of the SGD. So the map is a start, not an identity."""
    q = fit.component("Bagher").params
    f = np.asarray(q["eta"], float)
    return {
        "kd": _kd(fit),
        "ks": _rgb(q["albedo"]),
        "f0": f[0],
        "f1": f[1],
        "alpha": _rgb(q["alpha"]),
        "p": _rgb(q["p"]),
    }


def _family(key, file, metric, spec, maps) -> Family:
    return Family(key, file, metric, spec, *maps)


_SGD_NOTE = (
    "G1: the paper's empirical curve (4 more parameters per channel) against brdffit's "
    "exact Smith masking"
)
_BLINN_NOTE = "scored as Blinn's half-vector lobe, not bbm's Phong alias"
_LAFORTUNE_NOTE = "scored by bbm's formula in log space: bbm's C++ returns NaN for 33 of the 86"
_AS_LOW = "ashikhmin_shirley[diffuse=lambert,fresnel=dielectric]"

FAMILIES: dict[str, Family] = {
    f.key: f
    for f in (
        _family("ngan_ward", "ngan_ward.fit", "ngan", "ward", _ward("NganWard")),
        _family(
            "ngan_wardduer", "ngan_wardduer.fit", "ngan", "ward[normalization=duer]",
            _ward("NganWardDuer"),
        ),
        Family(
            "ngan_blinnphong", "ngan_blinnphong.fit", "ngan", "blinn_phong",
            _blinn_to, _blinn_back, _BLINN_NOTE, blinn_reading,
        ),
        Family(
            "ngan_lafortune", "ngan_lafortune.fit", "ngan", "lafortune",
            _lafortune_to, _lafortune_back, _LAFORTUNE_NOTE, lafortune_reading,
        ),
        _family(
            "ngan_cooktorrance", "ngan_cooktorrance.fit", "ngan", "cook_torrance[grey=f0]",
            _ct("NganCookTorrance", 4.0 / math.pi, "schlick"),
        ),
        _family(
            "ngan_ashikhminshirley", "ngan_ashikhminshirley.fit", "ngan",
            "ashikhmin_shirley[diffuse=lambert,grey=rs]",
            _as("NganAshikhminShirley", "schlick"),
        ),
        _family("ngan_he", "ngan_he.fit", "ngan", "he", (_he_to, _he_back)),
        _family(
            "low_cooktorrance_E1", "low_cooktorrance_E1.fit", "low_e1",
            "cook_torrance[fresnel=dielectric]", _ct("LowCookTorrance", 4.0, "dielectric"),
        ),
        _family(
            "low_cooktorrance_E2", "low_cooktorrance_E2.fit", "low_e2",
            "cook_torrance[fresnel=dielectric]", _ct("LowCookTorrance", 4.0, "dielectric"),
        ),
        _family(
            "low_ashikhminshirley_E1", "low_ashikhminshirley_E1.fit", "low_e1", _AS_LOW,
            _as("LowAshikhminShirley", "dielectric"),
        ),
        _family(
            "low_ashikhminshirley_E2", "low_ashikhminshirley_E2.fit", "low_e2", _AS_LOW,
            _as("LowAshikhminShirley", "dielectric"),
        ),
        _family(
            "low_lowmicrofacet_E2", "low_lowmicrofacet_E2.fit", "low_e2", "low",
            _low("LowMicrofacetFit", "abc"),
        ),
        _family(
            "low_lowsmooth_E2", "low_lowsmooth_E2.fit", "low_e2", "low[variant=smooth]",
            _low("LowSmooth", "smooth"),
        ),
        Family(
            "bagher_sgd", "bagher_sgd.fit", "ngan", "sgd[rgb_lobe=true]", None, _bagher_back,
            _SGD_NOTE,
        ),
    )
}  # fmt: skip
