"""A sweep folder read back for the ranking and the Pareto study: manifest and results.

:func:`load_sweep` reads ``sweep.json`` and every result file
``<material>/<label>__<metric>[.error].json`` of a sweep folder (:mod:`brdffit.sweep`)
into a :class:`SweepResults` of :class:`Record` rows, one per fit; a result file that
does not parse is listed, not fatal. A model is named by its label
(:func:`brdffit.models.label`). Families come from a ``families`` mapping (a user's
file, :func:`brdffit.selection.families.read_families`), else the sweep manifest, else
:func:`brdffit.selection.families.family_of`.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

from brdffit.core.result_terms import per_sample
from brdffit.errors import SweepError
from brdffit.selection.families import family_of


@dataclass(frozen=True)
class Record:
    """One result file of a sweep, the fields the ranking and the Pareto study read.

    ``loss`` is the value of ``metric`` (the one fitted), ``losses`` every metric on
    the same samples; ``wall_time`` in s; ``eval_ns`` ns per sample (``nan`` if not
    timed); ``status`` the :class:`brdffit.Status` name; ``provenance`` a short label
    of the code and device that computed it (``"unrecorded"`` in older sweeps).
    ``model`` is the label of the fitted variant (``walter``, ``lafortune[n_lobes=2]``),
    the result file's ``label`` (older sweeps, default options only: its ``model``).
    """

    material: str
    family: str
    model: str
    metric: str
    loss: float
    losses: dict
    aic: float
    bic: float
    n_free: int
    converged: bool
    status: str
    wall_time: float
    eval_ns: float
    provenance: str = "unrecorded"
    loss_per_sample: float = math.nan


@dataclass(frozen=True)
class SweepResults:
    """A sweep folder read back: manifest, results (sorted), recorded errors, and the
    result files that could not be read (``unreadable``: (path relative to the folder,
    why) pairs; the report lists them and goes on without them)."""

    manifest: dict
    records: tuple[Record, ...]
    errors: tuple[dict, ...]
    families: dict = field(default_factory=dict)
    unreadable: tuple[tuple[str, str], ...] = ()

    @property
    def materials(self) -> list[str]:
        """Materials of the manifest, in its order."""
        return list(self.manifest["materials"])

    @property
    def models(self) -> list[str]:
        """Model labels of the manifest, in its order."""
        return list(self.manifest["models"])

    @property
    def metrics(self) -> list[str]:
        """Metrics of the manifest, in its order."""
        return list(self.manifest["metrics"])

    def family(self, material: str) -> str:
        """Family from ``families`` (a user's file), else the manifest, else the name."""
        if material in self.families:
            return self.families[material]
        m = self.manifest["materials"].get(material, {})
        return m.get("family") or family_of(material)


def provenance_label(d: dict | None) -> str:
    """``brdffit 0.1.0 (git f1ea536), jax 0.10.2 on cpu (cpu)`` from a result's provenance."""
    if not d:
        return "unrecorded"
    return (
        f"brdffit {d.get('brdffit')} (git {d.get('git')}), jax {d.get('jax')} "
        f"on {d.get('backend')} ({d.get('device')})"
    )


def _record_family(d: dict, families: dict[str, str]) -> str:
    return families.get(d["material"]) or d.get("family") or family_of(d["material"])


def _num(x: object) -> float:
    return float("nan") if x is None else float(x)


def load_sweep(
    sweep_dir: str | os.PathLike[str], families: dict[str, str] | None = None
) -> SweepResults:
    """Read ``sweep.json`` and every ``<material>/<label>__<metric>[.error].json``.

    ``families``: material -> family, replacing the recorded ones for those materials.
    A result file that does not parse or lacks a field (truncated, foreign) is skipped
    and listed in ``unreadable``. Raises :class:`SweepError` when ``sweep.json`` is
    missing or is not a sweep manifest, or when the folder holds result files and none
    of them could be read.
    """
    families = dict(families or {})
    root = Path(sweep_dir)
    try:
        manifest = json.loads((root / "sweep.json").read_text())
    except (OSError, ValueError) as e:
        raise SweepError(f"{root}: not a sweep folder (sweep.json: {e})") from e
    if not (
        isinstance(manifest, dict)
        and isinstance(manifest.get("materials"), dict)
        and isinstance(manifest.get("settings"), dict)
        and all(isinstance(manifest.get(k), dict | list) for k in ("models", "metrics"))
    ):
        raise SweepError(
            f"{root / 'sweep.json'}: not a sweep manifest (expected an object with "
            "materials, models, metrics and settings)"
        )
    records, errors, unreadable = [], [], []
    for p in sorted(root.glob("*/*.json")):
        try:
            d = json.loads(p.read_text())
            if not isinstance(d, dict):
                raise TypeError(f"a JSON {type(d).__name__}, not an object")
            if p.name.endswith(".error.json"):
                missing = [k for k in ("material", "model", "metric", "error") if k not in d]
                if missing:
                    raise KeyError(", ".join(missing))
                errors.append(d)
            else:
                records.append(_record(d, families))
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
            why = f"missing field {e}" if isinstance(e, KeyError) else str(e) or type(e).__name__
            unreadable.append((str(p.relative_to(root)), " ".join(why.split())))
    if unreadable and not records and not errors:
        names = ", ".join(f"{path} ({why})" for path, why in unreadable)
        raise SweepError(f"{root}: no result file could be read ({names})")
    return SweepResults(manifest, tuple(records), tuple(errors), families, tuple(unreadable))


def _record(d: dict, families: dict[str, str]) -> Record:
    """The :class:`Record` of a result file's JSON object (``KeyError`` for a missing
    field, ``ValueError``/``TypeError`` for a value of the wrong kind)."""
    for key in ("material", "metric"):
        if not isinstance(d[key], str):
            raise TypeError(f"field {key!r} is {d[key]!r}, not a string")
    return Record(
        material=d["material"],
        family=_record_family(d, families),
        model=str(d.get("label") or d["model"]),
        metric=d["metric"],
        loss=_num(d["loss"]),
        losses={k: _num(v) for k, v in d.get("losses", {}).items()},
        aic=_num(d.get("aic")),
        bic=_num(d.get("bic")),
        n_free=int(d.get("n_free", 0)),
        converged=bool(d.get("converged", False)),
        status=str(d.get("status", "")),
        wall_time=_num(d.get("wall_time")),
        eval_ns=_num(d.get("eval_ns_per_sample")),
        provenance=provenance_label(d.get("provenance")),
        loss_per_sample=per_sample(d["metric"], _num(d["loss"]), d.get("n_samples", 0)),
    )
