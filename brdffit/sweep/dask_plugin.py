"""The Dask worker plugin of brdffit's jobs: the persistent compilation cache turned on
in every worker (:func:`brdffit.enable_compilation_cache`).

Its own module because it subclasses Dask's ``WorkerPlugin`` at import: only
:func:`brdffit.sweep.dask_runner.run_on_dask` imports it, so ``import brdffit.sweep``
does not import ``distributed``. The class is module-level: Dask pickles it to every
worker by reference.
"""

from __future__ import annotations

from distributed.diagnostics.plugin import WorkerPlugin

from brdffit.util.jax_config import enable_compilation_cache


class CompileCache(WorkerPlugin):
    """Turns on brdffit's persistent compilation cache in every worker it starts."""

    name = "brdffit-compile-cache"

    def setup(self, worker) -> None:  # noqa: ARG002 (Dask's signature)
        enable_compilation_cache()
