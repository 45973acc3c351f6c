"""Exception hierarchy of servosurf.

Every error a user can cause derives from :class:`ServosurfError`. Concrete classes
also derive from a builtin so callers may catch ``ValueError`` or ``OSError``. The CLI
turns any :class:`ServosurfError` into one line on stderr and exit status 1.

Messages follow one template: *name + constraint + actual value (+ remedy)*.
"""

from __future__ import annotations

__all__ = [
    "ServosurfError",
    "ConfigError",
    "UnitError",
    "FileFormatError",
    "UnsupportedFileFormatError",
    "CorruptedFileError",
    "ModelError",
]


class ServosurfError(Exception):
    """Base class of every error raised on purpose by servosurf."""

    def __reduce__(self):  # picklable across processes (dask, multiprocessing)
        return (self.__class__, self.args)


class ConfigError(ValueError, ServosurfError):
    """A configuration value, key or file is invalid."""


class UnitError(ValueError, ServosurfError):
    """A unit string is unknown or inconsistent."""


class FileFormatError(ServosurfError):
    """A file cannot be read or written in the requested format."""


class UnsupportedFileFormatError(FileFormatError):
    """No reader or writer is registered for this file or suffix."""


class CorruptedFileError(FileFormatError):
    """The file claims a known format but its content is inconsistent or truncated."""


class ModelError(ValueError, ServosurfError):
    """A model cannot be built or evaluated with the given parameters."""
