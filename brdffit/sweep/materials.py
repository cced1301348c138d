"""A sweep's materials: the lists a sweep is given (files of a folder, synthetic
recipes), their families, and each one's measurements (:func:`load_material`).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brdffit import models
from brdffit.errors import SweepError
from brdffit.io.load import load_measurements
from brdffit.io.synthetic import synthesize
from brdffit.selection.families import family_of

# Synthetic material recipes: (family word, model, parameter sampler).
_SYNTH = (
    ("plastic", "walter"),
    ("metal", "walter"),
    ("fabric", "oren_nayar"),
    ("paint", "blinn_phong"),
)


@dataclass(frozen=True)
class Material:
    """One material of a sweep.

    ``kind`` is ``"merl"``, ``"nbrdf"``, ``"rgl"``, ``"table"`` (``path`` the file) or
    ``"synthetic"`` (``spec``: generating model, parameters, noise and seed).
    """

    name: str
    family: str
    kind: str
    path: str | None = None
    spec: dict | None = None


def _folder_materials(
    folder: str | os.PathLike[str], kind: str, pattern: str | tuple[str, ...], names
):
    d = Path(folder)
    if not d.is_dir():
        raise SweepError(f"{d}: not a folder of {kind} files")
    patterns = (pattern,) if isinstance(pattern, str) else pattern
    files = [p for pat in patterns for p in sorted(d.glob(pat))]
    found = {p.stem: p for p in files}
    if len(found) < len(files):
        raise SweepError(f"{d}: two {kind} files share a name stem; rename one")
    pattern = " or ".join(patterns)
    if names:
        missing = [n for n in names if n not in found]
        if missing:
            raise SweepError(f"{d}: no {kind} material named {', '.join(missing)}")
        found = {n: found[n] for n in names}
    if not found:
        raise SweepError(f"{d}: no {pattern} files")
    return [Material(n, family_of(n), kind, str(p.resolve())) for n, p in found.items()]


def merl_materials(folder: str | os.PathLike[str], names: Sequence[str] | None = None):
    """Materials from the ``*.binary`` files of ``folder`` (``names``: pick some stems)."""
    return _folder_materials(folder, "merl", "*.binary", names)


def nbrdf_materials(folder: str | os.PathLike[str], names: Sequence[str] | None = None):
    """Materials from the NBRDF networks (``*.json`` + ``*.h5``) of ``folder``."""
    return _folder_materials(folder, "nbrdf", "*.json", names)


def rgl_materials(folder: str | os.PathLike[str], names: Sequence[str] | None = None):
    """Materials from the RGL-EPFL ``*.bsdf`` files of ``folder`` (:mod:`brdffit.io.rgl`)."""
    return _folder_materials(folder, "rgl", "*.bsdf", names)


def table_materials(folder: str | os.PathLike[str], names: Sequence[str] | None = None):
    """Materials from the sample tables (``*.csv``, ``*.npz``; :mod:`brdffit.io.table`) of
    ``folder``; a table is fitted as it is, whatever the sweep's ``stride``."""
    return _folder_materials(folder, "table", ("*.csv", "*.npz"), names)


def synthetic_materials(n: int, *, seed: int = 0, noise_mult: float = 0.03) -> list[Material]:
    """``n`` synthetic materials cycling plastic, metal, fabric, paint, seeded parameters.

    Plastic: Walter/GGX, kd U(0.05, 0.6), f0 0.04, alpha log-U(0.05, 0.3), grey specular
    weight ks U(0.6, 1); metal: Walter, kd U(0, 0.03), f0 U(0.5, 0.95), alpha
    log-U(0.03, 0.2), ks 1; fabric: Oren-Nayar, rho
    U(0.1, 0.7), sigma U(0.2, 0.8); paint: Blinn-Phong, kd U(0.1, 0.6), ks U(0.02, 0.2),
    n log-U(10, 500). Log-normal noise ``noise_mult``; material i uses seed ``seed + i``.
    """
    if n < 1:
        raise SweepError(f"--synthetic {n}: need at least 1 material")
    out = []
    for i in range(n):
        word, model = _SYNTH[i % len(_SYNTH)]
        rng = np.random.default_rng(seed + i)
        u = rng.uniform

        def logu(a: float, b: float, rng=rng) -> float:
            return float(np.exp(rng.uniform(np.log(a), np.log(b))))

        if word == "plastic":
            params = {"kd": u(0.05, 0.6, 3).tolist(), "f0": [0.04] * 3, "alpha": logu(0.05, 0.3)}
            params["ks"] = [float(u(0.6, 1.0))] * 3
        elif word == "metal":
            params = {"kd": u(0, 0.03, 3).tolist(), "f0": u(0.5, 0.95, 3).tolist()}
            params["alpha"] = logu(0.03, 0.2)
            params["ks"] = [1.0] * 3
        elif word == "fabric":
            params = {"rho": u(0.1, 0.7, 3).tolist(), "sigma": float(u(0.2, 0.8))}
        else:
            params = {"kd": u(0.1, 0.6, 3).tolist(), "ks": u(0.02, 0.2, 3).tolist()}
            params["n"] = logu(10.0, 500.0)
        spec = {"model": model, "params": params, "noise_mult": noise_mult, "seed": seed + i}
        name = f"syn{i:02d}-{word}"
        out.append(Material(name, family_of(name), "synthetic", None, spec))
    return out


def with_families(materials: Sequence[Material], families: dict[str, str]) -> list[Material]:
    """``materials`` with the families of ``families`` (material -> family, e.g. from
    :func:`brdffit.selection.families.read_families`) replacing the guessed ones it names."""
    return [dataclasses.replace(m, family=families.get(m.name, m.family)) for m in materials]


def load_material(material: Material, stride: tuple[int, int, int]):
    """The :class:`Measurements` of ``material`` on the MERL grid of ``stride``."""
    if material.kind == "synthetic":
        s = material.spec
        return synthesize(
            models.get(s["model"]),
            s["params"],
            stride=stride,
            noise_mult=s["noise_mult"],
            seed=s["seed"],
            source=f"synthetic {material.name} ({s['model']})",
        )
    return load_measurements(material.path, stride=1 if material.kind == "table" else stride)
