"""Mitsuba 3 XML of a BSDF dict: the form ``mi.load_string`` reads and scene files hold.

``{"type": "diffuse", "reflectance": {"type": "rgb", "value": [...]}}`` becomes
``<bsdf type="diffuse"><rgb name="reflectance" value="r, g, b"/></bsdf>``; nested BSDFs
(``blendbsdf``'s ``bsdf_0``, ``bsdf_1``) become named child ``<bsdf>`` elements in order.
Numbers are written with 9 significant digits, enough to round-trip Mitsuba's float32.
"""

from __future__ import annotations

from collections.abc import Mapping


def _xml_value(name: str, v: object, pad: str) -> str:
    if isinstance(v, dict) and v.get("type") == "rgb":
        text = ", ".join(f"{x:.9g}" for x in v["value"])
        return f'{pad}<rgb name="{name}" value="{text}"/>'
    if isinstance(v, str):
        return f'{pad}<string name="{name}" value="{v}"/>'
    return f'{pad}<float name="{name}" value="{float(v):.9g}"/>'


def _xml_bsdf(d: Mapping[str, object], pad: str, head: str) -> list[str]:
    lines = [f'{pad}<bsdf {head}type="{d["type"]}">']
    for key, v in d.items():
        if key == "type":
            continue
        if isinstance(v, dict) and v.get("type") != "rgb":
            lines += _xml_bsdf(v, pad + "    ", f'name="{key}" ')
        else:
            lines.append(_xml_value(key, v, pad + "    "))
    return lines + [f"{pad}</bsdf>"]


def to_xml(bsdf: Mapping[str, object], ident: str = "brdffit", comment: str = "") -> str:
    """The Mitsuba 3 XML of a BSDF dict (``mi.load_string`` reads it; ``id`` is ``ident``)."""
    head = f"<!-- {comment} -->\n" if comment else ""
    body = _xml_bsdf(bsdf, "", f'version="3.0.0" id="{ident}" ')
    return head + "\n".join(body) + "\n"
