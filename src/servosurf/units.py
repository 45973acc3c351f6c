"""Unit conversion at the boundaries (I/O and display only).

Everything inside servosurf is SI: metres, seconds, kilograms, newtons, hertz,
radians. This module holds the one table used to convert lengths on read and write.
"""

from __future__ import annotations

from .errors import UnitError

__all__ = ["LENGTH_UNITS", "length_factor", "normalise_unit"]

#: Length unit -> metres per unit.
LENGTH_UNITS: dict[str, float] = {
    "m": 1.0,
    "mm": 1e-3,
    "um": 1e-6,
    "nm": 1e-9,
    "pm": 1e-12,
    "a": 1e-10,  # angstrom
}

_ALIASES = {
    "meter": "m",
    "meters": "m",
    "metre": "m",
    "metres": "m",
    "millimeter": "mm",
    "millimeters": "mm",
    "millimetre": "mm",
    "micrometer": "um",
    "micrometers": "um",
    "micrometre": "um",
    "micron": "um",
    "microns": "um",
    "nanometer": "nm",
    "nanometers": "nm",
    "nanometre": "nm",
    "picometer": "pm",
    "angstrom": "a",
    "angstroms": "a",
    "å": "a",
}

_MU = ("\u00b5", "\u03bc")  # micro sign and Greek small mu


def normalise_unit(unit: str) -> str:
    """Return the canonical spelling of a length unit.

    Parameters
    ----------
    unit : str
        A length unit such as ``"µm"``, ``"MicroMeters"`` or ``"um"``.

    Returns
    -------
    str
        One of the keys of :data:`LENGTH_UNITS`.

    Raises
    ------
    UnitError
        If the unit is not a known length unit.
    """
    u = unit.strip()
    for mu in _MU:
        u = u.replace(mu, "u")
    key = u.lower()
    if key in LENGTH_UNITS:
        return key
    if key in _ALIASES:
        return _ALIASES[key]
    allowed = ", ".join(sorted(LENGTH_UNITS))
    raise UnitError(
        f"unknown length unit {unit!r}; allowed: {allowed} (or spelled out)"
    )


def length_factor(unit: str) -> float:
    """Return metres per ``unit``.

    Parameters
    ----------
    unit : str
        A length unit (see :func:`normalise_unit`).

    Returns
    -------
    float
        The factor that converts a value in ``unit`` to metres.
    """
    return LENGTH_UNITS[normalise_unit(unit)]
