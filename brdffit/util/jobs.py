"""Resumable jobs in worker processes, and the progress bar of every long command.

A job's ``work`` writes its own result file atomically (:mod:`brdffit.util.atomic`) and
returns a small status; a job whose file is finished is skipped by the caller before
it gets here, so an interrupted run resumes and a kill loses only the jobs in flight.
Workers are processes started with ``spawn`` (JAX is not fork-safe), each with the
persistent compilation cache on.
"""

from __future__ import annotations

import concurrent.futures as cf
import json
import multiprocessing
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TypeVar

from brdffit.util.atomic import write_text
from brdffit.util.jax_config import enable_compilation_cache

J = TypeVar("J")
R = TypeVar("R")


def run_jobs(
    jobs: Sequence[J],
    work: Callable[[J], R],
    record: Callable[[J, R], None],
    crashed: Callable[[J, BaseException], R],
    processes: int = 1,
) -> None:
    """``record(job, work(job))`` for every job, as each finishes.

    ``processes <= 1`` runs them here, in order; otherwise in that many spawned workers
    (``work`` must then be picklable: a module-level function or a ``functools.partial``
    of one). A worker that dies gives ``crashed(job, error)`` instead of a result; an
    exception or interrupt in the caller cancels the jobs not yet started.
    """
    if processes <= 1:
        for job in jobs:
            record(job, work(job))
        return
    ctx = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(
        max_workers=processes, mp_context=ctx, initializer=enable_compilation_cache
    ) as pool:
        futures = {pool.submit(work, job): job for job in jobs}
        try:
            for fut in cf.as_completed(futures):
                job = futures[fut]
                try:
                    result = fut.result()
                except Exception as e:  # a dead worker: its job is recorded as crashed
                    result = crashed(job, e)
                record(job, result)
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def write_json(path: str | Path, payload: dict) -> None:
    """Write ``payload`` as indented JSON to ``path`` atomically, making its folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(payload, indent=1))


def has_key(path: str | Path, key: str) -> bool:
    """True when ``path`` is a JSON object file that parses and holds ``key``."""
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(d, dict) and key in d


def progress_bar(total: int | None, desc: str, unit: str, enabled: bool = True):
    """The tqdm bar of a long command on stderr (``sweep``, ``rank``, ``simplify``):
    ``total`` steps of ``unit`` (``None``: count only); ``enabled=False`` shows nothing.
    Write a finished step's line above it with :func:`progress_line`."""
    from tqdm.auto import tqdm

    return tqdm(
        total=total, desc=desc, unit=unit, disable=not enabled, dynamic_ncols=True,
        file=sys.stderr,
    )  # fmt: skip


def progress_line(bar, text: str) -> None:
    """``text`` as one line on stderr above ``bar`` (nothing when the bar is disabled)."""
    if not bar.disable:
        bar.write(text, file=sys.stderr)
