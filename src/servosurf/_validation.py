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
    "check_plausible",
    "unit_slip",
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


#: Unit slips tried per SI unit: (name, factor to SI) of the units people type.
_SLIPS = {
    "m": (("nm", 1e-9), ("um", 1e-6), ("mm", 1e-3), ("cm", 1e-2)),
    "Hz": (("kHz", 1e3), ("MHz", 1e6), ("rpm", 1.0 / 60.0)),
    "rev/s": (("rpm", 1.0 / 60.0),),
    "s": (("ms", 1e-3), ("us", 1e-6), ("min", 60.0)),
    "kg": (("g", 1e-3), ("mg", 1e-6)),
    "m/s": (("mm/s", 1e-3), ("mm/min", 1e-3 / 60.0), ("m/min", 1.0 / 60.0)),
    "Pa": (("MPa", 1e6), ("GPa", 1e9), ("N/mm^2", 1e6)),
    "rad": (("degree", 0.017453292519943295),),
}


def unit_slip(value: float, unit: str, low: float, high: float,
              typical: float | None = None) -> str:
    """The likeliest unit slip that brings ``value`` into ``[low, high]``.

    Parameters
    ----------
    value : float
        The value given, read in ``unit``.
    unit : str
        Its SI unit (``m``, ``Hz``, ``kg``, ...).
    low, high : float
        The plausible range, in ``unit``.
    typical : float, optional
        A typical value (the default), in ``unit``; default: the geometric middle
        of the range.

    Returns
    -------
    str
        E.g. ``"10 um = 1e-05 m"``, or "" when no usual unit fits. Among fitting
        units the one landing nearest the typical value (on a log scale) wins.

    Examples
    --------
    >>> unit_slip(10, "m", 1e-9, 5e-3)
    '10 um = 1e-05 m'
    """
    best, score = "", math.inf
    if typical is not None and typical > 0:
        mid = math.log10(typical)
    else:
        mid = math.log10(math.sqrt(low * high)) if low > 0 and high > 0 else None
    for name, factor in _SLIPS.get(unit, ()):
        v = value * factor
        if low <= v <= high:
            d = abs(math.log10(abs(v)) - mid) if (mid is not None and v) else 0.0
            if d < score:
                best, score = f"{value:g} {name} = {v:.4g} {unit}", d
    return best


def check_plausible(value: float, /, *, name: str, unit: str, low: float,
                    high: float, what: str = "",
                    typical: float | None = None) -> float:
    """Refuse a finite but physically absurd value, naming the likely unit slip.

    Parameters
    ----------
    value : float
        The value, in ``unit`` (SI).
    name : str
        The TOML key or CLI flag to name.
    unit : str
        SI unit of the value.
    low, high : float
        Plausible range, in ``unit``.
    what : str, optional
        What the value is (e.g. "zero-to-peak tool amplitude").
    typical : float, optional
        A typical value in ``unit``, to pick the likeliest slip (see
        :func:`unit_slip`).

    Returns
    -------
    float
        ``value``.

    Raises
    ------
    ConfigError
        One line: key, value, unit, the plausible range and the likely slip.
    """
    v = check_finite(value, name=name)
    if low <= v <= high or (v == 0 and low <= 0):
        return v
    slip = unit_slip(v, unit, low, high, typical)
    hint = f"; values are SI ({unit}): did you mean {slip}?" if slip else ""
    desc = f" ({what})" if what else ""
    raise ConfigError(
        f"{name} = {value:g} {unit}{desc} is outside the plausible range "
        f"{low:g}..{high:g} {unit}{hint}"
    )


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
