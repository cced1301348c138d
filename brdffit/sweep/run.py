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
the model's own evaluation at the fitted parameters, best of 3 warm measurements, on
the material's valid directions tiled to ``eval_n`` samples, with the shading geometry
computed beforehand (:func:`brdffit.engine.timing.eval_ns_per_sample`, the timer
:func:`brdffit.simplify` uses too).

Engine: Dask distributed (:mod:`brdffit.sweep.dask_runner`). With ``scheduler`` the tasks run on
that cluster; without it on a LocalCluster of ``jobs`` worker processes (default one
per core), so a lost worker's task is run again elsewhere and its result is still
written once. ``jobs=1`` without a scheduler runs the tasks in the calling process.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from brdffit.engine.metrics import get_metric
from brdffit.errors import SweepError
from brdffit.models import registry
from brdffit.selection.simplify import CRITERIA
from brdffit.selection.survival import has_reduction
from brdffit.sweep.dask_runner import run_on_dask
from brdffit.sweep.lock import sweep_lock
from brdffit.sweep.materials import Material
from brdffit.sweep.tasks import Task, _failure, fit_chunk, write_outcome
from brdffit.util.atomic import has_key, remove_temporaries, write_text
from brdffit.util.progress import progress_bar

MANIFEST = "sweep.json"
SETTINGS = ("stride", "cut_deg", "n_restarts", "screen", "seed", "max_steps", "eval_n")


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


def is_finished(path: Path, simplify: str | None = None) -> bool:
    """True when ``path`` is a result file that parses and has a loss (and, with
    ``simplify``, a reduction made with that criterion:
    :func:`brdffit.selection.survival.has_reduction`)."""
    if simplify:
        return has_reduction(path, simplify)
    return has_key(path, "loss")


def _write_manifest(out: Path, materials, labels, metrics, settings: dict) -> dict:
    """Write (or extend, on resume) ``sweep.json``; settings must match an existing one.

    Its ``models`` maps each model label to every static option of the model (``repr``).
    """
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
        model = registry.from_spec(label)
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
    - ``materials``: from :func:`~brdffit.sweep.materials.merl_materials`,
      :func:`~brdffit.sweep.materials.nbrdf_materials`,
      :func:`~brdffit.sweep.materials.rgl_materials`,
      :func:`~brdffit.sweep.materials.table_materials` or
      :func:`~brdffit.sweep.materials.synthetic_materials`;
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
      :func:`brdffit.fit_many` call (:func:`brdffit.sweep.tasks.fit_chunk`; worth it on an
      accelerator, where the problems are vmapped, and on small grids).
    - ``progress``: show a tqdm bar (tasks, materials finished, time left).
    - ``announce``: gets the line naming the Dask scheduler and dashboard.

    Raises :class:`~brdffit.errors.ParameterError` for a bad model spec or metric and
    :class:`SweepError` for a bad setting or folder, or a folder another sweep is
    running in (:func:`brdffit.sweep.lock.sweep_lock`), before any fit.
    """
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
    chunks of at most ``size``; with ``size`` 1, one task a chunk in the order given.

    ``tasks`` come material by material, and a worker keeps the last material it loaded
    (:func:`brdffit.sweep.tasks.fit_task`), so single tasks stay in that order: grouped by
    model, every fit would load its material again (0.4 s for an NBRDF material at full
    resolution, where a fit of a cheap model takes a few seconds)."""
    if size == 1:
        return [(t,) for t in tasks]
    groups: dict[tuple[str, str], list[Task]] = {}
    for t in tasks:
        groups.setdefault((t.model, t.metric), []).append(t)
    return [tuple(g[i : i + size]) for g in groups.values() for i in range(0, len(g), size)]


def _progress_bar(total: int, n_materials: int, n_finished: int, enabled: bool):
    bar = progress_bar(total, "sweep", "fit", enabled)  # the bar rank and simplify show too
    bar.set_postfix_str(f"materials {n_finished}/{n_materials}", refresh=False)
    return bar
