"""The public export functions: :func:`export` of a fit to one target, :func:`write_exports`
of it to every target's files, the target names (:data:`TARGETS`, :func:`parse_targets`,
:func:`check_targets`) and :func:`default_prefix`. How an export is measured and what it
writes: the package docstring (:mod:`brdffit.export`).

Which fit to export: a renderer lit by an environment shows, at each view ``wo``, the
directional albedo ``a(wo) = integral of f cos(theta_i) d(wi)``. By Cauchy-Schwarz the
solid-angle RMS over the views of ``a``'s error (inside the fit's cut) is at most
``Omega`` times ``ngan``'s loss, the solid-angle-weighted RMS error of ``f
cos(theta_i)`` (``Omega`` the solid angle of the incident directions inside the cut,
5.19 sr at 80 degrees); no such bound holds for the log metrics, which weigh the
highlight's shape over its energy. So a fit made for a renderer is best fitted
under ``ngan``; every export of a fit under another metric carries that note
(:func:`render_note`). Measured on 11 RGL-EPFL files (``benchmarks/render_check.py``,
white environment, against Mitsuba's ``measured`` plugin): fitted under ``ngan``, each
of the 4 matte files has a model that renders within 0.10 relative RMSE and 10% per
channel, and the best env error falls on all 11 files; under ``low_e2`` the green felt
had none.
"""

from __future__ import annotations

import types
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from brdffit import models
from brdffit.core.abstract_model import eval_compiled
from brdffit.core.result import FitResult
from brdffit.errors import ExportError, ExportValueError
from brdffit.export import _numbers, gltf, materialx, mitsuba
from brdffit.export._match import (
    ERROR_DEFINITION,
    Match,
    albedo_directions,
    best,
    error_directions,
    match,
)
from brdffit.models._restrict import Restricted, base_of
from brdffit.util.atomic import write_text

TARGETS: dict[str, types.ModuleType] = {"mitsuba": mitsuba, "gltf": gltf, "materialx": materialx}
"""Target name -> module with ``candidates(model, params)`` and ``finish(...)``."""

RENDER_METRIC = "ngan"
"""The metric whose loss bounds the error of a render under an environment (module
docstring)."""


def render_note(metric: str) -> str | None:
    """The note an export of a fit under ``metric`` carries when that metric is not
    :data:`RENDER_METRIC` (module docstring), else ``None``."""
    if metric == RENDER_METRIC:
        return None
    return (
        f"fitted under {metric}, which does not weigh f cos(theta_i) by solid angle as a "
        f"renderer integrates it; for renders, refit with metric {RENDER_METRIC!r} "
        "(its loss bounds the error of the directional albedo)"
    )


@dataclass(frozen=True, eq=False)
class Export:
    """A fitted material written for one renderer, and how faithful it is.

    Fields: ``target`` (``"mitsuba"``, ``"gltf"``, ``"materialx"``); ``model`` (the
    fitted model's label); ``target_model`` (exactly what was written: the Mitsuba BSDF tree,
    ``"blendbsdf(diffuse, roughconductor[distribution=ggx])"``, the glTF material and its
    extensions, the OpenPBR surface);
    ``exact`` (measured error <= ``EXACT_TOL``); ``error`` (relative RMS of ``f cos_i``)
    and ``log_error`` (RMS of ``ln(1 + f cos_i)`` differences), :data:`ERROR_DEFINITION`;
    ``fitted`` (the target's parameters were fitted by least
    squares rather than mapped in closed form); ``albedo_error`` (RMS relative error of
    the directional albedo per channel at 4 views, :func:`~brdffit.export._match.albedo_error`;
    0 for an exact export, where it is not measured); ``notes`` (roughness convention, what is
    lost); ``material`` (the Mitsuba dict, the glTF document, the OpenPBR inputs);
    ``files`` (file suffix -> text, what :func:`write_exports` writes).
    """

    target: str
    model: str
    target_model: str
    exact: bool
    error: float
    log_error: float
    fitted: bool
    albedo_error: float
    notes: tuple[str, ...]
    material: dict
    files: dict[str, str]

    def summary(self) -> str:
        """One line: target, exact or approximate, the error and what was written."""
        kind = "exact" if self.exact else "approximate" + (" (fitted)" if self.fitted else "")
        return (
            f"{self.target}: {kind}, relative RMS error of f cos(theta_i) {self.error:.3g}, "
            f"log error {self.log_error:.3g}, albedo error {self.albedo_error:.3g} "
            f"({self.model} -> {self.target_model})"
        )


def parse_targets(text: str | Iterable[str]) -> tuple[str, ...]:
    """``"mitsuba,gltf"`` (or a sequence) -> checked target names, in order, no repeats.

    Raises :class:`ExportError` naming an unknown target and listing :data:`TARGETS`.
    """
    items = text.split(",") if isinstance(text, str) else list(text)
    out: list[str] = []
    for t in (s.strip().lower() for s in items):
        if not t:
            continue
        if t not in TARGETS:
            raise ExportError(f"export target {t!r} unknown; choose from {', '.join(TARGETS)}")
        if t not in out:
            out.append(t)
    if not out:
        raise ExportError(f"no export target given; choose from {', '.join(TARGETS)}")
    return tuple(out)


def check_targets(model: object, targets: str | Iterable[str]) -> tuple[str, ...]:
    """The checked target names (:func:`parse_targets`), so that the command line refuses
    a bad ``--export`` before it fits. Every target takes every model (``model``, a built
    model, is accepted for that reason and not read): a form without an exact mapping is
    fitted and its error measured."""
    del model
    return parse_targets(targets)


def default_prefix(input_path: str | Path, json_path: str | Path | None, label: str) -> Path:
    """Where ``brdffit fit --export`` writes without ``--export-prefix``.

    ``json_path`` without its suffix when given (``out/fit.json`` -> ``out/fit``), else
    the input file's stem and the model label in the current folder
    (``blue-acrylic.binary``, ``walter`` -> ``blue-acrylic.walter``).
    """
    if json_path:
        return Path(json_path).with_suffix("")
    safe = "".join(c if c.isalnum() or c in "_-=+" else "_" for c in label).strip("_")
    return Path(f"{Path(input_path).stem}.{safe}")


evaluate_model = eval_compiled
"""``model.eval(params, wi, wo)`` compiled once per model and options, then reused for
every parameter value (an export evaluates the model at 2,556 pairs). f in 1/sr, (N, 3)."""


@dataclass(frozen=True, eq=False)
class _Prepared:
    """A fit made ready for every target: the base model, its full RGB parameters, its
    values ``f_model`` (N, 3, 1/sr) at the error directions ``wi``, ``wo`` and
    ``albedo`` at :func:`~brdffit.export._match.albedo_directions`."""

    result: FitResult
    base: object
    params: dict[str, np.ndarray]
    f_model: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    albedo: np.ndarray


def _prepare(result: FitResult) -> _Prepared:
    """Evaluate the fitted model once at :func:`error_directions` (shared by all targets).

    Raises :class:`~brdffit.errors.ExportValueError` naming a non-finite parameter, or
    saying that the model's values are not finite at the fitted parameters.
    """
    _numbers.require_finite("the fit's parameter", result.params)
    wi, wo = error_directions()
    a_wi, a_wo = albedo_directions()
    model = models.model_of(result)
    params = {k: np.asarray(v, float) for k, v in result.params.items()}
    both = evaluate_model(model, params, np.vstack([wi, a_wi]), np.vstack([wo, a_wo]))
    f = np.asarray(both, float)  # one compiled call for both direction sets
    bad = ~np.isfinite(f)
    if bad.any():
        raise ExportValueError(
            "f",
            float(f[bad][0]),
            f"{models.label(result.model, result.options)} is not finite at the fitted "
            f"parameters ({int(bad.any(axis=1).sum())} of {len(f)} direction pairs, e.g. "
            f"{float(f[bad][0])}); a renderer cannot be given a material that the model "
            "itself cannot evaluate",
        )
    if isinstance(model, Restricted):
        params = model.expand({k: jnp.asarray(v) for k, v in params.items()})
    params = {k: np.array(v, float) for k, v in params.items()}
    return _Prepared(result, base_of(model), params, f[: len(wi)], wi, wo, f[len(wi) :])


def _choose(module: types.ModuleType, prep: _Prepared, fit: bool) -> tuple[Match, list[str]]:
    """The candidate with an exact start, else the one with the least log error after
    least squares (``fit``) or as mapped; and one note listing every candidate's errors."""
    starts = module.candidates(prep.base, prep.params)
    args = (prep.f_model, prep.wi, prep.wo)
    first = [match(fam, start, *args, fit=False) for fam, start in starts]
    exact = [m for m in first if m.exact]
    if exact:
        return exact[0], []
    with_albedo = {"albedo": prep.albedo}
    if fit:
        tried = [match(*s, *args, **with_albedo) for s in starts]
    else:
        tried = [match(*s, *args, fit=False, **with_albedo) for s in starts]
    chosen = best(tried)
    if len(tried) > 1:
        text = "; ".join(
            f"{m.family.name} {m.error:.3g} / {m.log_error:.3g} / {m.albedo_error:.3g}"
            for m in tried
        )
        return chosen, [
            f"candidates (error / log error / albedo error): {text}; kept the least "
            "log error + albedo error"
        ]
    return chosen, []


def _export(prep: _Prepared, name: str, fit: bool = True) -> Export:
    """:func:`export` of a prepared fit to the checked target ``name``."""
    module = TARGETS[name]
    chosen, tried = _choose(module, prep, fit)
    chosen = _numbers.writable(chosen, prep.f_model, prep.wi, prep.wo, prep.albedo)
    material, files, notes = module.finish(prep.result, prep.base, chosen)
    _numbers.check_material(material)
    return Export(
        target=name,
        model=models.label(prep.result.model, prep.result.options),
        target_model=module.written(material),
        exact=chosen.exact,
        error=chosen.error,
        log_error=chosen.log_error,
        fitted=chosen.fitted,
        albedo_error=chosen.albedo_error,
        notes=tuple(n for n in (render_note(prep.result.metric),) if n)
        + tuple(notes)
        + tuple(tried)
        + (f"error: {ERROR_DEFINITION}",),
        material=material,
        files=files,
    )


def export(result: FitResult, target: str, *, fit: bool = True) -> Export:
    """Map the fitted material of ``result`` to ``target`` and measure the error.

    Tries the target's candidate materials for the model (closed-form starts, kept when
    exact, else fitted by least squares) and keeps an exact one, else the one with the
    least log error plus albedo error (:func:`~brdffit.export._match.best`); its notes
    list every candidate's errors. Every written number
    follows :mod:`brdffit.export._numbers` (finite, zero within resolution written as
    0, float32 normal range), and the errors reported are those of the written numbers.

    Arguments: ``result``; ``target`` one of :data:`TARGETS`; ``fit`` False keeps the
    closed-form mappings without least squares (fast; exact mappings are unchanged,
    approximate ones have larger errors).

    Raises :class:`ExportError` for an unknown target;
    :class:`~brdffit.errors.ExportValueError` (a subclass)
    naming a parameter or value that is not finite.
    """
    (name,) = parse_targets(target)
    return _export(_prepare(result), name, fit)


def write_exports(
    result: FitResult, targets: str | Iterable[str], out_prefix: str | Path
) -> list[tuple[Export, tuple[Path, ...]]]:
    """Export ``result`` to every target and write each file atomically.

    Files are ``out_prefix`` plus each export's suffixes (``.mitsuba.xml``,
    ``.mitsuba.json``, ``.gltf``, ``.mtlx``). Every target is checked before anything
    is written, so a refused target or value (:class:`ExportError`) leaves no file.
    Returns each export with the paths written.
    """
    names = check_targets(models.model_of(result), targets)
    prep = _prepare(result)
    done = [_export(prep, t) for t in names]
    out = []
    for e in done:
        paths = tuple(Path(f"{out_prefix}{suffix}") for suffix in e.files)
        for p, text in zip(paths, e.files.values(), strict=True):
            write_text(p, text)
        out.append((e, paths))
    return out
