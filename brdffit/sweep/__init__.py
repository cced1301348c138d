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
