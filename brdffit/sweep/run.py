"""Sweeps: fit many materials x models x metrics, one JSON file per result, resumable.

A sweep folder holds ``sweep.json`` (the manifest, written first: materials with
their sources and families, model labels with all their options, metrics, settings)
and one file per task, ``<material>/<stem>__<metric>.json``: :meth:`FitResult.to_dict`
(NaN as null) plus ``label``, ``material``, ``family``, ``eval_ns_per_sample`` and
``eval_n``. A model is given as a spec, ``name`` or ``name[k=v,...]``
(:func:`brdffit.models.parse_spec`) and known by its canonical label
(:func:`brdffit.models.label`); the file ``stem`` is the label with ``[`` and ``,``
written ``@`` and ``]`` dropped (``lafortune[n_lobes=2,anisotropic=true]`` ->
``lafortune@n_lobes=2@anisotropic=true``), so a model with default options keeps its
plain name and older sweep folders resume. A task whose file exists and parses is
finished and never redone, so an interrupted sweep resumes where it stopped; every file
is written atomically by this process as its result comes back from a worker, so a kill
loses at most the fits in flight and workers need no file system in common with it. A
fit that does not converge is a result (``converged`` false, ``status`` says why); an
exception is written to ``<stem>__<metric>.error.json`` and the task is tried again on
the next run.

Times are measured in the worker the same way for every model: ``wall_time`` is the
fit's own clock (:func:`brdffit.fit`, compile included on a worker's first fit of a
model and grid shape, so compare medians over materials); ``eval_ns_per_sample`` is
the best of 3 warm calls of ``jax.jit(model.eval)`` at the fitted parameters on the
material's valid directions tiled to ``eval_n`` samples.

Engine: Dask distributed (:mod:`brdffit.sweep.dask_runner`). With ``scheduler`` the tasks run on
that cluster; without it on a LocalCluster of ``jobs`` worker processes (default one
per core), so a lost worker's task is run again elsewhere and its result is still
written once. ``jobs=1`` without a scheduler runs the tasks in the calling process.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import socket
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from brdffit.errors import SweepError
from brdffit.selection.families import family_of
from brdffit.sweep.tasks import (  # noqa: F401 (the sweep's public names, re-exported)
    Material,
    Task,
    _failure,
    checkout_commit,
    file_stem,
    fit_chunk,
    fit_task,
    load_material,
    provenance,
    write_outcome,
)
from brdffit.util.atomic import has_key, remove_temporaries, write_text
from brdffit.util.progress import progress_bar

MANIFEST = "sweep.json"
SETTINGS = ("stride", "cut_deg", "n_restarts", "screen", "seed", "max_steps", "eval_n")

# Synthetic material recipes: (family word, model, parameter sampler).
_SYNTH = (
    ("plastic", "walter"),
    ("metal", "walter"),
    ("fabric", "oren_nayar"),
    ("paint", "blinn_phong"),
)


@dataclass(frozen=True)
class SweepSummary:
    """What one :func:`run_sweep` call did (counts of tasks) and how long it took (s)."""

    out: str
    n_tasks: int
    n_skipped: int
    n_done: int
    n_unconverged: int
    n_errors: int
    wall_time: float


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


def is_finished(path: Path, simplify: str | None = None) -> bool:
    """True when ``path`` is a result file that parses and has a loss (and, with
    ``simplify``, a reduction made with that criterion: :func:`brdffit.selection.survival.has_reduction`)."""
    if simplify:
        from brdffit.selection.survival import has_reduction

        return has_reduction(path, simplify)
    return has_key(path, "loss")


def _write_manifest(out: Path, materials, labels, metrics, settings: dict) -> dict:
    """Write (or extend, on resume) ``sweep.json``; settings must match an existing one.

    Its ``models`` maps each model label to every static option of the model (``repr``).
    """
    from brdffit import models

    man = {"materials": {}, "models": {}, "metrics": [], "settings": settings}
    old_path = out / MANIFEST
    if old_path.exists():
        try:
            man = json.loads(old_path.read_text())
        except ValueError as e:
            raise SweepError(f"{old_path}: not a sweep manifest ({e})") from e
        for k in SETTINGS:
            if man["settings"].get(k) != settings[k]:
                raise SweepError(
                    f"{old_path}: setting {k}={man['settings'].get(k)!r} differs from "
                    f"{settings[k]!r}; resume with the same settings or use a new folder"
                )
    for m in materials:
        old = man["materials"].get(m.name)
        if old is not None and (old["kind"], old["path"], old["spec"]) != (m.kind, m.path, m.spec):
            raise SweepError(f"{old_path}: material {m.name} already comes from {old['path']}")
        man["materials"][m.name] = asdict(m)
    for label in labels:
        model = models.from_spec(label)
        man["models"][label] = {k: repr(v) for k, v in model.options().items()}
    man["metrics"] = list(dict.fromkeys([*man["metrics"], *metrics]))
    write_text(old_path, json.dumps(man, indent=1))
    return man


def run_sweep(
    out: str | os.PathLike[str],
    materials: Sequence[Material],
    models: Sequence[str],
    metrics: Sequence[str],
    *,
    stride: tuple[int, int, int] | int = (1, 1, 1),
    cut_deg: float | None = 80.0,
    n_restarts: int = 1,
    screen: int = 32,
    seed: int = 0,
    max_steps: int = 512,
    eval_n: int = 65536,
    simplify: str | None = None,
    jobs: int | None = None,
    scheduler: str | None = None,
    batch: int = 1,
    progress: bool = True,
    announce=print,
) -> SweepSummary:
    """Fit every (material, model, metric) not yet finished in folder ``out``.

    Arguments:
    - ``materials``: from :func:`merl_materials`, :func:`nbrdf_materials`,
      :func:`rgl_materials`, :func:`table_materials` or :func:`synthetic_materials`;
      ``models``: model specs, ``name`` or ``name[k=v,...]``
      (:func:`brdffit.models.parse_spec`; each variant is fitted and ranked as a model of
      its own, specs of the same model counted once); ``metrics``: metric names.
    - ``stride``, ``cut_deg``, ``n_restarts``, ``screen``, ``seed``, ``max_steps``: as in
      :func:`brdffit.fit` and :func:`brdffit.io.load.load_measurements`; a resumed
      sweep must use the same values (else :class:`SweepError`).
    - ``eval_n``: samples of the evaluation-cost timing (module docstring).
    - ``simplify``: ``"cv"`` or ``"bic"`` runs :func:`brdffit.simplify` with that criterion
      after each fit and stores its record in the task's file under ``"simplify"``
      (:func:`brdffit.selection.survival.sweep_reduction`; read them with
      :func:`brdffit.selection.survival.survival_table`). A finished fit without that record is done
      again, so ``--simplify`` can be added to a finished sweep.
    - ``jobs``: worker processes of the LocalCluster (default ``os.cpu_count()``); 1
      without ``scheduler`` runs in this process.
    - ``scheduler``: a Dask scheduler address (``tcp://host:8786``) to run the tasks on
      (module docstring); its workers need brdffit installed and the material files at
      the same paths (or the synthetic recipe).
    - ``batch``: fit up to this many materials of one model and metric in one
      :func:`brdffit.fit_many` call (:func:`fit_chunk`; worth it on an accelerator, where
      the problems are vmapped, and on small grids).
    - ``progress``: show a tqdm bar (tasks, materials finished, time left).
    - ``announce``: gets the line naming the Dask scheduler and dashboard.

    Raises :class:`~brdffit.errors.ParameterError` for a bad model spec or metric and
    :class:`SweepError` for a bad setting or folder, or a folder another sweep is
    running in (:func:`sweep_lock`), before any fit.
    """
    from brdffit import models as registry
    from brdffit.engine.metrics import get_metric

    t0 = time.perf_counter()
    out = Path(out)
    if isinstance(stride, int):
        stride = (stride, stride, stride)
    # a bad spec fails before any work; equal variants (default options spelt out) merge
    labels = [registry.label(registry.from_spec(m)) for m in models]
    labels = list(dict.fromkeys(labels))
    for name in metrics:
        get_metric(name)
    if not materials or not labels or not metrics:
        raise SweepError("a sweep needs at least one material, one model and one metric")
    settings = dict(
        stride=list(stride), cut_deg=cut_deg, n_restarts=n_restarts, screen=screen, seed=seed,
        max_steps=max_steps,
    )  # fmt: skip
    settings["eval_n"] = eval_n
    if simplify is not None:
        from brdffit.selection.simplify import CRITERIA

        if simplify not in CRITERIA:
            raise SweepError(f"simplify={simplify!r}: use one of {', '.join(CRITERIA)}")
        settings["simplify"] = simplify
    out.mkdir(parents=True, exist_ok=True)
    with sweep_lock(out):  # a second sweep into this folder stops here
        _write_manifest(out, materials, labels, metrics, settings)
        remove_temporaries(out)
        tasks = [Task(m, mo, me, settings) for m in materials for mo in labels for me in metrics]
        todo = [t for t in tasks if not is_finished(t.path(out), simplify)]
        left = {m.name: sum(t.material.name == m.name for t in todo) for m in materials}
        counts = {"done": 0, "unconverged": 0, "errors": 0}
        bar = _progress_bar(len(todo), len(materials), sum(v == 0 for v in left.values()), progress)

        def record(chunk: Sequence[Task], outcomes: list[dict]) -> None:
            for task, outcome in zip(chunk, outcomes, strict=True):
                record_one(task, outcome)

        def record_one(task: Task, outcome: dict) -> None:
            status = write_outcome(out, task, outcome)
            counts["done"] += status["ok"]
            counts["unconverged"] += status["ok"] and not status["converged"]
            counts["errors"] += not status["ok"]
            left[task.material.name] -= 1
            n_mat = sum(v == 0 for v in left.values())
            bar.set_postfix_str(
                f"materials {n_mat}/{len(materials)}, last {task.material.name}/{task.model}",
                refresh=False,
            )
            bar.update(1)

        def crashed(chunk: Sequence[Task], e: BaseException) -> list[dict]:
            return [_failure(t, e) for t in chunk]

        if batch < 1:
            raise SweepError(f"batch={batch}; accepted: 1 or more materials per fit_many call")
        chunks = _chunks(todo, batch)
        workers = jobs or os.cpu_count() or 1
        try:
            if workers <= 1 and scheduler is None:
                for c in chunks:
                    record(c, fit_chunk(c))
            else:
                from brdffit.sweep.dask_runner import run_on_dask

                run_on_dask(
                    chunks, fit_chunk, record, crashed,
                    scheduler=scheduler, workers=workers, announce=announce,
                )  # fmt: skip
        finally:
            bar.close()
        return SweepSummary(
            str(out),
            len(tasks),
            len(tasks) - len(todo),
            counts["done"],
            counts["unconverged"],
            counts["errors"],
            time.perf_counter() - t0,
        )


def _chunks(tasks: Sequence[Task], size: int) -> list[tuple[Task, ...]]:
    """``tasks`` grouped by (model, metric), in order of first appearance, cut into
    chunks of at most ``size``."""
    groups: dict[tuple[str, str], list[Task]] = {}
    for t in tasks:
        groups.setdefault((t.model, t.metric), []).append(t)
    return [tuple(g[i : i + size]) for g in groups.values() for i in range(0, len(g), size)]


LOCK = ".sweep.lock"
"""The lock file a running sweep holds in its folder: ``<pid> <host>``."""
STALE_EMPTY_S = 10.0
"""An empty or garbled lock file older than this is a crash between its creation and
its first write: stale."""


def _pid_alive(pid: int) -> bool:
    """True when a process ``pid`` exists on this machine (signal 0 probes it)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by another user
        return True
    except (OSError, OverflowError):
        return False
    return True


def _lock_holder(path: Path) -> str | None:
    """Who holds the lock at ``path`` (``"process <pid> on <host>"``), or ``None`` when the
    lock is stale: its process is dead on this host, or the file is empty or garbled and
    older than :data:`STALE_EMPTY_S`."""
    try:
        text, age = path.read_text(), time.time() - path.stat().st_mtime
    except OSError:
        return None  # gone meanwhile
    fields = text.split()
    if not fields or not fields[0].isdigit():
        return None if age > STALE_EMPTY_S else "a sweep that is starting"
    pid, host = int(fields[0]), fields[1] if len(fields) > 1 else socket.gethostname()
    if host == socket.gethostname():
        return f"process {pid}" if _pid_alive(pid) else None
    return f"process {pid} on {host}"  # another machine's process: cannot be probed


@contextlib.contextmanager
def sweep_lock(out: str | os.PathLike[str]) -> Iterator[Path]:
    """Hold the lock of sweep folder ``out`` (:data:`LOCK`) while the block runs.

    Two sweeps in one folder would both fit every task; the second raises
    :class:`SweepError` naming the process that holds the folder. A lock left by a dead
    process (a kill, a crash) is taken over. The lock file is removed on leaving.
    """
    path = Path(out) / LOCK
    for _ in range(3):  # a stale lock is removed, then the creation is tried again
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            holder = _lock_holder(path)
            if holder is not None:
                raise SweepError(
                    f"{out}: another sweep is running in this folder ({holder}; lock file "
                    f"{path}); wait for it, or delete the lock file if that sweep is gone"
                ) from None
            path.unlink(missing_ok=True)
            continue
        with os.fdopen(fd, "w") as f:
            f.write(f"{os.getpid()} {socket.gethostname()}\n")
        break
    else:
        raise SweepError(f"{out}: cannot take the lock file {path}; another sweep keeps taking it")
    try:
        yield path
    finally:
        path.unlink(missing_ok=True)


def _progress_bar(total: int, n_materials: int, n_finished: int, enabled: bool):
    bar = progress_bar(total, "sweep", "fit", enabled)  # the bar rank and simplify show too
    bar.set_postfix_str(f"materials {n_finished}/{n_materials}", refresh=False)
    return bar
