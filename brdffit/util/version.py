"""The installed distribution's version (``None`` in a source tree that was not installed)."""

from importlib import metadata

try:
    __version__: str | None = metadata.version("brdffit")
except metadata.PackageNotFoundError:
    __version__ = None
