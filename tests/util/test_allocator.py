"""Freed memory kept for reuse (:mod:`brdffit.util.allocator`): a program whose buffers
exceed glibc's mmap threshold faults its pages in again on every call, unless the
settings are made in the process (``mallopt``) or given to it at its start (the
environment a sweep's Dask workers get). Each case runs in a fresh interpreter: the
settings are the process's, and one heap for all threads works only from its start."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from brdffit.util import allocator

pytestmark = pytest.mark.skipif(not allocator.wanted(), reason="needs Linux with glibc")

PAGES = (8 << 20) * 8 // 4096
"""4 KiB pages of the 64 MiB (2^23 float64) array that the program below writes each call."""

PROGRAM = """
import resource, sys
from brdffit.util import allocator
applied = allocator.keep_freed_memory() if sys.argv[1] == "call" else False
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
x = jnp.arange(2**23, dtype=jnp.float64)
f = jax.jit(lambda x: x * 2.0 + 1.0)
for _ in range(10):
    jax.block_until_ready(f(x))
faults = []
for _ in range(21):
    r0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    jax.block_until_ready(f(x))
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - r0)
print(applied, sorted(faults)[10])
"""


def _median_faults(how: str, env: dict[str, str]) -> tuple[str, float]:
    """``(applied, minor page faults of the median call)`` of :data:`PROGRAM` in a fresh
    process (the median: now and then a call grows the heap, a fault for each new page)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")} | env
    out = subprocess.run(
        [sys.executable, "-c", PROGRAM, how], env=env, capture_output=True, text=True, check=True
    )
    applied, faults = out.stdout.split()[-2:]
    return applied, float(faults)


def test_kept_memory_is_reused_without_page_faults():
    applied, faults = _median_faults("call", {})
    assert applied == "True"
    assert faults < 0.02 * PAGES, f"{faults:.0f} faults in the median call for {PAGES} pages"


def test_the_environment_gives_a_new_process_the_same_settings():
    _, faults = _median_faults("no", dict(allocator.ENVIRONMENT))
    assert faults < 0.02 * PAGES, f"{faults:.0f} faults in the median call for {PAGES} pages"


def test_without_the_settings_the_pages_fault_in_again():
    # what the settings are for: glibc maps a buffer over 32 MiB afresh at every call
    # (a kernel that backs all memory with huge pages faults far less: then skip)
    _, faults = _median_faults("no", {})
    if faults < 0.02 * PAGES:
        pytest.skip(f"{faults:.0f} faults a call: this kernel maps huge pages by default")
    assert faults > 0.5 * PAGES


def test_brdffit_malloc_system_turns_it_off(monkeypatch):
    monkeypatch.setenv("BRDFFIT_MALLOC", "system")
    assert not allocator.wanted()
    assert allocator.keep_freed_memory() is False
