"""Jobs on Dask distributed: a cluster at an address, or an in-process LocalCluster.

Dask does the scheduling and the recovery: a job whose worker dies is run again on
another worker (up to ``distributed.scheduler.allowed-failures`` times, 3 by default;
past that its future raises ``KilledWorker`` and the job is recorded as crashed). Each
job's result travels back to this client, which records it, so the workers need no file
system in common with the client and every result is recorded exactly once, however
often a lost worker made Dask compute it.

Without an address, :func:`run_on_dask` starts a ``LocalCluster`` of ``workers``
processes with one thread each (JAX and XLA use the cores of their process; spawned
processes, as JAX is not fork-safe), and closes it after the jobs. With an address
(``tcp://host:8786``, e.g. a cluster that ``dask-jobqueue`` started on SLURM or PBS),
it connects to that scheduler and leaves the cluster running. Every worker turns on
brdffit's persistent compilation cache (:func:`brdffit.enable_compilation_cache`) when
it starts (:class:`brdffit.sweep.dask_plugin.CompileCache`). A LocalCluster's workers
start with glibc set to keep freed memory for reuse
(:data:`brdffit.util.allocator.ENVIRONMENT`, in place of Dask's own
``MALLOC_TRIM_THRESHOLD_`` of 64 KiB, set for the opposite aim: memory given back
soon); workers of a named scheduler get it from the plugin, for the threads that start
after it.
"""

from __future__ import annotations

import logging
import socket
from collections.abc import Callable, Sequence
from typing import TypeVar

from brdffit.errors import MissingDependencyError, ParameterError
from brdffit.util import allocator

J = TypeVar("J")
R = TypeVar("R")


def _client(scheduler: str | None, workers: int, dashboard: str | None, timeout: float):
    """A Dask client and the LocalCluster it owns (``None`` for a named scheduler)."""
    try:
        import dask
        from dask.distributed import Client, LocalCluster  # deferred: optional, heavy
    except ImportError as e:
        raise MissingDependencyError(
            f"running jobs on Dask needs dask[distributed] ({e}): pip install 'dask[distributed]'"
        ) from None
    if scheduler:
        try:
            return Client(scheduler, timeout=f"{timeout}s"), None
        except (OSError, TimeoutError, ValueError) as e:
            raise ParameterError(
                f"--scheduler {scheduler}: no Dask scheduler answers there ({e}); give the "
                "address a running scheduler prints, e.g. tcp://host:8786"
            ) from None
    # set before each worker process starts, where glibc reads them (Dask's docs: only
    # ``pre-spawn-environ`` reaches glibc); the Nanny keeps them for restarts
    spawn = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    if allocator.wanted():
        spawn.update(allocator.ENVIRONMENT)
    with dask.config.set({"distributed.nanny.pre-spawn-environ": spawn}):
        cluster = LocalCluster(
            n_workers=max(1, workers),
            threads_per_worker=1,
            processes=True,
            dashboard_address=_free_port_or_any(dashboard),
            silence_logs=logging.ERROR,
        )
    return Client(cluster), cluster


def _free_port_or_any(address: str | None) -> str | None:
    """``address`` (``":8787"``) when its port is free here, else ``":0"`` (any free port:
    a second sweep on one machine gets its own dashboard instead of Dask's warning)."""
    if not address or not address.startswith(":"):
        return address
    with socket.socket() as s:
        try:
            s.bind(("", int(address[1:])))
        except OSError:
            return ":0"
    return address


def run_on_dask(
    jobs: Sequence[J],
    work: Callable[[J], R],
    record: Callable[[J, R], None],
    crashed: Callable[[J, BaseException], R],
    *,
    scheduler: str | None = None,
    workers: int = 1,
    dashboard: str | None = ":8787",
    announce: Callable[[str], None] = print,
    connect_timeout: float = 20.0,
) -> None:
    """``record(job, work(job))`` for every job, as each finishes, on Dask.

    Arguments:
    - ``jobs``, ``work``, ``record``, ``crashed``: as :func:`benchmarks.jobs.run_jobs` (the
      benchmarks' runner); ``work`` runs on the workers (a picklable function), ``record``
      here.
    - ``scheduler``: a Dask scheduler address, or ``None`` for a LocalCluster of
      ``workers`` processes (module docstring).
    - ``dashboard``: the LocalCluster's dashboard address (``":0"`` any free port, ``None``
      none); a remote cluster's is its own.
    - ``announce``: gets one line naming the scheduler and the dashboard.
    - ``connect_timeout``: seconds to wait for a named scheduler to answer.

    An exception or interrupt here cancels the jobs not yet finished and closes a
    LocalCluster; results already recorded stay recorded.
    """
    if not jobs:
        return
    from dask.distributed import as_completed  # deferred: optional, heavy

    from brdffit.sweep.dask_plugin import CompileCache  # deferred: imports distributed

    client, cluster = _client(scheduler, workers, dashboard, connect_timeout)
    try:
        client.register_plugin(CompileCache())
        where = scheduler or f"a local cluster of {max(1, workers)} worker processes"
        link = client.dashboard_link if (scheduler or dashboard) else "off"
        announce(f"dask: {where}; dashboard {link}")
        futures = client.map(work, list(jobs), pure=False)
        index = {f.key: k for k, f in enumerate(futures)}
        try:
            for fut in as_completed(futures):
                job = jobs[index[fut.key]]
                try:
                    result = fut.result()
                except Exception as e:  # KilledWorker after repeated worker deaths
                    result = crashed(job, e)
                record(job, result)
                fut.release()
        except BaseException:
            client.cancel(futures)
            raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
