"""A sweep's unit of work: its tasks, and the fit a worker runs for them.

A :class:`Task` is one (material, model, metric) fit; :func:`fit_task` (or
:func:`fit_chunk`, several materials of one model and metric in one
:func:`brdffit.fit_many` call) runs where Dask puts it and returns what to write, and
:func:`write_outcome` writes it in the client (:mod:`brdffit.sweep.run`), so a worker needs
the material's file but no file system in common with the client. Times are measured
in the worker the same way for every model (:mod:`brdffit.sweep.run`'s docstring).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import subprocess
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import jax
import numpy as np

from brdffit import models
from brdffit.engine.fit import fit, fit_many
from brdffit.engine.timing import eval_ns_per_sample
from brdffit.selection.survival import sweep_reduction
from brdffit.sweep.materials import Material, load_material
from brdffit.util.atomic import write_json
from brdffit.util.version import __version__


def file_stem(label: str) -> str:
    """The file-name form of a model label: ``name[k=v,k2=v2]`` -> ``name@k=v@k2=v2``.

    Labels hold only letters, digits and ``_.+-=`` besides the brackets and commas
    (:func:`brdffit.models.parse_spec`), so the stem is safe in a file name; a plain
    name is its own stem.
    """
    return label.replace("[", "@").replace(",", "@").removesuffix("]")


@dataclass(frozen=True)
class Task:
    """One (material, model, metric) fit and the settings shared by the sweep.

    ``model`` is the model's label (:func:`brdffit.models.label`).
    """

    material: Material
    model: str
    metric: str
    settings: dict = field(default_factory=dict)

    def path(self, out: Path) -> Path:
        """Result file ``<out>/<material>/<stem>__<metric>.json`` (:func:`file_stem`)."""
        return Path(out) / self.material.name / f"{file_stem(self.model)}__{self.metric}.json"


_CACHE: dict = {}


def _cached_data(material: Material, stride: tuple[int, int, int]):
    key = (material.name, stride)
    if key not in _CACHE:
        _CACHE.clear()
        _CACHE[key] = load_material(material, stride)
    return _CACHE[key]


def checkout_commit(package_dir: Path) -> str | None:
    """``git describe --always --dirty`` of the checkout whose top level holds
    ``package_dir`` as ``<top>/<package name>``; ``None`` when there is none (an
    installed copy, possibly inside some other repository, which it must not report)."""

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "-C", str(package_dir), *args],
            capture_output=True, text=True, timeout=10, check=True,
        ).stdout.strip()  # fmt: skip

    try:
        top = Path(git("rev-parse", "--show-toplevel")).resolve()
        if top / package_dir.name != package_dir.resolve():
            return None
        return git("describe", "--always", "--dirty") or None
    except (OSError, subprocess.SubprocessError):
        return None


@functools.cache
def provenance() -> dict:
    """Where a result was computed: brdffit version and git commit, JAX backend, device.

    Results from different fitter versions or devices must not be mixed unknowingly
    in one report; the commit (``-dirty`` with uncommitted changes) is
    :func:`checkout_commit` of the package, else ``$BRDFFIT_GIT_DESCRIBE`` (set by
    whoever installed a copy), else ``None``.
    """
    here = Path(__file__).resolve().parents[1]  # the brdffit package folder
    commit = checkout_commit(here) or os.environ.get("BRDFFIT_GIT_DESCRIBE") or None
    return {
        "brdffit": __version__,
        "git": commit,
        "jax": jax.__version__,
        "backend": jax.default_backend(),
        "device": str(jax.devices()[0].device_kind),
    }


def write_outcome(out: Path, task: Task, outcome: dict) -> dict:
    """Write :func:`fit_task`'s outcome under ``out`` atomically: the result file (and
    remove an old ``.error.json``) or the error file; returns the short status."""
    path = task.path(out)
    err_path = path.with_suffix(".error.json")
    if outcome["ok"]:
        write_json(path, outcome["result"])
        err_path.unlink(missing_ok=True)
    else:
        write_json(err_path, outcome["error_record"])
    return outcome["status"]


def fit_task(task: Task) -> dict:
    """Fit one task where this runs (a worker) and return what to write, nothing written.

    Returns ``{"ok", "status", "result"}`` or, on an exception (recorded, the sweep goes
    on), ``{"ok": False, "status", "error_record"}``.
    """
    try:
        data = _cached_data(task.material, tuple(task.settings["stride"]))
        model = models.from_spec(task.model)
        r = fit(model, data, task.metric, **_fit_options(task.settings), throw=False)
        return _outcome(task, model, data, r)
    except Exception as e:  # recorded, the sweep goes on
        return _failure(task, e, traceback.format_exc())


def fit_chunk(chunk: Sequence[Task]) -> list[dict]:
    """:func:`fit_task` for tasks of one model and metric, batched by
    :func:`brdffit.fit_many` (same start policy, so the same answers as single fits).

    Each result's ``wall_time`` is the batch's time over its size, and ``batch`` its
    size. Materials whose sample counts differ after the cut, or a failure of the batch,
    fall back to one :func:`fit_task` each.
    """
    if len(chunk) == 1:
        return [fit_task(chunk[0])]
    try:
        first = chunk[0]
        stride = tuple(first.settings["stride"])
        datasets = [load_material(t.material, stride) for t in chunk]
        model = models.from_spec(first.model)
        opts = _fit_options(first.settings)
        results = fit_many(model, datasets, first.metric, **opts, throw=False)
    except Exception:  # unequal sample counts or a failed batch: one at a time
        return [fit_task(t) for t in chunk]
    wall = max(r.wall_time for r in results)
    out = []
    for t, data, r in zip(chunk, datasets, results, strict=True):
        try:
            r = dataclasses.replace(r, wall_time=wall / len(chunk))
            out.append(_outcome(t, model, data, r, batch=len(chunk)))
        except Exception as e:
            out.append(_failure(t, e, traceback.format_exc()))
    return out


def _fit_options(settings: dict) -> dict:
    """The :func:`brdffit.fit` keywords a sweep's settings fix."""
    keys = ("cut_deg", "n_restarts", "screen", "seed", "max_steps")
    return {k: settings[k] for k in keys}


def _outcome(task: Task, model, data, r, batch: int = 1) -> dict:
    """The result record of fit ``r`` of ``task`` (timing, provenance, reduction)."""
    s = task.settings
    d = json.loads(r.to_json())
    ok = bool(np.isfinite(r.loss))  # an unconverged fit is ranked by its loss: time it too
    ns = eval_ns_per_sample(model, r.params, data, n=s["eval_n"]) if ok else None
    d.update(
        label=task.model,
        material=task.material.name,
        family=task.material.family,
        eval_ns_per_sample=ns,
        eval_n=s["eval_n"],
        batch=batch,
        provenance=provenance(),
    )
    if s.get("simplify"):  # brdffit sweep --simplify: the reduction after the fit
        d["simplify"] = sweep_reduction(model, data, task.metric, r, s)
    status = {"ok": True, "converged": r.converged, "task": task.path(Path(".")).name}
    return {"ok": True, "status": status, "result": d}


def _failure(task: Task, e: BaseException, trace: str | None = None) -> dict:
    """The error outcome of ``task``: the record for its ``.error.json`` and a status."""
    info = {"material": task.material.name, "model": task.model, "metric": task.metric}
    record = {**info, **_error(e), **({"traceback": trace} if trace else {})}
    status = {"ok": False, "converged": False, "task": task.path(Path(".")).name}
    return {"ok": False, "status": {**status, "error": str(e)}, "error_record": record}


def _error(e: BaseException) -> dict:
    return {"error": type(e).__name__, "message": str(e)}
