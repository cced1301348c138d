"""Typed exceptions; each message names the file or parameter, the bad value, what is accepted."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager


class BrdffitError(Exception):
    """Base class of every error brdffit raises on purpose."""


class MeasurementFileError(BrdffitError, ValueError):
    """A measurement file is missing, unreadable or malformed; ``path`` names it."""

    def __init__(self, path: object, problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


@contextmanager
def reading(path: object, expected: str) -> Iterator[None]:
    """Inside the block, the operating system's refusals to read ``path`` become
    :class:`MeasurementFileError`: no such file, a directory (``expected`` says what was
    wanted: ``"a MERL .binary file"``), permission denied, any other ``OSError``."""
    try:
        yield
    except FileNotFoundError:
        raise MeasurementFileError(path, "no such file") from None
    except IsADirectoryError:
        raise MeasurementFileError(path, f"is a directory; expected {expected}") from None
    except PermissionError:
        raise MeasurementFileError(path, "permission denied; cannot read the file") from None
    except OSError as e:
        raise MeasurementFileError(path, f"cannot be read: {e.strerror or e}") from None


class ParameterError(BrdffitError, ValueError):
    """A parameter name, value, shape or option is not accepted by a model or a call."""


class MeasurementsError(BrdffitError, ValueError):
    """Arrays given to build measurements have the wrong shape, dtype or content."""


class FitError(BrdffitError, RuntimeError):
    """A fit failed and ``throw=True`` was asked for; ``result`` still holds what was found."""

    def __init__(self, message: str, result: object = None) -> None:
        self.result = result
        super().__init__(message)


class ChainTooShortError(BrdffitError, RuntimeError):
    """An MCMC chain is shorter than the asked number of autocorrelation times.

    ``estimate`` carries the autocorrelation times measured anyway.
    """

    def __init__(self, message: str, estimate: object = None) -> None:
        self.estimate = estimate
        super().__init__(message)


class SweepError(BrdffitError, ValueError):
    """A sweep folder, material source or sweep setting is not usable; the message names it."""


class MissingDependencyError(BrdffitError, ImportError):
    """An optional dependency is not installed; the message names the extra to install."""


class ExportError(BrdffitError, ValueError):
    """An export target is unknown, or the fit cannot be written to it; says which."""


class ExportValueError(ExportError):
    """A value to export is not finite or not writable; ``parameter`` names it."""

    def __init__(self, parameter: str, value: object, message: str) -> None:
        self.parameter = parameter
        self.value = value
        super().__init__(message)
