"""RGL-EPFL measured materials (``.bsdf``, Dupuy & Jakob 2018) through Mitsuba 3.

Dupuy and Jakob, "An Adaptive Parameterization for Efficient Material Acquisition and
Rendering", ACM TOG 37(6), 2018; the database is https://rgl.epfl.ch/materials. A
``.bsdf`` file is a Mitsuba tensor file; Mitsuba 3's ``measured`` plugin evaluates it
(an optional dependency: ``pip install brdffit[rgl]``). Its ``eval`` returns
``f cos(theta_o)``; we pass ``si.wi = wi`` (toward the light, the file's incidence
direction) and ``wo`` (toward the viewer), and divide by ``cos(theta_o) = wo.z``.

Grazing angles: the plugin interpolates ``f cos`` over the half-vector domain, which
does not vanish exactly at the horizon, so ``eval / cos`` amplifies the interpolation
error by ``1 / cos(theta_o)`` (11.5x at 85 degrees, unbounded at 90). Samples whose
``wi`` or ``wo`` lies more than ``grazing_deg`` from the normal (default
:data:`GRAZING_DEG`) are therefore not evaluated: they are kept, marked invalid, stored
as -1 and counted as "outside the cut" (``Measurements.zenith_cut_deg``,
:meth:`~brdffit.core.measurements.Measurements.mask_counts`), not as "not measured". Beyond
the file's largest incidence angle (its ``theta_i`` nodes, shown in ``source``) Mitsuba
holds the last measured slice.

Negative values are measured values (``negative="signed"``): the files hold RGB
converted from spectra and interpolated by the plugin, and both leave small genuine
negative channels (vch_golden_yellow in plane at theta_i = theta_o = 20 degrees is
(8.82, 4.49, -0.355) 1/sr, a saturated yellow whose blue falls outside the sRGB gamut).
Masking such a cell, as MERL's convention would, dropped 16-20% of the cells inside
the cut on leaf_maple and cc_ibiza_sunset, whole back-scatter regions and specular
peaks, and biased the fitted colour. They are kept and fitted as they are; a log metric
leaves out the rare channel with ``1 + f cos <= 0`` (:func:`brdffit.engine.metrics.prepare`).

The header is checked first, without Mitsuba (:func:`brdffit.io.rgl_header.rgl_header`).
Grids: :func:`read_rgl` evaluates the (strided) MERL grid, :func:`read_rgl_at` the
directions a user gives. The MERL grid has ``phi_h = 0``; an anisotropic file is seen in
that plane, or, with ``phi_h_deg``, in the grid rotated about the normal.

Spectral files (a ``wavelengths`` field): the file's spectra are converted node by node
to linear sRGB (:func:`brdffit.io.spectra.spectral_weights`) and written to a temporary RGB
file. That is exact: the plugin's interpolation is linear in the stored values and
linear in wavelength between nodes, as the conversion assumes.

Mitsuba variants (checked on a 2-core Xeon with AVX-512, Mitsuba 3.9.1, Dr.Jit 1.5.0,
system LLVM 15.0.6): ``llvm_ad_rgb`` would evaluate ``measured`` vectorised but aborts
the process ("LLVM ERROR: Cannot select ... fminimum" while compiling the kernel, with or
without fast math, packet ops or symbolic loops; the ``diffuse`` plugin works), while
``scalar_rgb`` works at about 10 us per direction in a Python loop (the full MERL grid,
1.0 M cells inside the cut, took 17 s with two workers). So Mitsuba runs in worker
processes: each variant of :data:`VARIANTS` is tried in turn (``variant=`` or
``$BRDFFIT_RGL_VARIANT`` picks one), a variant whose worker crashes is skipped for the
rest of the process (a new process tries it again, about 1 s), and a scalar evaluation
is split over the cores. A crash can never take the caller down, and the caller's own
Mitsuba variant is left alone.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from jaxtyping import ArrayLike, Float

from brdffit.core.measurements import Measurements
from brdffit.errors import MeasurementFileError, MissingDependencyError, ParameterError
from brdffit.io.merl_grid import merl_grid, merl_grid_measurements
from brdffit.io.rgl_header import RglFile, rgl_header
from brdffit.io.spectra import spectral_weights

GRAZING_DEG: float = 85.0
"""Default zenith cut (degrees) of :func:`read_rgl` and :func:`read_rgl_at`."""

VARIANTS: tuple[str, ...] = ("llvm_ad_rgb", "scalar_rgb")
"""Mitsuba variants tried in turn: vectorised first, the scalar loop as the fallback."""

_SCALAR_CHUNK = 20_000  # directions per scalar worker, at least
_LLVM_CHUNK = 1 << 20  # directions per vectorised eval call
_BROKEN: dict[str, str] = {}  # variant -> why it failed in this process

# The worker: its own process, so that a crash in Mitsuba's JIT cannot kill the caller.
# argv: variant, .bsdf path, directions .npy (2, N, 3) float32, output .npy (N, 3) float32.
_WORKER = r"""
import sys
import numpy as np
variant, bsdf_path, dirs_path, out_path = sys.argv[1:5]
try:
    import mitsuba as mi
    mi.set_variant(variant)
except Exception as e:
    sys.stderr.write("brdffit-rgl-variant: %s\n" % e)
    sys.exit(4)
try:
    bsdf = mi.load_dict({"type": "measured", "filename": bsdf_path})
except Exception as e:
    sys.stderr.write("brdffit-rgl-load: %s\n" % " ".join(str(e).split()))
    sys.exit(3)
d = np.load(dirs_path)
n = d.shape[1]
out = np.empty((n, 3), np.float32)
ctx = mi.BSDFContext()
if variant.startswith("scalar"):
    si, V, ev = mi.SurfaceInteraction3f(), mi.Vector3f, bsdf.eval
    for k, (a, b) in enumerate(zip(d[0].tolist(), d[1].tolist())):
        si.wi = V(a)
        out[k] = ev(ctx, si, V(b))
else:
    import drjit as dr
    for s in range(0, n, CHUNK):
        e = min(n, s + CHUNK)
        si = dr.zeros(mi.SurfaceInteraction3f, e - s)
        si.wi = mi.Vector3f(np.ascontiguousarray(d[0, s:e].T))
        v = bsdf.eval(ctx, si, mi.Vector3f(np.ascontiguousarray(d[1, s:e].T)))
        out[s:e] = np.asarray(v).T
np.save(out_path, out)
""".replace("CHUNK", str(_LLVM_CHUNK))


def _check_mitsuba() -> None:
    if importlib.util.find_spec("mitsuba") is None:
        raise MissingDependencyError(
            "reading RGL .bsdf files needs Mitsuba 3: pip install 'brdffit[rgl]' "
            "(or pip install 'mitsuba>=3.5')"
        )


def _rgb_copy(header: RglFile, folder: Path) -> Path:
    """An RGB file with the spectral file's tables converted to linear sRGB, in ``folder``."""
    from mitsuba.python import tensor_io  # deferred: optional dependency

    with contextlib.redirect_stdout(io.StringIO()):  # tensor_io prints a line per call
        t = tensor_io.read(header.path)
        w = spectral_weights(np.asarray(t.pop("wavelengths"), float))  # (L, 3)
        t["rgb"] = np.einsum("ptlyx,lc->ptcyx", t.pop("spectra"), w).astype(np.float32)
        out = folder / "rgb.bsdf"
        tensor_io.write(str(out), **t)
    return out


def rgl_eval_cos(
    path: str | os.PathLike[str],
    wi: Float[ArrayLike, "n 3"],
    wo: Float[ArrayLike, "n 3"],
    *,
    variant: str | None = None,
) -> Float[np.ndarray, "n 3"]:
    """Mitsuba's ``measured`` ``eval``: ``f(wi, wo) cos(theta_o)``, linear RGB, float32.

    No cut, no division: the raw plugin output (0 below the horizon). See
    :func:`read_rgl_at` for BRDF values.

    Arguments:
    - ``path``: the ``.bsdf`` file (RGB or spectral).
    - ``wi``, ``wo``: (n, 3) unit directions, light and viewer, shading frame.
    - ``variant``: a Mitsuba variant, or ``None`` for ``$BRDFFIT_RGL_VARIANT`` or the
      first of :data:`VARIANTS` that works here (module docstring).

    Raises :class:`MissingDependencyError` without Mitsuba, :class:`MeasurementFileError`
    when the file cannot be loaded or every variant fails.
    """
    header = rgl_header(path)
    _check_mitsuba()
    wi = np.asarray(wi, np.float32).reshape(-1, 3)
    wo = np.asarray(wo, np.float32).reshape(-1, 3)
    if wi.shape != wo.shape:
        raise ParameterError(f"wi and wo must both be (n, 3); got {wi.shape} and {wo.shape}")
    if wi.shape[0] == 0:
        return np.zeros((0, 3), np.float32)
    chosen = variant or os.environ.get("BRDFFIT_RGL_VARIANT")
    tries = [chosen] if chosen else [v for v in VARIANTS if v not in _BROKEN]
    with tempfile.TemporaryDirectory(prefix="brdffit-rgl-") as tmp:
        folder = Path(tmp)
        bsdf = _rgb_copy(header, folder) if header.spectral else Path(header.path).resolve()
        failures = []
        for v in tries:
            try:
                return _run_workers(v, bsdf, folder, np.stack([wi, wo]))
            except _LoadFailed as e:
                raise MeasurementFileError(
                    path, f"Mitsuba's 'measured' plugin cannot load it: {e}"
                ) from None
            except _WorkerFailed as e:
                failures.append(f"{v}: {e}")
                if not chosen:
                    _BROKEN[v] = str(e)
    raise MeasurementFileError(
        path, "Mitsuba could not evaluate it; " + "; ".join(failures or ["no variant left"])
    )


class _WorkerFailed(RuntimeError):
    """A worker process crashed or could not start the variant."""


class _LoadFailed(RuntimeError):
    """Mitsuba's ``measured`` plugin rejected the file (the message is Mitsuba's)."""


def _run_workers(variant: str, bsdf: Path, folder: Path, dirs: np.ndarray) -> np.ndarray:
    """Evaluate ``dirs`` ((2, n, 3): wi, wo) in worker processes (scalar: one per core)."""
    n = dirs.shape[1]
    parts = 1
    if variant.startswith("scalar"):
        parts = max(1, min(os.cpu_count() or 1, n // _SCALAR_CHUNK))
    bounds = np.linspace(0, n, parts + 1).astype(int)
    procs = []
    for k in range(parts):
        d_path, o_path = folder / f"dirs{k}.npy", folder / f"out{k}.npy"
        np.save(d_path, dirs[:, bounds[k] : bounds[k + 1]])
        cmd = [sys.executable, "-c", _WORKER, variant, str(bsdf), str(d_path), str(o_path)]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        procs.append((proc, o_path))
    done = [(proc, proc.communicate()[1].decode("utf-8", "replace"), o) for proc, o in procs]
    for proc, text, _ in done:
        if proc.returncode == 3:
            raise _LoadFailed(text.split("brdffit-rgl-load:", 1)[-1].strip())
        if proc.returncode != 0:
            lines = [ln for ln in text.splitlines() if ln.strip()]
            why = lines[0][:120] if lines else "no message"
            raise _WorkerFailed(f"exit {proc.returncode} ({why})")
    return np.concatenate([np.load(o) for _, _, o in done])


def _cut_mask(wi: np.ndarray, wo: np.ndarray, grazing_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(above the horizon, inside the zenith cut) masks."""
    if not 0.0 < grazing_deg <= 90.0:
        raise ParameterError(
            f"grazing_deg={grazing_deg}; accepted: 0 < grazing_deg <= 90 (degrees)"
        )
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    c = np.cos(np.radians(grazing_deg))
    return above, above & (wi[:, 2] >= c) & (wo[:, 2] >= c)


def _evaluate(path, wi, wo, inside, variant) -> np.ndarray:
    """(N, 3) f in 1/sr: eval / wo.z inside the cut, -1 (not measured) elsewhere."""
    values = np.full((wi.shape[0], 3), -1.0)
    fcos = rgl_eval_cos(path, wi[inside], wo[inside], variant=variant).astype(np.float64)
    values[inside] = fcos / wo[inside, 2:3]
    return values


def _note(header: RglFile, n: int, above, inside, grazing_deg: float) -> str:
    """``source``: the file, its kind and incidence range, and the cells the cut masked."""
    kind = "isotropic" if header.isotropic else "anisotropic"
    kind += ", spectral to linear sRGB" if header.spectral else ", RGB"
    t = header.theta_i_deg
    parts = [
        f"RGL {kind} '{header.description}'",
        f"theta_i nodes {t[0]:.3g}-{t[-1]:.3g} deg" if t else "no theta_i nodes",
        f"{int(above.sum() - inside.sum()):,} of {n:,} samples beyond the reader's "
        f"{grazing_deg:g} deg zenith cut, not evaluated",
    ]
    return f"{header.path} ({'; '.join(parts)})"


def read_rgl(
    path: str | os.PathLike[str],
    *,
    stride: tuple[int, int, int] | int = (1, 1, 1),
    grazing_deg: float = GRAZING_DEG,
    phi_h_deg: float = 0.0,
    variant: str | None = None,
) -> Measurements:
    """An RGL ``.bsdf`` file evaluated on the (strided) MERL grid, as :class:`Measurements`.

    Values are ``eval / cos(theta_o)`` in 1/sr (no cosine), linear RGB, signed (module
    docstring); weights the MERL cells' solid angles (sr^2). Cells below the horizon or
    beyond the zenith cut are marked invalid and counted (``brdffit info``).

    Arguments:
    - ``path``: the ``.bsdf`` file (RGB or spectral, isotropic or anisotropic).
    - ``stride``: the grid, as in :func:`brdffit.io.merl_grid.merl_grid`; the full grid (1.46 M
      cells) gives ``grid = MERL_SHAPE``, so the result can be written with
      :func:`brdffit.io.merl.write_merl`.
    - ``grazing_deg``: zenith cut in degrees for ``wi`` and ``wo`` (module docstring).
    - ``phi_h_deg``: rotate the grid about the normal by this azimuth (degrees; matters
      for anisotropic files only).
    - ``variant``: see :func:`rgl_eval_cos`.

    Raises :class:`MeasurementFileError`, :class:`MissingDependencyError`,
    :class:`~brdffit.errors.ParameterError` (bad stride or cut).
    """
    header = rgl_header(path)
    g = merl_grid(stride)
    wi, wo = g.wi, g.wo
    if phi_h_deg:
        c, s = np.cos(np.radians(phi_h_deg)), np.sin(np.radians(phi_h_deg))
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        wi, wo = wi @ rot.T, wo @ rot.T
    above, inside = _cut_mask(wi, wo, grazing_deg)
    values = _evaluate(path, wi, wo, inside, variant)
    values[~above] = 0.0  # a BRDF is 0 below the horizon
    data = merl_grid_measurements(
        values.T.reshape(3, *g.shape),
        source=_note(header, g.n, above, inside, grazing_deg),
        stride=stride,
        valid=inside.reshape(g.shape),
        negative="signed",
        zenith_cut_deg=grazing_deg,
    )
    return data.replace(wi=wi, wo=wo) if phi_h_deg else data


def read_rgl_at(
    path: str | os.PathLike[str],
    wi: Float[ArrayLike, "n 3"],
    wo: Float[ArrayLike, "n 3"],
    *,
    weights: Float[ArrayLike, " n"] | None = None,
    grazing_deg: float = GRAZING_DEG,
    variant: str | None = None,
) -> Measurements:
    """An RGL ``.bsdf`` file evaluated at the given directions, as :class:`Measurements`.

    As :func:`read_rgl`, at ``wi``, ``wo`` ((n, 3) unit directions, light and viewer,
    shading frame); ``weights`` (n,) sr^2, default uniform (``(2 pi)^2 / n``).
    """
    header = rgl_header(path)
    wi = np.asarray(wi, float).reshape(-1, 3)
    wo = np.asarray(wo, float).reshape(-1, 3)
    if wi.shape != wo.shape:
        raise ParameterError(f"wi and wo must both be (n, 3); got {wi.shape} and {wo.shape}")
    above, inside = _cut_mask(wi, wo, grazing_deg)
    values = _evaluate(path, wi, wo, inside, variant)
    values[~above] = 0.0
    return Measurements.from_directions(
        wi,
        wo,
        values,
        weights=weights,
        valid=inside,
        negative="signed",
        source=_note(header, wi.shape[0], above, inside, grazing_deg),
        zenith_cut_deg=grazing_deg,
    )
