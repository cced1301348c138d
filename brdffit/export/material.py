"""From a measurement to the best material a renderer can hold: :func:`best_material`.

For one target (``"mitsuba"``, ``"gltf"``, ``"materialx"``) every form of
:data:`FORMS` is fitted to the data under :data:`~brdffit.export.api.RENDER_METRIC`
(``ngan``, whose loss bounds the error of an environment render), each fit is exported,
and each is scored in *render space* against the measurement itself
(:func:`render_error`):

* **albedo error**: the directional albedo ``a(wo) = integral of f cos(theta_i) dwi``
  (``theta_i`` < 80 degrees) at views 0, 30, 60 and 75 degrees, ``||a_fit - a_data|| /
  ||a_data||`` over views and R, G, B: what a render under a white environment shows
  (a channel the material barely reflects weighs as little as it shows; a per-channel
  ratio would explode on it: RGL cg_sunflower's blue albedo is near 0). The integral is
  taken over half vectors, ``dwi = 4 (wo.h) dwh``, with Gauss-Legendre panels in ``1 -
  cos(theta_h)`` spaced geometrically from 1e-10 (:func:`_albedo_pairs`), so a lobe as
  narrow as alpha 1e-4 carries its energy into the albedo as a render's importance
  sampling would; a grid uniform in ``wi`` steps over it. (The 80-degree edge is a
  step across the panels: a Lambertian's albedo comes out 1.1% high at normal view, on
  the fit and the data alike);
* **point-light error**: ``||fit - data|| / ||data||`` over the pixels and channels of a
  unit sphere seen along its axis under a distant light from (3, 3, 4) (the scene of
  ``benchmarks/render_check.py``): 48 x 48 pixels, those whose footprint lies wholly on
  the sphere, each the mean of ``f cos(theta_i)`` at 3 x 3 points of its footprint. A
  pixel averages over the normals it sees, as a render does: a lobe far narrower than a
  pixel (a fit's alpha of 1e-4 chasing a peak) shows as the little it adds to the
  pixel, where a sample on the exact mirror direction read it as 1e7 (in-plane slices
  at whole degrees did: point errors of 1e4 on RGL cg_sunflower and ilm_solo_m_68).

The data side reads the measurement at those directions by nearest MERL bin, a channel
the reader left out taking its nearest measured bin's value
(:func:`brdffit.io.merl_grid.nearest_bin`), so the data must lie on a MERL grid or a
strided one (MERL, NBRDF and RGL-EPFL files do; a table of scattered samples does not).
Fits may run on a strided grid, but scores are read from the full-resolution grid
(``measured``; ``brdffit material`` reads the file twice): on a coarse grid a sample
stands for its whole cell, and near a highlight that step is part of the point-light
error.

An export that is not exact (``Export.exact`` false) adds its own errors against the fit:
its relative error of ``f cos(theta_i)`` to the point-light error and its albedo error
(:func:`brdffit.export._match.albedo_error`) to the albedo error; by the triangle
inequality the written material's error is at most about the sum. (Without the albedo
term, a two-lobe fit of RGL satin_rosaline whose nested blend had to darken the diffuse
was chosen and rendered at 0.58-0.67 of the measured brightness.) The score is albedo error plus
point-light error. The form chosen is the one with the fewest free parameters among
those whose score is within :data:`SCORE_TOLERANCE` of the least: a feature stays only
when a render would show it.

With ``reference`` (default :data:`REFERENCE`, a form no target holds as such: two GGX
lobes and a sheen) the same scores are measured for a richer model, so that what the
target could not hold is a number (the render error a richer form reaches), not a guess.
"""

from __future__ import annotations

import functools
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
from brdffit.io.merl_grid import merl_stride, nearest_bin

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

ALBEDO_VIEWS_DEG = (0.0, 30.0, 60.0, 75.0)
LIGHT = np.array([3.0, 3.0, 4.0]) / np.sqrt(34.0)
"""Direction toward the light of the point-light sphere (render_check's light position)."""
PIXELS, SUBSAMPLES = 48, 3


DARK = 0.05
"""A channel whose measured albedo at normal view is below this fraction of the brightest
channel's is not reported as a colour ratio (its ratio is noise over ~0)."""


@dataclass(frozen=True)
class RenderError:
    """Render-space error of a material against a measurement (module docstring):
    ``albedo`` (relative error of the directional albedo over views and channels),
    ``point`` (relative error of the point-light sphere, the export's own error
    included), ``fit_rgb`` and ``data_rgb`` (the albedo at normal view, R, G, B)."""

    albedo: float
    point: float
    fit_rgb: tuple[float, float, float]
    data_rgb: tuple[float, float, float]

    @property
    def ratio(self) -> tuple[float, ...]:
        """Fit over data albedo at normal view per channel (``nan`` for a :data:`DARK` one)."""
        top = max(self.data_rgb)
        return tuple(
            f / d if d > DARK * top else math.nan
            for f, d in zip(self.fit_rgb, self.data_rgb, strict=True)
        )

    @property
    def score(self) -> float:
        """``albedo + point``: what a form is chosen by."""
        return self.albedo + self.point

    def text(self) -> str:
        r = ", ".join(f"{x:.2f}" for x in self.ratio)
        return (
            f"albedo error {self.albedo:.3f}, point-light error {self.point:.3f}, albedo ratio {r}"
        )


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


@functools.lru_cache(maxsize=1)
def _albedo_pairs() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(wi, wo, weight)`` of the albedo quadrature at each view of
    :data:`ALBEDO_VIEWS_DEG`, in view order with equal counts (module docstring): 30
    panels of 8 Gauss-Legendre nodes in ``t = 1 - cos(theta_h)`` (``dwh = dt dphi``), 48
    azimuths; ``weight`` (sr) is 0 where ``wi`` lies beyond the 80-degree cut."""
    ends = np.concatenate([[0.0], np.geomspace(1e-10, 1.0, 30)])
    x, w = np.polynomial.legendre.leggauss(8)
    lo, hi = ends[:-1, None], ends[1:, None]
    t = (0.5 * (hi - lo) * x + 0.5 * (hi + lo)).ravel()
    wt = (0.5 * (hi - lo) * w).ravel()
    phi = (np.arange(48) + 0.5) * 2.0 * np.pi / 48
    tt, pp = (a.ravel() for a in np.meshgrid(t, phi, indexing="ij"))
    ww = np.repeat(wt, len(phi)) * 2.0 * np.pi / len(phi)
    cz = 1.0 - tt
    sz = np.sqrt(np.maximum(1.0 - cz**2, 0.0))
    h = np.stack([sz * np.cos(pp), sz * np.sin(pp), cz], axis=1)
    out = []
    for view in np.radians(ALBEDO_VIEWS_DEG):
        wo = np.array([np.sin(view), 0.0, np.cos(view)])
        oh = h @ wo
        wi = 2.0 * oh[:, None] * h - wo
        ok = (oh > 0.0) & (wi[:, 2] > np.cos(np.radians(80.0)))
        wi = np.where(ok[:, None], wi, np.array([0.0, 0.0, 1.0]))
        out.append((wi, np.broadcast_to(wo, wi.shape), np.where(ok, 4.0 * oh * ww, 0.0)))
    return tuple(np.concatenate(parts) for parts in zip(*out, strict=True))


@functools.lru_cache(maxsize=1)
def _sphere_pairs() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local ``(wi, wo)`` at the sub-pixel points of the point-light sphere, and each
    point's pixel (module docstring). The frame at normal ``n`` is Duff et al.'s (2017)
    branchless orthonormal basis; the BRDF is isotropic, so its choice does not matter."""
    step = 2.0 / PIXELS
    centres = -1.0 + step * (np.arange(PIXELS) + 0.5)
    cx, cy = (a.ravel() for a in np.meshgrid(centres, centres))
    keep = np.hypot(cx, cy) + np.sqrt(2.0) * step / 2 < 1.0
    offsets = step * ((np.arange(SUBSAMPLES) + 0.5) / SUBSAMPLES - 0.5)
    ox, oy = (a.ravel() for a in np.meshgrid(offsets, offsets))
    x = (cx[keep][:, None] + ox[None, :]).ravel()
    y = (cy[keep][:, None] + oy[None, :]).ravel()
    pixel = np.repeat(np.arange(int(keep.sum())), SUBSAMPLES**2)
    n = np.stack([x, y, np.sqrt(1.0 - x**2 - y**2)], axis=1)
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    u = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)

    def local(v: np.ndarray) -> np.ndarray:
        return np.stack([t @ v, u @ v, n @ v], axis=1)

    return local(LIGHT), local(np.array([0.0, 0.0, 1.0])), pixel


def _pooled(fit: np.ndarray, data: np.ndarray) -> float:
    """``||fit - data|| / ||data||`` over every value given."""
    return float(np.linalg.norm(fit - data) / max(np.linalg.norm(data), 1e-300))


def _albedos(f: np.ndarray) -> np.ndarray:
    """Directional albedos (views, 3) of values ``f`` at :func:`_albedo_pairs`."""
    wi, _, weight = _albedo_pairs()
    return (f * (wi[:, 2] * weight)[:, None]).reshape(len(ALBEDO_VIEWS_DEG), -1, 3).sum(axis=1)


def _sphere_image(f: np.ndarray) -> np.ndarray:
    """Point-light sphere pixels (P, 3) of values ``f`` at :func:`_sphere_pairs` (each pixel
    the sum over its points, which the relative error does not see)."""
    wi, _, pixel = _sphere_pairs()
    fc = f * np.maximum(wi[:, 2:3], 0.0)
    return np.stack([np.bincount(pixel, fc[:, c], pixel.max() + 1) for c in range(3)], axis=1)


@dataclass(frozen=True, eq=False)
class Measured:
    """The measurement's side of :func:`render_error`, read once per file: its albedos
    (views, 3) and point-light sphere (P, 3), by nearest bin with the reader's missing
    channels filled (:func:`brdffit.io.merl_grid.nearest_bin`, a distance transform over
    the whole grid per call, so not once per form)."""

    albedo: np.ndarray
    sphere: np.ndarray

    @classmethod
    def of(cls, data: Measurements) -> Measured:
        """Raises :class:`~brdffit.errors.MeasurementsError` naming the file when ``data``
        is not on a MERL grid."""
        merl_stride(data)
        wi, wo, _ = _albedo_pairs()
        albedo = _albedos(nearest_bin(data, wi, wo, fill=True))
        wi, wo, _ = _sphere_pairs()
        return cls(albedo, _sphere_image(nearest_bin(data, wi, wo, fill=True)))


def render_error(
    data: Measurements | Measured, fitted: FitResult, export: Export | None = None
) -> RenderError:
    """The render-space error of ``fitted`` against ``data`` (module docstring; pass
    :class:`Measured` to read the data once for several fits); an inexact ``export`` of
    it adds its own errors."""
    ref = data if isinstance(data, Measured) else Measured.of(data)
    model = models.model_of(fitted)
    params = {k: np.asarray(v) for k, v in fitted.params.items()}
    wi, wo, _ = _albedo_pairs()
    albedo = _albedos(np.asarray(model.eval(params, wi, wo), float))
    wi, wo, _ = _sphere_pairs()
    sphere = _sphere_image(np.asarray(model.eval(params, wi, wo), float))
    extra = (0.0, 0.0) if export is None or export.exact else (export.albedo_error, export.error)
    rgb = tuple(tuple(float(x) for x in a[0]) for a in (albedo, ref.albedo))
    return RenderError(
        _pooled(albedo, ref.albedo) + extra[0], _pooled(sphere, ref.sphere) + extra[1], *rgb
    )


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
