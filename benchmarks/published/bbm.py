"""Evaluate published BRDF fits with bsdfbenchmark's own C++ (bbm), the independent scorer.

:func:`evaluate` runs ``bbm_eval`` (``bbm_eval.cpp`` here, built against bbm's headers by
``build_bbm_eval.sh``: native backbone, ``doubleRGB``, bbm's string importer), which
parses the right-hand side of a ``fits/*.fit`` line exactly as bbm does and returns bbm's
``bsdf->eval(in = wi, out = wo)`` for R, G, B in 1/sr, without the cosine factor. ``wi`` is
the direction towards the light and ``wo`` towards the viewer (bbm's ``in`` and ``out``
with unit Radiance); for the 14 model classes of the fit files the value is symmetric in
the two. Directions are unit vectors in the local frame (z = normal), used as given;
below the horizon the value is 0.

The binary is ``$BBM_EVAL``, or ``~/.cache/brdffit/bbm_eval`` when that is unset.

bbm's values are returned as bbm computes them, NaN included: NganLafortune is NaN at
every pair on the lines whose normalisation ``max(Cz^2, Cxy^2)^(n/2)`` underflows (33 of
86 in ``ngan_lafortune.fit``), NganHe is NaN or inf when one direction lies within ~1e-8
rad of the normal, and Ward / Ward-Duer are NaN for ``z(wi) = z(wo) = 0``.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Sequence
from pathlib import Path

import numpy as np

BUILD_SCRIPT = Path(__file__).with_name("build_bbm_eval.sh")


def binary() -> Path:
    """Where the ``bbm_eval`` binary is looked for: ``$BBM_EVAL`` or the default."""
    env = os.environ.get("BBM_EVAL")
    return Path(env) if env else Path.home() / ".cache" / "brdffit" / "bbm_eval"


def available() -> bool:
    """Whether the ``bbm_eval`` binary exists and is executable."""
    path = binary()
    return path.is_file() and os.access(path, os.X_OK)


def _directions(name: str, v: np.ndarray) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), not {a.shape}")
    return a


def evaluate(
    bsdf: str | Sequence[str], wi: np.ndarray, wo: np.ndarray, *, threads: int = 1
) -> np.ndarray:
    """bbm's BSDF values ``f(wi, wo)`` for R, G, B (1/sr, no cosine factor).

    ``bsdf`` is a bbm constructor string (the right-hand side of a fit-file line) or a
    list of them; ``wi`` (light) and ``wo`` (view) are (N, 3) unit vectors in the local
    frame. Returns (N, 3), or (len(bsdf), N, 3) for a list (one process for all).
    ``threads`` > 1 splits the pairs among that many threads in the binary.

    Raises FileNotFoundError when the binary is not built, ValueError when bbm cannot
    parse a string (its message names it), RuntimeError on any other failure.
    """
    single = isinstance(bsdf, str)
    specs = [bsdf] if single else list(bsdf)
    if not specs:
        raise ValueError("no BSDF string given")
    wi = _directions("wi", wi)
    wo = _directions("wo", wo)
    if wi.shape != wo.shape:
        raise ValueError(f"wi and wo differ in shape: {wi.shape} and {wo.shape}")
    path = binary()
    if not available():
        raise FileNotFoundError(
            f"bbm_eval not found at {path} (set BBM_EVAL, or build it with "
            f"{BUILD_SCRIPT}; it needs g++ with C++20 and a bbm source tree or clone)"
        )
    n = wi.shape[0]
    payload = np.ascontiguousarray(np.concatenate([wi, wo], axis=1), dtype="<f8").tobytes()
    cmd = [str(path), "--threads", str(max(1, int(threads))), *specs]
    proc = subprocess.run(cmd, input=payload, capture_output=True, check=False)
    err = proc.stderr.decode(errors="replace").strip()
    if proc.returncode == 2:
        raise ValueError(err or "bbm_eval could not parse a BSDF string")
    if proc.returncode != 0:
        raise RuntimeError(f"bbm_eval failed (exit {proc.returncode}): {err}")
    out = np.frombuffer(proc.stdout, dtype="<f8")
    if out.size != len(specs) * n * 3:
        raise RuntimeError(
            f"bbm_eval returned {out.size} values, expected {len(specs) * n * 3}: {err}"
        )
    out = out.astype(float).reshape(len(specs), n, 3)
    return out[0] if single else out
