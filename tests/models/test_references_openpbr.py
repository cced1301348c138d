"""The OpenPBR reference (``tests/references_openpbr.py``) against things that do not depend on it.

The reference interprets MaterialX's ``open_pbr_surface`` node graph with numpy transcriptions
of its genglsl closures. Here it meets: closed forms derived from those GLSL sources at special
settings (each derivation is in the test's docstring; GGX, Smith, Fresnel and the OpenPBR
anisotropy mapping are written afresh below, only MaterialX's fitted GGX albedo ``Ess`` is
borrowed, and the furnace test checks that fit by quadrature); energy balances by quadrature;
the invariances the graph's weights imply; reciprocity exactly where the GLSL is reciprocal;
and rewired copies of the library graph, which must change the answer.
"""

from __future__ import annotations

import MaterialX as mx
import numpy as np
import pytest

from tests.references_openpbr import (
    NODEDEF,
    _ggx_dir_albedo,
    default_inputs,
    evaluate,
    library,
    open_pbr_brdf,
)

RNG_SEED = 20240611
EXACT = 1e-12  # identities of the graph: only float64 rounding separates the two sides


def _dirs(rng, n, zmin=0.05):
    v = rng.normal(size=(4 * n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v[v[:, 2] > zmin][:n]


def _pairs(n=400, seed=RNG_SEED):
    rng = np.random.default_rng(seed)
    return _dirs(rng, n), _dirs(rng, n)


def _quadrature(n_u=64, n_phi=128):
    """Directions over the upper hemisphere and their solid-angle weights (Gauss in cos)."""
    u, wu = np.polynomial.legendre.leggauss(n_u)
    u, wu = 0.5 * (u + 1.0), 0.5 * wu
    phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    U, P = np.meshgrid(u, phi, indexing="ij")
    s = np.sqrt(1.0 - U**2)
    dirs = np.stack([s * np.cos(P), s * np.sin(P), U], axis=-1).reshape(-1, 3)
    return dirs, np.repeat(wu * (2.0 * np.pi / n_phi), n_phi)


def _albedo(inputs, mu, grid):
    """Directional albedo (per channel) for viewing cosine ``mu``: the integral of f cos_i."""
    wi, w = grid
    wo = np.tile([np.sqrt(1.0 - mu * mu), 0.0, mu], (len(wi), 1))
    return (evaluate(inputs, wi, wo) * (wi[:, 2] * w)[:, None]).sum(axis=0)


# Independent microfacet pieces (textbook forms, not the GLSL's algebra)


def _alphas(roughness, anisotropy):
    """OpenPBR spec: alpha_t = r^2 sqrt(2 / (1 + (1 - a)^2)), alpha_b = (1 - a) alpha_t."""
    ax = roughness**2 * np.sqrt(2.0 / (1.0 + (1.0 - anisotropy) ** 2))
    return ax, (1.0 - anisotropy) * ax


def _ggx_d(h, ax, ay):
    return 1.0 / (np.pi * ax * ay * ((h[:, 0] / ax) ** 2 + (h[:, 1] / ay) ** 2 + h[:, 2] ** 2) ** 2)


def _smith_g2(ci, co, a):
    """Height-correlated Smith, 1 / (1 + Lambda_i + Lambda_o), isotropic alpha ``a``."""
    lam = lambda c: (np.sqrt(1.0 + a * a * (1.0 - c * c) / (c * c)) - 1.0) / 2.0  # noqa: E731
    return 1.0 / (1.0 + lam(ci) + lam(co))


def _fresnel(c, n):
    """Unpolarised Fresnel reflectance from vacuum into index n > 1."""
    ct = np.sqrt(1.0 - (1.0 - c * c) / (n * n))
    rs = (c - n * ct) / (c + n * ct)
    rp = (n * c - ct) / (n * c + ct)
    return (rs * rs + rp * rp) / 2.0


def _specular(wi, wo, ax, ay, F):
    """GGX D F G / (4 cos_i cos_o) times MaterialX's compensation 1 + F (1 - Ess) / Ess.

    G uses the isotropic alpha sqrt(ax ay), as mx_*_bsdf pass ``mx_average_alpha`` to G2.
    """
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    a = np.sqrt(ax * ay)
    dg = _ggx_d(h, ax, ay) * _smith_g2(wi[:, 2], wo[:, 2], a) / (4.0 * wi[:, 2] * wo[:, 2])
    ess = _ggx_dir_albedo(wo[:, 2], a, 1.0, 1.0)[:, 0]
    return dg[:, None] * F * (1.0 + F * ((1.0 - ess) / ess)[:, None])


def _cos_h(wi, wo):
    h = wi + wo
    return np.sum(wo * h, axis=1) / np.linalg.norm(h, axis=1)


# ---------------------------------------------------------------------------------------------


def test_inputs_are_the_nodedefs():
    """Defaults come from the library; explicit defaults change nothing; typos raise."""
    d = default_inputs()
    assert d["base_color"] == pytest.approx((0.8, 0.8, 0.8)) and d["specular_ior"] == 1.5
    assert d["coat_ior"] == 1.6 and d["fuzz_roughness"] == 0.5
    assert d["geometry_thin_walled"] is False
    wi, wo = _pairs(50)
    np.testing.assert_array_equal(open_pbr_brdf({}, wi, wo), open_pbr_brdf(d, wi, wo))
    with pytest.raises(KeyError, match="base_colour"):
        open_pbr_brdf({"base_colour": 0.5}, wi, wo)


@pytest.mark.parametrize("r, bw, color", [(0.3, 1.0, [0.8, 0.5, 0.2]), (0.7, 0.6, [0.1, 0.9, 1.0])])
def test_diffuse_alone(r, bw, color):
    """specular_weight = 0, base_diffuse_roughness = 0: f = bw (c + 1e-8 c^2) / pi (1 - B(mu_o)).

    The graph turns specular_weight into the dielectric's IOR: F0' = specular_weight F0, so
    eta' = 1 and F = 0. EON at roughness 0: A = 1, the single-scatter lobe is c, and the
    multiple-scatter lobe is c^2 EPS EPS / EPS (every ``max(EPS, 1 - E)`` hits EPS = 1e-8). But
    the dielectric's throughput is 1 - mx_ggx_dir_albedo(mu_o, alpha, F0 = 0, F90 = 1.0) =
    1 - B: its F90 = 1 term does not vanish with the IOR, so MaterialX darkens the diffuse base
    by 1 - B(mu_o, r^2) even with no specular (B ~ 0.37 at mu_o = 0.05, r = 0.3).
    """
    wi, wo = _pairs()
    inputs = {"specular_weight": 0.0, "specular_roughness": r, "base_weight": bw}
    inputs["base_color"] = color
    c = np.asarray(color)
    darkening = 1.0 - _ggx_dir_albedo(wo[:, 2], r * r, 0.0, 1.0)
    expected = bw * (c + 1e-8 * c * c) / np.pi * darkening
    np.testing.assert_allclose(open_pbr_brdf(inputs, wi, wo), expected, rtol=EXACT)
    assert darkening.min() < 0.95  # not negligible at grazing view


@pytest.mark.parametrize("r, aniso, sw", [(0.4, 0.0, 1.0), (0.5, 0.7, 0.6), (0.9, 0.3, 1.0)])
def test_metal(r, aniso, sw):
    """base_metalness = 1, specular_color = 1: a GGX metal with Schlick F, compensated.

    generalized_schlick_bsdf(weight = specular_weight, color0 = base_color base_weight,
    color82 = specular_color, color90 = 1, exponent 5): Hoffman's F82 term vanishes for
    color82 = 1, leaving F = F0 + (1 - F0)(1 - cos_h)^5.
    """
    wi, wo = _pairs()
    color, bw = np.array([0.9, 0.6, 0.3]), 0.8
    inputs = {"base_metalness": 1.0, "base_color": color, "base_weight": bw,
              "specular_roughness": r, "specular_roughness_anisotropy": aniso,
              "specular_weight": sw}  # fmt: skip
    F0 = color * bw
    F = F0 + (1.0 - F0) * ((1.0 - _cos_h(wi, wo)) ** 5)[:, None]
    expected = sw * _specular(wi, wo, *_alphas(r, aniso), F)
    np.testing.assert_allclose(open_pbr_brdf(inputs, wi, wo), expected, rtol=1e-10)


@pytest.mark.parametrize("sw, ior", [(1.0, 1.5), (0.35, 1.8), (0.8, 1.2)])
def test_specular_weight_enters_the_ior(sw, ior):
    """base_color = 0: the dielectric alone, F exact at eta' with F0(eta') = sw F0(ior).

    The graph's ``modulated_eta_s``: eta' = (1 + sqrt(sw F0)) / (1 - sqrt(sw F0)); the tint
    is specular_color; no closure weight carries specular_weight.
    """
    wi, wo = _pairs()
    tint = np.array([1.0, 0.6, 0.8])
    inputs = {"base_color": 0.0, "specular_weight": sw, "specular_ior": ior, "specular_color": tint}
    s = np.sqrt(sw * ((ior - 1.0) / (ior + 1.0)) ** 2)
    F = _fresnel(_cos_h(wi, wo), (1.0 + s) / (1.0 - s))[:, None] * np.ones(3)
    expected = _specular(wi, wo, *_alphas(0.3, 0.0), F) * tint
    np.testing.assert_allclose(open_pbr_brdf(inputs, wi, wo), expected, rtol=1e-10)


def test_coat_alone():
    """coat_weight = 1, coat_color = 0: the base is multiplied by 0, the coat's GGX remains."""
    wi, wo = _pairs()
    inputs = {"coat_weight": 1.0, "coat_color": 0.0, "coat_roughness": 0.35,
              "coat_roughness_anisotropy": 0.4, "coat_ior": 1.45}  # fmt: skip
    F = _fresnel(_cos_h(wi, wo), 1.45)[:, None] * np.ones(3)
    expected = _specular(wi, wo, *_alphas(0.35, 0.4), F)
    np.testing.assert_allclose(open_pbr_brdf(inputs, wi, wo), expected, rtol=1e-10)


@pytest.mark.parametrize("metalness", [0.0, 1.0])
def test_coat_darkening(metalness):
    """OpenPBR's coat darkening: the base (under the coat) scales by (1 - K) / (1 - E K).

    K = 1 - (1 - F0_coat) / n_coat^2; E = base_color (dielectric) or specular_weight base_color
    (metal). ``coat_darkening`` mixes it in: (f(cd) - f_coat) / (f(0) - f_coat) = mix(1, D, cd).
    """
    wi, wo = _pairs(200)
    color, n, sw = np.array([0.7, 0.4, 0.1]), 1.7, 0.9
    inputs = {"coat_weight": 1.0, "coat_ior": n, "base_color": color, "specular_weight": sw,
              "base_metalness": metalness, "coat_roughness": 0.2}  # fmt: skip
    coat = open_pbr_brdf({**inputs, "coat_color": 0.0}, wi, wo)
    f0 = open_pbr_brdf({**inputs, "coat_darkening": 0.0}, wi, wo) - coat
    k = 1.0 - (1.0 - ((n - 1.0) / (n + 1.0)) ** 2) / n**2
    e = color * (sw if metalness else 1.0)
    for cd in (1.0, 0.4):
        ratio = (open_pbr_brdf({**inputs, "coat_darkening": cd}, wi, wo) - coat) / f0
        np.testing.assert_allclose(ratio, np.broadcast_to(1 - cd + cd * (1 - k) / (1 - e * k),
                                                          ratio.shape), rtol=1e-9)  # fmt: skip


def test_parameters_of_absent_layers_do_nothing():
    """coat_weight = fuzz_weight = thin_film_weight = 0 (or film thickness 0): no trace."""
    wi, wo = _pairs()
    base = {"base_color": [0.6, 0.3, 0.2], "base_metalness": 0.4, "specular_roughness": 0.5}
    f = open_pbr_brdf(base, wi, wo)
    unused = {"coat_color": [0.1, 0.5, 0.2], "coat_roughness": 0.8, "coat_ior": 2.2,
              "coat_darkening": 0.3, "coat_roughness_anisotropy": 0.6,
              "fuzz_color": [0.9, 0.1, 0.4], "fuzz_roughness": 0.1,
              "thin_film_thickness": 0.3, "thin_film_ior": 1.9}  # fmt: skip
    np.testing.assert_array_equal(open_pbr_brdf({**base, **unused}, wi, wo), f)
    no_film = {"thin_film_weight": 1.0, "thin_film_thickness": 0.0}
    np.testing.assert_array_equal(open_pbr_brdf({**base, **no_film}, wi, wo), f)
    assert not np.allclose(open_pbr_brdf({**base, "thin_film_weight": 1.0}, wi, wo), f)


XYZ_TO_RGB = np.array([[2.3706743, -0.9000405, -0.4706338],  # mx_fresnel_airy's matrix
                       [-0.5138850, 1.4253036, 0.0885814],
                       [0.0052982, -0.0146949, 1.0093968]])  # fmt: skip


def test_a_vacuum_thin_film():
    """thin_film_ior = 1: Airy's R12 = 0 and T121 = 1, so I = (R23p + R23s) / 2, then XYZ -> RGB.

    Dielectric base: R23p,s are the polarised Fresnel terms, I is grey and the matrix (unit row
    sums to 1e-7) leaves it: no film. Generalized-Schlick (metal) base: the GLSL sets
    R23p = R23s = F / 2 with F the RGB Hoffman-Schlick value, so I = F / 2 (halved), and it
    reads that RGB triple as XYZ: F_film = clip(M F / 2). MaterialX's own quirks, kept.
    """
    wi, wo = _pairs()
    film = {"thin_film_weight": 1.0, "thin_film_thickness": 0.4, "thin_film_ior": 1.0}
    base = {"base_color": [0.9, 0.6, 0.3], "specular_roughness": 0.3}
    np.testing.assert_allclose(
        open_pbr_brdf({**base, **film}, wi, wo), open_pbr_brdf(base, wi, wo), rtol=1e-6
    )
    metal = {**base, "base_metalness": 1.0}
    F0 = np.array(base["base_color"])
    F = F0 + (1.0 - F0) * ((1.0 - _cos_h(wi, wo)) ** 5)[:, None]
    expected = _specular(wi, wo, *_alphas(0.3, 0.0), np.clip(0.5 * F @ XYZ_TO_RGB.T, 0.0, 1.0))
    # R12 is 0 only to rounding (~1e-16), and the interference terms carry sqrt(R12): 1e-8
    np.testing.assert_allclose(open_pbr_brdf({**metal, **film}, wi, wo), expected, rtol=1e-7)


def test_weights_mix_linearly():
    """Without a coat, base_metalness, thin_film_weight and transmission_weight mix linearly.

    transmission_weight t: the transmission closures have no reflection response, so it only
    scales the opaque base: f(t) = f(base_weight = 1 - t) for a dielectric.
    """
    wi, wo = _pairs(200)
    base = {"base_color": [0.6, 0.3, 0.2], "specular_roughness": 0.4, "thin_film_thickness": 0.3,
            "fuzz_weight": 0.5, "base_diffuse_roughness": 0.5}  # fmt: skip
    for name, w in (("base_metalness", 0.3), ("thin_film_weight", 0.6)):
        f0, f1 = (open_pbr_brdf({**base, name: v}, wi, wo) for v in (0.0, 1.0))
        fw = open_pbr_brdf({**base, name: w}, wi, wo)
        np.testing.assert_allclose(fw, (1 - w) * f0 + w * f1, rtol=1e-10)
    np.testing.assert_allclose(
        open_pbr_brdf({**base, "transmission_weight": 0.35}, wi, wo),
        open_pbr_brdf({**base, "base_weight": 0.65}, wi, wo),
        rtol=EXACT,
    )


def test_white_furnace():
    """Albedos by quadrature: the compensated white metal keeps ~all energy (the Ess fit is
    good to ~2.5%); the white EON base under the index-matched dielectric has albedo exactly
    1 - B at normal view (no L there has L.V < 0) but more at grazing view: the GLSL clamps
    L.V to >= 1e-8, which lifts the EON single-scatter term where L.V < 0 (+15% at mu = 0.05).
    """
    grid = _quadrature()
    for mu in (0.2, 0.6, 0.95):
        for r in (0.5, 0.8):
            metal = _albedo({"base_metalness": 1.0, "base_color": 1.0, "specular_roughness": r},
                            mu, grid)  # fmt: skip
            np.testing.assert_allclose(metal, 1.0, atol=0.025)
    eon = {"specular_weight": 0.0, "base_color": 1.0, "base_diffuse_roughness": 1.0}
    dark = lambda mu: 1.0 - _ggx_dir_albedo(np.array([mu]), 0.09, 0.0, 1.0)[0, 0]  # noqa: E731
    np.testing.assert_allclose(_albedo(eon, 1.0, grid), dark(1.0), rtol=1e-4)
    assert _albedo(eon, 0.05, grid)[0] > 1.1 * dark(0.05)


def test_fuzz_reflects_what_it_takes():
    """Zeltner sheen layer: base x (1 - E(mu_o)), plus color E(mu_o) D_ltc(L) with D_ltc of
    unit integral, so the energy taken from the base equals the fuzz's own albedo."""
    grid = _quadrature(48, 96)
    wi = grid[0]
    for mu, r in ((0.3, 0.3), (0.7, 0.8)):
        wo = np.tile([np.sqrt(1.0 - mu * mu), 0.0, mu], (len(wi), 1))
        base = {"base_color": [0.5, 0.3, 0.2], "specular_roughness": 0.6, "fuzz_roughness": r}
        fuzz_black = {**base, "fuzz_weight": 1.0, "fuzz_color": 0.0}
        taken = 1.0 - evaluate(fuzz_black, wi, wo) / evaluate(base, wi, wo)
        assert np.ptp(taken) < EXACT and taken[0, 0] > 1e-3
        given = _albedo({**base, "fuzz_weight": 1.0, "fuzz_color": 1.0}, mu, grid)
        given -= _albedo(fuzz_black, mu, grid)
        np.testing.assert_allclose(given, taken[0, 0], rtol=1e-6)


FULL = {"base_color": [0.8, 0.5, 0.2], "base_metalness": 0.3, "base_diffuse_roughness": 0.5,
        "specular_roughness": 0.4, "specular_roughness_anisotropy": 0.3,
        "specular_color": [0.9, 0.7, 0.8], "coat_weight": 0.6, "coat_roughness": 0.2,
        "coat_color": [0.9, 0.8, 0.7], "fuzz_weight": 0.5, "fuzz_color": [0.2, 0.9, 0.3],
        "thin_film_weight": 0.5, "thin_film_thickness": 0.4, "subsurface_weight": 0.3}  # fmt: skip


def test_reciprocal_only_at_equal_elevations():
    """Every asymmetry of the GLSL enters through mu_o alone (energy compensation, the
    throughput of the layers above, the LTC frame), so f(wi, wo) = f(wo, wi) when wi.z = wo.z,
    and not otherwise."""
    rng = np.random.default_rng(RNG_SEED)
    wi = _dirs(rng, 300)
    phi = rng.uniform(0.0, 2.0 * np.pi, len(wi))
    c, s = np.cos(phi), np.sin(phi)
    wo = np.stack([c * wi[:, 0] - s * wi[:, 1], s * wi[:, 0] + c * wi[:, 1], wi[:, 2]], axis=1)
    np.testing.assert_allclose(open_pbr_brdf(FULL, wi, wo), open_pbr_brdf(FULL, wo, wi), rtol=1e-9)
    wi, wo = _pairs(300)
    asym = np.abs(open_pbr_brdf(FULL, wi, wo) / open_pbr_brdf(FULL, wo, wi) - 1.0)
    assert asym.max() > 0.05


def test_positive_finite_and_zero_below_the_horizon():
    rng = np.random.default_rng(RNG_SEED + 1)
    nodedef = library().getNodeDef(NODEDEF)
    wi, wo = rng.normal(size=(2, 500, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    below = (wi[:, 2] <= 0) | (wo[:, 2] <= 0)
    for _ in range(6):
        inputs = {}
        for p in nodedef.getActiveInputs():  # floats over their UI (soft) range
            if p.getType() == "float":
                lo = float(p.getAttribute("uisoftmin") or p.getAttribute("uimin") or 0.0)
                hi = float(p.getAttribute("uisoftmax") or p.getAttribute("uimax") or 1.0)
                inputs[p.getName()] = rng.uniform(lo, hi)
            elif p.getType() == "color3":
                inputs[p.getName()] = rng.uniform(0.0, 1.0, 3)
        f = open_pbr_brdf(inputs, wi, wo)
        assert np.all(np.isfinite(f)) and np.all(f >= 0.0) and np.all(f[below] == 0.0)
        assert np.all(f[~below].max(axis=1) > 0.0)


def _rewired(edit):
    doc = mx.createDocument()
    doc.copyContentFrom(library())
    edit(doc.getNodeDef(NODEDEF).getImplementation())
    return doc


def test_the_interpreter_follows_the_wires():
    """Rewiring the library graph changes the answer; an untouched copy does not."""
    wi, wo = _pairs(100)
    f = evaluate(FULL, wi, wo)
    np.testing.assert_array_equal(evaluate(FULL, wi, wo, document=_rewired(lambda g: None)), f)
    edits = [
        lambda g: g.getNode("base_substrate").getInput("mix").setInterfaceName("coat_weight"),
        lambda g: g.getNode("two_times_coat_roughness_to_power_4")
        .getInput("in2")
        .setValueString("3.0"),
        lambda g: g.getNode("fuzz_layer").getInput("base").setNodeName("dielectric_base"),
    ]  # fmt: skip
    for edit in edits:
        changed = evaluate(FULL, wi, wo, document=_rewired(edit))
        assert np.max(np.abs(changed / f - 1.0)) > 1e-3


def test_generator_mix_rewrite_is_the_mix_node_for_weights_in_range():
    """premultipliedBsdfAdd (what the GLSL generator emits) equals mx_mix_bsdf on [0, 1]."""
    wi, wo = _pairs(200)
    a = evaluate(FULL, wi, wo)
    np.testing.assert_allclose(evaluate(FULL, wi, wo, premultiplied_add=False), a, rtol=EXACT)
    out_of_range = {**FULL, "base_metalness": 1.3}
    b = evaluate(out_of_range, wi, wo, premultiplied_add=False)
    assert not np.allclose(evaluate(out_of_range, wi, wo), b)
