"""Jobs on Dask (brdffit.sweep.dask_runner): every result recorded once, a lost worker's job run
again elsewhere, a bad scheduler address named, workers started with glibc set to keep
freed memory."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

pytest.importorskip("distributed")

from brdffit import ParameterError
from brdffit.sweep.dask_runner import run_on_dask  # noqa: E402
from brdffit.util import allocator


def square_or_die(job: tuple[int, str]) -> int:
    """``k * k``; job 3 kills its worker process the first time it runs (a marker file
    says it already did), as a node lost mid-task would."""
    k, marker = job
    if k == 3 and not Path(marker).exists():
        Path(marker).write_text(str(os.getpid()))
        os._exit(1)
    return k * k


def test_a_killed_worker_loses_nothing_and_records_each_result_once(tmp_path):
    marker = str(tmp_path / "killed")
    jobs = [(k, marker) for k in range(8)]
    got: list[tuple[int, int]] = []
    lines: list[str] = []
    run_on_dask(
        jobs,
        square_or_die,
        lambda job, r: got.append((job[0], r)),
        lambda job, e: pytest.fail(f"job {job} crashed: {e!r}"),
        workers=2,
        dashboard=None,
        announce=lines.append,
    )
    assert Path(marker).exists()  # a worker really died mid-job
    assert sorted(got) == [(k, k * k) for k in range(8)]  # each once, none lost
    assert lines and "local cluster of 2 worker processes" in lines[0]


def malloc_environment(_job: int) -> dict[str, str | None]:
    """The worker's glibc settings, as its environment gave them at its start."""
    return {k: os.environ.get(k) for k in allocator.ENVIRONMENT}


@pytest.mark.skipif(not allocator.wanted(), reason="needs Linux with glibc")
def test_local_workers_start_with_freed_memory_kept():
    got: list[dict] = []
    run_on_dask(
        [0],
        malloc_environment,
        lambda job, r: got.append(r),
        lambda job, e: pytest.fail(f"job {job} crashed: {e!r}"),
        workers=1,
        dashboard=None,
        announce=lambda line: None,
    )
    assert got == [allocator.ENVIRONMENT]  # not Dask's MALLOC_TRIM_THRESHOLD_ of 65536


def test_an_unreachable_scheduler_is_a_parameter_error():
    with pytest.raises(ParameterError, match="tcp://127.0.0.1:9"):
        run_on_dask(
            [1],
            abs,
            lambda *a: None,
            lambda *a: None,
            scheduler="tcp://127.0.0.1:9",
            connect_timeout=1.0,
        )
