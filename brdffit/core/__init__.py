"""The core: the data and types every other layer shares, with no fitting in them.

- ``geometry``: directions, Rusinkiewicz half/difference angles, the MERL bins and weights.
- ``measurements``: :class:`~brdffit.core.measurements.Measurements`, one container for samples.
- ``parameters``: model parameters: the table row, the optimiser transforms, flat packing.
- ``abstract_model``: the model contract every file in ``brdffit/models/`` follows.
- ``result``: :class:`~brdffit.core.result.FitResult`, its report, its JSON form.

The submodules are imported by name; this package re-exports nothing.
"""
