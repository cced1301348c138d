"""Rows of group c: the Disney 2012 BRDF (every static option on and off) and Brady 2014."""

from __future__ import annotations

from brdffit import models
from tests.cases import Case

_OFF = dict(
    subsurface=False,
    sheen=False,
    clearcoat=False,
    anisotropic=False,
    metallic=False,
    specular_tint=False,
)
_DISNEY = {  # every Disney parameter, inside its bounds
    "base_color": [0.8, 0.5, 0.2], "metallic": 0.3, "subsurface": 0.4, "specular": 0.6,
    "roughness": 0.4, "specular_tint": 0.3, "anisotropic": 0.5, "sheen": 0.4,
    "sheen_tint": 0.6, "clearcoat": 0.5, "clearcoat_gloss": 0.7,
}  # fmt: skip


def _disney(not_identifiable: dict | None = None, **on: bool) -> Case:
    """A Disney row with the features in ``on`` switched on and the others off."""
    names = {p.name for p in models.get("disney", **{**_OFF, **on}).parameters}
    params = {k: v for k, v in _DISNEY.items() if k in names}
    return Case("disney", {**_OFF, **on}, params, not_identifiable or {})


_TINT_METAL = (
    "with metallic: F0 = A + B C per channel, so (base_color, metallic, specular, "
    "specular_tint) fix only C (1 - metallic), A, B; a one-parameter family fits equally"
)
_GREY = "grey base colour: C_tint = 1, the tint mix is the identity"

ROWS: list[Case] = [
    Case("disney", {}, _DISNEY, not_identifiable={"specular_tint": _TINT_METAL}),
    Case(
        "disney",
        {},
        {**_DISNEY, "base_color": [0.5, 0.5, 0.5]},
        not_identifiable={
            "specular_tint": _GREY,
            "sheen_tint": _GREY,
            "metallic": "grey base colour: diffuse C (1 - metallic) and grey F0 = .08 specular "
            "(1 - metallic) + metallic C are two numbers for C, metallic, specular",
        },
    ),
    _disney(),
    _disney(anisotropic=True),
    _disney({"specular_tint": _TINT_METAL}, metallic=True, specular_tint=True),
    _disney(subsurface=True),
    _disney(sheen=True, clearcoat=True),
    Case(
        "brady",
        params={"kd": [0.1, 0.2, 0.3], "ks": [2.0, 1.5, 1.0], "f0": 0.1, "beta": 0.4},
    ),
    Case("brady", params={"ks": [30.0, 20.0, 10.0], "beta": 0.2, "exponent": 2.0}),
    Case("brady", params={"kd": [0.5, 0.4, 0.3], "beta": 0.8, "exponent": 0.5}),
]
