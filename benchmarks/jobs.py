"""Resumable jobs in worker processes, for the benchmarks (the package's sweeps run on Dask).

A job's ``work`` writes its own result file atomically (:mod:`brdffit.util.atomic`) and
returns a small status; a job whose file is finished is skipped by the caller before
it gets here, so an interrupted run resumes and a kill loses only the jobs in flight.
Workers are processes started with ``spawn`` (JAX is not fork-safe), each with the
persistent compilation cache on.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
from collections.abc import Callable, Sequence
from typing import TypeVar

from brdffit import enable_compilation_cache

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
