"""Freed memory kept for reuse: glibc ``malloc`` settings for XLA's large buffers.

XLA on the CPU takes each program's outputs and temporary buffer from ``malloc`` at
every call and frees them after. glibc serves a request above its mmap threshold (at
most 32 MiB) with a fresh ``mmap`` and gives it back with ``munmap`` on ``free``, and it
returns the free top of its heap to the kernel past a trim threshold (threads other than
the first allocate from heaps of their own). So a program that needs 100 MB of buffers
touches 100 MB of fresh pages on every call, and each 4 KiB page costs a fault and the
kernel zeroing it. On a full MERL grid that is a third of what a cheap model's
linearisation costs: Lambert's, 27,000 faults and 72 ms a call, 47 ms without the faults
(``benchmarks/results/fit_lm.md``). Dask starts its workers with a trim threshold of
64 KiB, which gives the heap's free top back as well.

The same program measured with each setting alone (scratch profile, Lambert's
linearisation on a full MERL grid): no ``mmap`` and no trimming left the faults as they
were; one heap for all threads as well took them to none. :func:`keep_freed_memory`
sets all three, as PyTorch's CPU tuning guide advises an allocator that reuses memory
(jemalloc, tcmalloc) for the same reason: no ``mmap`` for large requests
(``M_MMAP_MAX = 0``; ``malloc`` still falls back to ``mmap`` when the heap cannot
grow), no trimming below 2 GiB of free top (``M_TRIM_THRESHOLD``, the largest value
``mallopt`` takes) and one heap for all threads (``M_ARENA_MAX = 1``). The cost: the
process holds on to its peak memory until it exits (``malloc_trim`` gives it back).

The ``brdffit`` command and a sweep's worker processes call it; a script or notebook
that fits at full resolution may call it first (before JAX runs anything, so that XLA's
threads start on the shared heap). ``BRDFFIT_MALLOC=system`` turns it off everywhere.
Elsewhere than Linux with glibc it does nothing.
"""

from __future__ import annotations

import ctypes
import os
import platform

_M_TRIM_THRESHOLD, _M_MMAP_MAX, _M_ARENA_MAX = -1, -4, -8
"""``mallopt`` parameter numbers (glibc's ``malloc.h``)."""

TRIM_THRESHOLD = 2**31 - 1
"""Free top of the heap kept (bytes): the largest value ``mallopt`` takes (a C ``int``)."""

ENVIRONMENT = {
    "MALLOC_MMAP_MAX_": "0",
    "MALLOC_TRIM_THRESHOLD_": str(TRIM_THRESHOLD),
    "MALLOC_ARENA_MAX": "1",
}
"""The same settings for a process glibc has not started yet: its environment
variables, read once at start-up (a sweep's Dask workers get them so)."""


def wanted() -> bool:
    """Whether this process runs glibc and ``BRDFFIT_MALLOC`` is not ``system``."""
    if os.environ.get("BRDFFIT_MALLOC", "").lower() == "system":
        return False
    return platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"


def keep_freed_memory() -> bool:
    """Make this process's ``malloc`` keep freed memory for reuse (module docstring).

    Returns whether the settings took effect: False where :func:`wanted` is False or
    glibc refused one. Calling it again changes nothing. Call it before JAX runs
    anything: a thread that has already allocated keeps the heap it had.
    """
    if not wanted():
        return False
    libc = ctypes.CDLL("libc.so.6")
    done = [
        libc.mallopt(_M_ARENA_MAX, 1),
        libc.mallopt(_M_MMAP_MAX, 0),
        libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD),
    ]
    return all(done)
