"""ZYGO Mx profile exports (``.csv``): one line per sample, ``X, Y, Slice``.

Mx writes a header line ``X ,Y ,Slice`` (padded with spaces) and rows of position
along the profile, height and slice label, both numbers in micrometres unless the
header names a unit (``X (mm)``, ``Y [nm]``). Only the first slice is read; missing
samples (gaps in X) and empty or ``NaN``/``No Data`` heights become NaN.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import UnitError
from ..metrology import Profile
from ..units import length_factor
from ._common import Source, corrupt, decode_text
from ._registry import register_reader

__all__ = ["read_mx_profile_csv"]

_UNIT = re.compile(r"[\(\[]\s*([^\)\]]+?)\s*[\)\]]")
_X_NAMES = ("x", "position", "distance")
_Z_NAMES = ("y", "z", "height")


def _column(label: str) -> tuple[str, str | None]:
    m = _UNIT.search(label)
    unit = m.group(1) if m else None
    base = _UNIT.sub("", label).strip().lower()
    return base, unit


def _header(line: str) -> tuple[str, str | None, str, str | None] | None:
    parts = line.split(",")
    if len(parts) < 2:
        return None
    (xb, xu), (zb, zu) = _column(parts[0]), _column(parts[1])
    if xb not in _X_NAMES or zb not in _Z_NAMES:
        return None
    return xb, xu, zb, zu


def _is_mx_csv(data: bytes) -> bool:
    head = data[:512].decode("latin-1")
    first = head.lstrip("\ufeff").split("\n", 1)[0].strip("\r")
    return _header(first) is not None


def _factor(unit: str | None, name: str, column: str) -> float:
    if unit is None:
        return 1e-6
    try:
        return length_factor(unit)
    except UnitError:
        raise corrupt(
            name, f"column {column} has unit {unit!r}", "a length unit"
        ) from None


@register_reader(
    "mx_profile_csv",
    description="ZYGO Mx profile export (.csv): X, Y (um), Slice",
    suffixes=(".csv",),
    sniff=_is_mx_csv,
    kind="profile",
)
def read_mx_profile_csv(source: Source) -> Profile:
    """Read an Mx profile CSV export.

    Parameters
    ----------
    source : Source
        Loaded file.

    Returns
    -------
    Profile
        Heights in m (NaN for missing samples) at the constant step in m, ``x0``
        the first position in m.
    """
    name = source.name
    lines = [
        ln
        for ln in decode_text(source.data).lstrip("\ufeff").splitlines()
        if ln.strip()
    ]
    if not lines:
        raise corrupt(name, "file is empty", "a header 'X, Y, Slice' and data rows")
    head = _header(lines[0])
    if head is None:
        raise corrupt(
            name, f"header line is {lines[0][:60]!r}", "columns 'X, Y[, Slice]'"
        )
    _, xu, _, zu = head
    fx, fz = _factor(xu, name, "X"), _factor(zu, name, "Y")
    xs, zs = [], []
    first_slice = None
    for i, ln in enumerate(lines[1:], start=2):
        parts = [p.strip() for p in ln.split(",")]
        if len(parts) < 2:
            raise corrupt(
                name, f"line {i} has {len(parts)} field(s)", "at least X and Y"
            )
        if len(parts) >= 3:
            if first_slice is None:
                first_slice = parts[2]
            elif parts[2] != first_slice:
                continue
        try:
            x = float(parts[0])
        except ValueError:
            raise corrupt(
                name, f"line {i} X is {parts[0][:30]!r}", "a number"
            ) from None
        zt = parts[1]
        if zt == "" or zt.lower() in ("nan", "no data", "nodata", "invalid"):
            z = np.nan
        else:
            try:
                z = float(zt)
            except ValueError:
                raise corrupt(
                    name, f"line {i} Y is {zt[:30]!r}", "a number or empty"
                ) from None
        xs.append(x)
        zs.append(z)
    if len(xs) < 2:
        raise corrupt(name, f"file has {len(xs)} data row(s)", "at least 2 samples")
    x = np.array(xs) * fx
    z = np.array(zs) * fz
    if not np.isfinite(x).all():
        raise corrupt(name, "an X position is not finite", "finite positions")
    steps = np.diff(x)
    step = float(np.median(steps))
    if not step > 0:
        raise corrupt(name, f"median X step is {step!r} m", "increasing X positions")
    pos = np.rint((x - x[0]) / step)
    if not np.isfinite(pos).all() or pos.max() > 64 * len(x) + 1024:
        raise corrupt(
            name,
            "X positions are not increasing on a regular grid",
            "a constant step (gaps allowed)",
        )
    idx = pos.astype(np.int64)
    if np.any(np.diff(idx) <= 0):
        raise corrupt(
            name,
            "X positions are not increasing on a regular grid",
            "a constant step (gaps allowed)",
        )
    step = float((x[-1] - x[0]) / idx[-1])
    if np.max(np.abs(x - (x[0] + idx * step))) > 0.05 * step:
        raise corrupt(
            name,
            "X positions deviate from a constant step by more than 5 %",
            "a constant step",
        )
    out = np.full(idx[-1] + 1, np.nan)
    out[idx] = z
    out[~np.isfinite(out)] = np.nan
    if not np.isfinite(out).any():
        raise corrupt(
            name, f"all {out.size} heights are invalid", "at least one valid height"
        )
    md = {"instrument": "ZYGO", "source_format": "mx_profile_csv"}
    if first_slice:
        md["slice"] = first_slice
    return Profile(out, step, metadata=md, x0=float(x[0]))
