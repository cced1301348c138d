"""Helpers with no BRDF in them, used by every layer above.

- ``atomic``: atomic file writes (bytes, text, JSON, figures) and leftover temporaries.
- ``text_table``: text, Markdown, CSV and HTML tables.
- ``progress``: the progress bar of long commands, on stderr.
- ``jax_config``: JAX's 64-bit mode and the on-disk compilation cache.
- ``programs``: the fit's jitted functions exported ahead of time and kept in that cache.
- ``version``: the installed distribution's version.

The submodules are imported by name; this package re-exports nothing.
"""
