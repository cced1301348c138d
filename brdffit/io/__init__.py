"""Readers and writers of measurement files, and synthetic measurements.

- ``load``: open a measurement file by its kind, picked by its suffix.
- ``merl``: the MERL binary format: read and write.
- ``merl_grid``: the MERL grid: geometry, strided sub-grids, Measurements on it, lookup.
- ``nbrdf``: neural BRDFs (NBRDF): the network, evaluated in numpy, and its Measurements.
- ``keras_file``: the Keras files of an NBRDF: JSON architecture and HDF5 weights.
- ``rgl``: RGL-EPFL ``.bsdf`` materials, evaluated through Mitsuba 3.
- ``rgl_header``: the header of a Mitsuba tensor file, read without Mitsuba.
- ``table``: plain tables of BRDF samples (CSV or ``.npz``).
- ``spectra``: spectra to colour (CIE 1931, XYZ, linear sRGB).
- ``synthetic``: synthetic measurements from any model and parameters.

The submodules are imported by name; this package re-exports nothing (the main readers
are re-exported by :mod:`brdffit`).
"""
