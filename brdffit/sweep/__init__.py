"""Sweeps: every (material, model, metric) fitted, each result a file, resumable, on one
machine or a Dask cluster.

- ``run``: :func:`run_sweep`, the manifest and the progress bar.
- ``materials``: the material lists (folders of files, synthetic recipes) and loading one.
- ``tasks``: one task's work (load, fit, time, reduce) and its result file.
- ``lock``: one sweep per folder at a time.
- ``dask_runner``: the package's one parallel runner (a LocalCluster or a scheduler's
  address); ``dask_plugin``: what each Dask worker runs when it starts.
"""

from brdffit.sweep.lock import sweep_lock
from brdffit.sweep.materials import (
    Material,
    load_material,
    merl_materials,
    nbrdf_materials,
    rgl_materials,
    synthetic_materials,
    table_materials,
    with_families,
)
from brdffit.sweep.run import SweepSummary, run_sweep

__all__ = [
    "Material",
    "SweepSummary",
    "load_material",
    "merl_materials",
    "nbrdf_materials",
    "rgl_materials",
    "run_sweep",
    "sweep_lock",
    "synthetic_materials",
    "table_materials",
    "with_families",
]
