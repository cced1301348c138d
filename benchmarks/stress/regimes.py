"""Regimes of the stress suite, the models' roles and the suite's constants."""

from __future__ import annotations

from dataclasses import dataclass, field

from tests.cases import params_of

N_STARTS = 20
N_SAMPLES = 2000
REL_TOL = 1e-6
ABS_TOL = 1e-10
NEAR_MIRROR = 1e-3
EXPONENT_RANGE = (1e4, 1e5)
DYNAMIC_RANGE = 1e7
RECOVERY_TARGET = 0.95
DEFAULT_METRICS = ("low_e2", "ngan")
MAX_STEPS = 512  # LM steps per descent: brdffit.fit's default
STALL_DISTANCE = 0.1  # optimiser-space distance under which a converged miss is a stall
START_U = 3.0  # random starts: u ~ U(-START_U, START_U) in each parameter's optimiser space


@dataclass(frozen=True)
class Regime:
    """One stress regime: how it changes the truth, the data and the fit.

    Fields: ``name``, ``description``; truth: ``roughness`` (set the lobe width to this
    roughness, ``alpha`` units; ``"near_mirror"`` also draws Phong-type exponents in
    :data:`EXPONENT_RANGE`), ``dynamic_range`` (scale the diffuse parameter so that the
    specular peak over the diffuse floor is this), ``at_bounds`` (albedo channels on
    their bounds), ``correlated`` (multi-lobe models, or a broad lobe); data:
    ``directions`` (``"rusinkiewicz"`` or ``"grazing"``), ``noise_mult`` (log-normal),
    ``missing`` (fraction of cells invalid), ``outliers`` (fraction of cells multiplied
    by ``outlier_factor``), ``float32`` (data made by the model evaluated in float32;
    the fit itself runs in float64, as :class:`Measurements` holds float64); fit:
    ``cut_deg`` and ``robust``.
    """

    name: str
    description: str
    roughness: float | None = None
    near_mirror: bool = False
    dynamic_range: float | None = None
    at_bounds: bool = False
    correlated: bool = False
    directions: str = "rusinkiewicz"
    cut_deg: float | None = 80.0
    noise_mult: float = 0.0
    missing: float = 0.0
    outliers: float = 0.0
    outlier_factor: float = 100.0
    robust: str | None = None
    float32: bool = False

    @property
    def needs_lobe(self) -> bool:
        """True when the regime changes a specular lobe (not applicable without one)."""
        return self.near_mirror or self.roughness is not None or self.dynamic_range is not None


REGIMES: dict[str, Regime] = {
    r.name: r
    for r in (
        Regime("baseline", "moderate roughness, noise-free, cut 80"),
        Regime(
            "near_mirror",
            f"roughness {NEAR_MIRROR:g}; Phong-type exponents log-uniform in "
            f"[{EXPONENT_RANGE[0]:g}, {EXPONENT_RANGE[1]:g}]",
            roughness=NEAR_MIRROR,
            near_mirror=True,
        ),
        Regime("fully_rough", "roughness 1 (exponents 2)", roughness=1.0),
        Regime(
            "dynamic_range",
            f"roughness 0.01 and diffuse scaled so that peak / diffuse floor = {DYNAMIC_RANGE:g}",
            roughness=0.01,
            dynamic_range=DYNAMIC_RANGE,
        ),
        Regime(
            "grazing_cut80",
            "80% of directions beyond 60 degrees, cut 80",
            directions="grazing",
        ),
        Regime(
            "grazing_nocut",
            "80% of directions beyond 60 degrees, no cut",
            directions="grazing",
            cut_deg=None,
        ),
        Regime("noise30", "30% multiplicative log-normal noise", noise_mult=0.3),
        Regime("missing_half", "half the cells invalid", missing=0.5),
        Regime("outliers", "1% of cells x100, plain least squares", outliers=0.01),
        Regime("outliers_huber", "1% of cells x100, Huber loss", outliers=0.01, robust="huber"),
        Regime(
            "at_bounds",
            "albedo channels on bounds: 1st RGB parameter [0] low and [2] high, 2nd [1] low",
            at_bounds=True,
        ),
        Regime(
            "correlated",
            "two lobes (Lafortune, Kurt); else a broad lobe (roughness 0.5) against the albedo",
            correlated=True,
        ),
        Regime("float32", "data from the model evaluated in float32", float32=True),
    )
}


@dataclass(frozen=True)
class Roles:
    """What the stress regimes need to know about one model.

    Fields: ``truth`` baseline parameters (natural units; others take defaults);
    ``rough`` the lobe-width parameter and ``kind`` its mapping (module docstring);
    ``diffuse`` the diffuse albedo parameter; ``freeze`` parameters frozen at the truth
    (not identifiable, with the reason, as declared in ``tests/cases*.py``);
    ``two_lobes`` (options, truth) for the correlated regime; ``floor_zero`` parameters
    set to 0 in the dynamic-range regime so that the diffuse parameter scales the diffuse
    term only (Disney's metallic and tint, Filament's metallic), and frozen there: with
    the base colour at 1e-5, metallic moves only F0, which ``specular``/``reflectance``
    also set, and the diffuse scale, which the base colour also sets (a ridge: the fits
    reached the minimum's cost along it and crawled); ``narrow`` parameters set when the
    lobe exponent exceeds 1e3 (Lafortune's ``cxy = -1``: with ``|cxy| > 1`` the lobe
    grows as ``|cxy|^n`` towards grazing, 1e1000 at ``n = 1e4``, far past float64 (the
    model returns ``+inf`` there); no material does that);
    ``alpha_floor`` the narrowest lobe (``alpha``) the model evaluates, and ``narrow``
    then applies at near-mirror too: Disney clamps each axis at ``alpha = 0.001``, so its
    near-mirror truth is isotropic with ``alpha = 1.1e-3``. At ``alpha = 1e-3`` with
    anisotropic 0.53 the narrow axis sat on the clamp and the specular lobe fixed only
    ``roughness^2 / aspect``; roughness was left to the diffuse retro-reflection term,
    no start (of 20, either metric) recovered, and the traced low_e2 fit crawled along
    that curved valley.
    """

    truth: dict
    rough: str | None = None
    kind: str | None = None
    diffuse: str | None = None
    freeze: dict = field(default_factory=dict)
    two_lobes: tuple[dict, dict] | None = None
    floor_zero: tuple[str, ...] = ()
    narrow: dict = field(default_factory=dict)
    alpha_floor: float = 0.0


_DISNEY_TINT = (
    "with metallic on, F0 = A + B C per channel: base_color, metallic, specular and "
    "specular_tint fix only C (1 - metallic), A and B (tests/cases_c.py)"
)

ROLES: dict[str, Roles] = {
    "ashikhmin_shirley": Roles(
        {"rd": [0.5, 0.3, 0.2], "rs": [0.1, 0.2, 0.3], "n": 300.0}, "n", "exponent", "rd"
    ),
    "blinn_phong": Roles(
        {"kd": [0.2, 0.3, 0.4], "ks": [0.3, 0.2, 0.1], "n": 120.0}, "n", "exponent", "kd"
    ),
    "brady": Roles(
        {"kd": [0.1, 0.2, 0.3], "ks": [2.0, 1.5, 1.0], "f0": 0.1, "beta": 0.4},
        "beta",
        "squared",
        "kd",
    ),
    "cook_torrance": Roles(
        {"kd": [0.1, 0.2, 0.3], "ks": [0.8, 0.7, 0.6], "f0": [0.9, 0.6, 0.3], "m": 0.2},
        "m",
        "width",
        "kd",
    ),
    "course_cook_torrance": Roles(
        {"albedo": [0.7, 0.4, 0.2], "f0": [0.04, 0.05, 0.06], "roughness": 0.4},
        "roughness",
        "squared",
        "albedo",
    ),
    "disney": Roles(
        {
            "base_color": [0.8, 0.5, 0.2],
            "metallic": 0.3,
            "subsurface": 0.4,
            "specular": 0.6,
            "roughness": 0.4,
            "specular_tint": 0.3,
            "anisotropic": 0.5,
            "sheen": 0.4,
            "sheen_tint": 0.6,
            "clearcoat": 0.5,
            "clearcoat_gloss": 0.7,
        },
        "roughness",
        "squared",
        "base_color",
        freeze={"specular_tint": _DISNEY_TINT},
        floor_zero=("metallic", "specular_tint"),
        narrow={"anisotropic": 0.0},
        alpha_floor=1e-3,
    ),
    "filament": Roles(
        {"base_color": [0.8, 0.5, 0.2], "metallic": 0.3, "reflectance": 0.6, "roughness": 0.4},
        "roughness",
        "squared",
        "base_color",
        floor_zero=("metallic",),
    ),
    "gltf": Roles(
        {
            "base_color": [0.8, 0.5, 0.2],
            "metallic": 0.3,
            "roughness": 0.4,
            "specular": 0.8,
            "specular_f0": [0.04, 0.05, 0.06],
        },
        "roughness",
        "squared",
        "base_color",
        floor_zero=("metallic",),
    ),
    "kurt": Roles(
        {"kd": [0.2, 0.1, 0.05], "ks_1": [0.6, 0.5, 0.4], "f0_1": 0.3, "m_1": 0.2, "alpha_1": 0.3},
        "m_1",
        "width",
        "kd",
        two_lobes=({"n_lobes": 2}, params_of("kurt", n_lobes=2)),
    ),
    "lafortune": Roles(
        {"kd": [0.1, 0.2, 0.3], "rho_1": [0.5, 0.4, 0.3], "cxy_1": -1.2, "n_1": 30.0},
        "n_1",
        "exponent",
        "kd",
        narrow={"cxy_1": -1.0},
        two_lobes=({"n_lobes": 2}, params_of("lafortune", n_lobes=2)),
    ),
    # He et al.: the lobe's slope is 2 sigma / tau and sigma / lambda decides between the
    # series and its rough limit, so no one parameter is "the roughness" the lobe regimes
    # set; the truth is a moderate lobe (slope 0.04; g = 1-2 at normal incidence, the series).
    "he": Roles(
        {"kd": [0.1, 0.2, 0.3], "ks": [0.5, 0.4, 0.3], "sigma": 0.05, "tau": 2.5, "eta": 1.5},
        diffuse="kd",
    ),
    "lambert": Roles({"kd": [0.2, 0.5, 0.8]}, diffuse="kd"),
    "low": Roles(
        {"kd": [0.1, 0.2, 0.3], "ks": [0.5, 0.4, 0.3], "B": 500.0, "C": 1.3, "eta": 1.6},
        "B",
        "exponent",
        "kd",
    ),
    "nishino_lombardi": Roles(
        {"kd": [0.3, 0.2, 0.1], "ks": [0.8, 0.7, 0.6], "f0": [0.9, 0.7, 0.5], "k": 3.0, "m": 200.0},
        "m",
        "exponent",
        "kd",
    ),
    "openpbr": Roles(  # MaterialX's OpenPBR, default options (tests/cases_j.py's core row)
        {
            "base_color": [0.8, 0.5, 0.2],
            "base_metalness": 0.3,
            "base_diffuse_roughness": 0.6,
            "specular_weight": 0.7,
            "specular_color": [0.9, 0.7, 0.8],
            "specular_roughness": 0.35,
            "specular_ior": 1.7,
        },
        "specular_roughness",
        "squared",
        "base_color",
        floor_zero=("base_metalness",),
    ),
    "oren_nayar": Roles({"rho": [0.3, 0.5, 0.8], "sigma": 0.4}, "sigma", "sigma", "rho"),
    "phong": Roles(
        {"kd": [0.2, 0.3, 0.4], "ks": [0.3, 0.2, 0.1], "n": 80.0}, "n", "exponent", "kd"
    ),
    "principled": Roles(  # Mitsuba's plugin, default options; alpha clamped at 0.001 as Disney
        {"base_color": [0.8, 0.5, 0.2], "metallic": 0.3, "roughness": 0.4, "specular": 0.6},
        "roughness",
        "squared",
        "base_color",
        floor_zero=("metallic",),
        alpha_floor=1e-3,
    ),
    "sgd": Roles(
        # alpha is a slope variance (Beckmann's m^2), mapped as a width: the near-mirror
        # regime then has m = 0.03 (alpha 1e-3); m = 1e-3 would need alpha 1e-6, below
        # the table's bound of 1e-5
        {"kd": [0.1, 0.2, 0.3], "ks": [0.3, 0.25, 0.2], "f0": [0.6, 0.4, 0.2], "alpha": 0.05},
        "alpha",
        "width",
        "kd",
    ),
    "std": Roles(
        {"kd": [0.1, 0.2, 0.3], "ks": [0.8, 0.7, 0.6], "alpha": 0.15, "gamma": 3.0},
        "alpha",
        "width",
        "kd",
    ),
    "walter": Roles(
        {"kd": [0.1, 0.2, 0.3], "ks": [0.8, 0.7, 0.6], "f0": [0.9, 0.6, 0.3], "alpha": 0.15},
        "alpha",
        "width",
        "kd",
    ),
    "ward": Roles(
        {"kd": [0.2, 0.3, 0.4], "ks": [0.1, 0.1, 0.1], "alpha": 0.15}, "alpha", "width", "kd"
    ),
}

NOT_IDENTIFIABLE: dict[tuple[str, str], str] = {}
"""(model, regime) -> why the case has no unique optimum even in principle, declared;
:func:`score` also finds cases whose data move the optimum (:func:`_optimum_moved`)."""
