"""From a measurement to the best material a renderer can hold: :func:`best_material`.

For one target (``"mitsuba"``, ``"gltf"``, ``"materialx"``) every form of
:data:`FORMS` is fitted to the data under :data:`~brdffit.export.api.RENDER_METRIC`
(``ngan``, whose loss bounds the error of an environment render), each fit is exported,
and each is scored in *render space* against the measurement itself
(:func:`brdffit.export.render_score.render_error`): the error of the directional albedo
(what a render under a white environment shows) and of a point-light sphere, against
the measurement read at full resolution.

The score is albedo error plus
point-light error. The form chosen is the one with the fewest free parameters among
those whose score is within :data:`SCORE_TOLERANCE` of the least: a feature stays only
when a render would show it.

With ``reference`` (default :data:`REFERENCE`, a form no target holds as such: two GGX
lobes and a sheen) the same scores are measured for a richer model, so that what the
target could not hold is a number (the render error a richer form reaches), not a guess.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from brdffit import models
from brdffit.core.measurements import Measurements
from brdffit.core.result import FitResult
from brdffit.engine.fit import fit
from brdffit.errors import ExportError
from brdffit.export.api import RENDER_METRIC, Export, export, parse_targets, write_exports
from brdffit.export.render_score import Measured, RenderError, render_error

FORMS: dict[str, tuple[str, ...]] = {
    "gltf": (
        "gltf",
        "gltf[sheen=true]",
        "gltf[clearcoat=true]",
        "gltf[sheen=true,clearcoat=true]",
        "gltf[iridescence=true]",
        "gltf[clearcoat=true,iridescence=true]",
    ),
    "mitsuba": (
        "principled",
        "principled[spec_tint=true]",
        "principled[sheen=true,sheen_tint=true]",
        "principled[clearcoat=true]",
        "walter[grey=ks]",
        "walter[n_lobes=2,grey=ks_1+ks_2]",
    ),
    "materialx": (
        "openpbr",
        "openpbr[fuzz=true]",
        "openpbr[coat=true]",
        "openpbr[coat=true,fuzz=true]",
    ),
}
"""Forms fitted per target, each exported exactly (or, for a blend whose weights leave
their range, with its measured error): glTF's metallic-roughness material and its
sheen, clear-coat and iridescence (thin-film) extensions, the film alone and under a
clear coat, as colour-shift paints and wraps are (:mod:`brdffit.models.gltf_pbr`); Mitsuba's
``principled`` (:mod:`brdffit.models.mitsuba_principled`) and walter's GGX lobes, which
Mitsuba holds as ``blendbsdf`` of ``diffuse`` and ``principled`` metals; MaterialX's
OpenPBR Surface as its GLSL evaluates it, with its fuzz and coat
(:mod:`brdffit.models.openpbr`)."""

REFERENCE = "walter[n_lobes=2,sheen=true]"
"""The richer form fitted beside a target's forms (module docstring)."""

SCORE_TOLERANCE = 0.01
"""A richer form is chosen only when it lowers the score by more than this fraction:
render_check's own Monte Carlo noise is 2-5% relative RMSE under an environment, so 1%
of the score is below what a render shows."""


@dataclass(frozen=True)
class Form:
    """One fitted form: its ``spec``, the fit, its export to the target (``None`` for the
    reference), its render-space ``error`` and the seconds the fit took."""

    spec: str
    result: FitResult
    export: Export | None
    error: RenderError
    seconds: float

    @property
    def n_free(self) -> int:
        return self.result.n_free


@dataclass(frozen=True)
class Material:
    """What :func:`best_material` found: the ``target``, every ``forms`` fitted, the
    ``chosen`` one, the ``reference`` fit (or ``None``), the files written."""

    target: str
    forms: tuple[Form, ...]
    chosen: Form
    reference: Form | None
    files: tuple[Path, ...] = field(default=())

    def report(self) -> str:
        """The lines ``brdffit material`` prints: each form, the choice, what is missing."""
        lines = [f"forms for {self.target} (fitted under {RENDER_METRIC}; score = albedo + point):"]
        for f in self.forms:
            mark = "*" if f is self.chosen else " "
            kind = "exact" if f.export is not None and f.export.exact else "approximate"
            lines.append(
                f" {mark} {f.spec:<44} k={f.n_free:<3} score {f.error.score:.3f}  "
                f"({f.error.text()}; export {kind}, {f.seconds:.0f} s)"
            )
        c = self.chosen
        lines.append(f"chosen: {c.spec} -> {c.export.target_model}")
        lines.append(f"render-space error against the measurement: {c.error.text()}")
        lines += self.missing()
        lines += [f"wrote {p}" for p in self.files]
        return "\n".join(lines)

    def missing(self) -> list[str]:
        """What the target could not hold: the reference's error beside the chosen one's,
        and the albedo colour left over."""
        out = []
        c, ref = self.chosen, self.reference
        if ref is not None:
            gain = 1.0 - ref.error.score / max(c.error.score, 1e-300)
            verdict = (
                f"a richer form ({ref.spec}, which {self.target} holds at best "
                "approximately) would lower "
                f"the score by {100 * gain:.0f}%: {ref.error.text()}"
                if gain > SCORE_TOLERANCE
                else f"a richer form ({ref.spec}) would not lower the score: the target "
                "holds what the data show"
            )
            out.append(f"not held by {self.target}: {verdict}")
        off = [
            f"{ch} {100 * (r - 1):+.0f}%"
            for ch, r in zip("RGB", c.error.ratio, strict=True)
            if not math.isnan(r) and abs(r - 1) > 0.1
        ]
        if off:
            out.append(f"albedo at normal view off by more than 10%: {', '.join(off)}")
        return out


def _fit_form(
    spec: str,
    data: Measurements,
    measured: Measured,
    target: str | None,
    cut_deg: float,
    seed: int,
) -> Form:
    t0 = time.perf_counter()
    r = fit(models.from_spec(spec), data, RENDER_METRIC, cut_deg=cut_deg, seed=seed, throw=False)
    if not np.isfinite(r.loss):
        raise ExportError(f"{data.source}: the fit of {spec} failed ({r.status.value})")
    e = export(r, target) if target is not None else None
    err = render_error(measured, r, e)
    return Form(spec, r, e, err, time.perf_counter() - t0)


def choose(forms: Sequence[Form]) -> Form:
    """The form with the fewest free parameters among those whose score is within
    :data:`SCORE_TOLERANCE` of the least (then the lower score)."""
    best = min(f.error.score for f in forms)
    near = [f for f in forms if f.error.score <= best * (1.0 + SCORE_TOLERANCE)]
    return min(near, key=lambda f: (f.n_free, f.error.score))


def best_material(
    data: Measurements,
    target: str,
    prefix: str | Path | None = None,
    *,
    forms: Sequence[str] | None = None,
    reference: str | None = REFERENCE,
    measured: Measurements | Measured | None = None,
    cut_deg: float = 80.0,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> Material:
    """Fit ``target``'s forms to ``data``, choose by render-space error, write the files.

    Arguments: ``data`` (on a MERL grid, module docstring); ``target`` one of
    :data:`FORMS`; ``prefix``: write ``PREFIX.<target files>`` (``write_exports``)
    when given; ``forms`` (specs) instead of :data:`FORMS` ``[target]``; ``reference``
    (a spec, or ``None`` for none); ``measured``: the data the scores read (module
    docstring; default ``data``), or its :class:`Measured` side read once for several
    targets; ``cut_deg``, ``seed`` as :func:`brdffit.fit`;
    ``progress`` called with one line before each fit.
    Raises :class:`~brdffit.errors.ExportError` for an unknown target or a failed fit,
    :class:`~brdffit.errors.MeasurementsError` for data off a MERL grid,
    :class:`~brdffit.errors.ParameterError` for a bad form spec (before any fit).
    """
    targets = parse_targets(target)
    if len(targets) != 1:
        raise ExportError(f"material: one target, not {target!r}; choose from {', '.join(FORMS)}")
    target = targets[0]
    specs = tuple(forms) if forms else FORMS[target]
    for s in (*specs, *((reference,) if reference else ())):
        models.from_spec(s)  # a bad spec fails here, before minutes of fitting
    if not isinstance(measured, Measured):
        measured = Measured.of(data if measured is None else measured)
    say = progress or (lambda _line: None)
    done = []
    for i, spec in enumerate(specs, 1):
        say(f"material: fitting form {i} of {len(specs)}: {spec}")
        done.append(_fit_form(spec, data, measured, target, cut_deg, seed))
    ref = None
    if reference:
        say(f"material: fitting the reference {reference}")
        ref = _fit_form(reference, data, measured, None, cut_deg, seed)
    chosen = choose(done)
    files: tuple[Path, ...] = ()
    if prefix is not None:
        written = write_exports(chosen.result, [target], prefix)
        files = tuple(p for _, paths in written for p in paths)
    return Material(target, tuple(done), chosen, ref, files)
