"""Reusable argument checks: ``check_*(value, /, *, name=...)``.

Each raises a :class:`~servosurf.errors.ServosurfError` subclass whose message names
the argument, the constraint and the value received.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import ConfigError

__all__ = [
    "check_positive",
    "check_nonnegative",
    "check_finite",
    "check_in_range",
    "check_array",
    "check_no_kwargs",
]


def check_finite(value: float, /, *, name: str) -> float:
    """Return ``value`` as float if finite, else raise :class:`ConfigError`."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ConfigError(f"{name} must be finite, got {value!r}")
    return v


def check_positive(value: float, /, *, name: str) -> float:
    """Return ``value`` as float if finite and > 0, else raise :class:`ConfigError`."""
    v = check_finite(value, name=name)
    if v <= 0:
        raise ConfigError(f"{name} must be > 0, got {value!r}")
    return v


def check_nonnegative(value: float, /, *, name: str) -> float:
    """Return ``value`` as float if finite and >= 0, else raise :class:`ConfigError`."""
    v = check_finite(value, name=name)
    if v < 0:
        raise ConfigError(f"{name} must be >= 0, got {value!r}")
    return v


def check_in_range(
    value: float, /, *, name: str, low: float, high: float, unit: str = ""
) -> float:
    """Return ``value`` if ``low <= value <= high``, else raise :class:`ConfigError`."""
    v = check_finite(value, name=name)
    if not (low <= v <= high):
        u = f" {unit}" if unit else ""
        raise ConfigError(f"{name} must be in [{low:g}, {high:g}]{u}, got {value!r}")
    return v


def check_array(
    value,
    /,
    *,
    name: str,
    ndim: int | None = None,
    finite: bool = False,
    min_size: int = 1,
    dtype=np.float64,
) -> np.ndarray:
    """Return ``value`` as a contiguous array after checking its shape and values."""
    try:
        a = np.ascontiguousarray(value, dtype=dtype)
    except (TypeError, ValueError):
        raise ConfigError(
            f"{name} must be a numeric array, got {type(value).__name__}"
        ) from None
    if ndim is not None and a.ndim != ndim:
        raise ConfigError(f"{name} must be {ndim}-dimensional, got shape {a.shape}")
    if a.size < min_size:
        raise ConfigError(
            f"{name} must have at least {min_size} element(s), got {a.size}"
        )
    if finite and not np.all(np.isfinite(a)):
        raise ConfigError(f"{name} must have finite values")
    return a


def check_no_kwargs(kwargs: dict, /, *, name: str) -> None:
    """Raise ``TypeError`` when ``kwargs`` is not empty (unknown keyword arguments)."""
    if kwargs:
        keys = ", ".join(sorted(kwargs))
        raise TypeError(f"{name}() got unexpected keyword argument(s): {keys}")
