"""Exports of a fitted material to renderers: Mitsuba 3, glTF 2.0, MaterialX (OpenPBR).

``export(result, target)`` maps a :class:`~brdffit.FitResult` to one target and says,
by measurement, how well: it evaluates the exported material (with this package's own
implementation of the target's BRDF, checked against Mitsuba 3 and an independent
glTF implementation by the tests) and the model at :func:`error_directions`, and
reports the relative RMS error of ``f cos(theta_i)`` and the RMS error of
``ln(1 + f cos(theta_i))`` (:data:`ERROR_DEFINITION`). An export is *exact* when the
relative error is at float64 round-off (``EXACT_TOL``); otherwise every candidate form
the target offers is fitted to the model by least squares (on the log error), the one
with the least log error is written, and the errors are those left.

Every number written passes one rule, :mod:`brdffit.export._numbers`: finite (else
:class:`~brdffit.errors.ExportValueError` naming it, before any file is written), a
value within resolution of a bound written as the bound, and 0 or a normal float32
(Mitsuba parses with ``std::stof``, which throws on subnormals). ``Export.target_model``
names exactly what was written (for Mitsuba the BSDF tree).

Targets (each module documents its mapping, roughness convention and losses):

* ``"mitsuba"`` -- a BSDF dict for ``mi.load_dict`` and the same BSDF as XML
  (:mod:`brdffit.export.mitsuba`);
* ``"gltf"`` -- a glTF 2.0 document holding one material, ``pbrMetallicRoughness`` with
  ``KHR_materials_specular``, ``_ior``, ``_anisotropy``, ``_clearcoat``, ``_sheen``,
  ``_iridescence`` where they apply (:mod:`brdffit.export.gltf`);
* ``"materialx"`` -- a MaterialX document with an ``open_pbr_surface``, the fit itself
  for ``openpbr``, an OpenPBR surface fitted to the model otherwise
  (:mod:`brdffit.export.materialx`).

Which fit to export (fitted under ``ngan``, else the note of :func:`render_note`), and
the functions themselves: :mod:`brdffit.export.api`.

``write_exports(result, targets, prefix)`` writes the files atomically:
``PREFIX.mitsuba.xml`` and ``PREFIX.mitsuba.json``, ``PREFIX.gltf``, ``PREFIX.mtlx``.
"""

from brdffit.errors import ExportError, ExportValueError
from brdffit.export._match import (
    ERROR_DEFINITION,
    EXACT_TOL,
    albedo_directions,
    error_directions,
    log_rms,
    relative_rms,
)
from brdffit.export.api import (
    RENDER_METRIC,
    TARGETS,
    Export,
    check_targets,
    default_prefix,
    evaluate_model,
    export,
    parse_targets,
    render_note,
    write_exports,
)

__all__ = [
    "ERROR_DEFINITION",
    "EXACT_TOL",
    "RENDER_METRIC",
    "TARGETS",
    "Export",
    "ExportError",
    "ExportValueError",
    "albedo_directions",
    "check_targets",
    "default_prefix",
    "error_directions",
    "evaluate_model",
    "export",
    "log_rms",
    "parse_targets",
    "relative_rms",
    "render_note",
    "write_exports",
]
