"""JAX settings every brdffit process shares: 64-bit floats, and the on-disk compilation cache.

Importing this module (as ``import brdffit`` does first) turns on JAX's 64-bit mode: fits
run in float64 by default because measured BRDF values span 1e-4 to 1e4. float32
evaluation still works by passing float32 directions.
"""

import hashlib
import os
import platform
from importlib import metadata

import jax

jax.config.update("jax_enable_x64", True)

CACHE_MAX_BYTES = 4 << 30
"""Bound of the on-disk cache (bytes); the least recently used entries go first. Setting
any bound turns on JAX's file lock (below). 4 GiB is over twice what this project's
development machine gathered in three weeks across hundreds of source versions (1.6 GB):
programs of an earlier brdffit (whose source digest is in the key) are evicted, not kept
forever."""


def enable_compilation_cache(path: str | None = None) -> None:
    """Keep XLA executables on disk so later processes skip most compile time.

    ``path`` defaults to ``$BRDFFIT_JAX_CACHE`` or ``~/.cache/brdffit/jax``; setting
    ``BRDFFIT_JAX_CACHE=off`` disables it. The command line and the Dask workers call
    this; the test suite does not (see ``tests/conftest.py``).

    Entries go into a subfolder named after this host's CPU and jaxlib, because JAX's
    cache key names neither: a home folder shared by machines of different CPUs (a
    cluster's NFS home) would otherwise hand one machine code compiled for another,
    and XLA aborts the process while loading it, with no Python exception to catch.

    The cache is bounded (:data:`CACHE_MAX_BYTES`), and that is also what makes it safe
    to share between processes at once (a sweep's Dask workers, pytest-xdist's): without
    a bound JAX writes an entry in place and reads without a lock, so a process could
    load another's half-written executable, on which XLA aborts; with one, every read
    and write of the folder holds a file lock (``filelock``). A bounded cache keeps an
    access-time file beside each entry, and JAX fails on every write into a folder
    holding entries without one (as earlier brdffit versions' unbounded cache wrote), so
    the bounded cache has a folder of its own (``-lru`` in its name).
    """
    path = path or os.environ.get("BRDFFIT_JAX_CACHE", "~/.cache/brdffit/jax")
    if path.lower() in ("off", "0", "none", ""):
        return
    folder = os.path.join(os.path.expanduser(path), _host_tag())
    jax.config.update("jax_compilation_cache_dir", folder)
    jax.config.update("jax_compilation_cache_max_size", CACHE_MAX_BYTES)
    # every program, however quick to compile: a fit runs some 100 small ones (start
    # draws, affine solves), 20-30 ms each to compile and far less to load; with a 0.2 s
    # floor a fresh process compiled 93 of them again, 2.4 s of an 8.5 s first fit
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def _host_tag() -> str:
    """A short name for (machine, CPU model and flags, jaxlib version)."""
    cpu = ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            cpu = "".join(line for line in f if line.startswith(("model name", "flags")))[:20000]
    except OSError:
        cpu = platform.processor()
    try:
        jaxlib = metadata.version("jaxlib")
    except metadata.PackageNotFoundError:
        jaxlib = "unknown"
    digest = hashlib.sha256(f"{platform.machine()}|{cpu}|{jaxlib}".encode()).hexdigest()
    return f"{platform.machine()}-jaxlib{jaxlib}-{digest[:12]}-lru"
