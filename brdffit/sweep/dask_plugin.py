"""The Dask worker plugin of brdffit's jobs: the persistent compilation cache turned on
in every worker (:func:`brdffit.enable_compilation_cache`), and freed memory kept for
reuse (:func:`brdffit.util.allocator.keep_freed_memory`).

Its own module because it subclasses Dask's ``WorkerPlugin`` at import: only
:func:`brdffit.sweep.dask_runner.run_on_dask` imports it, so ``import brdffit.sweep``
does not import ``distributed``. The class is module-level: Dask pickles it to every
worker by reference.
"""

from __future__ import annotations

from distributed.diagnostics.plugin import WorkerPlugin

from brdffit.util.allocator import keep_freed_memory
from brdffit.util.jax_config import enable_compilation_cache


class CompileCache(WorkerPlugin):
    """Turns on brdffit's persistent compilation cache in every worker it starts, and
    keeps freed memory there (a LocalCluster's workers have it from their start)."""

    name = "brdffit-compile-cache"

    def setup(self, worker) -> None:  # noqa: ARG002 (Dask's signature)
        keep_freed_memory()
        enable_compilation_cache()
