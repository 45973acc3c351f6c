"""Mitutoyo Formtracer contour exports (``.DAT`` text): unit, point count, ``x, z``.

Layout, as FORMTRACEPAK writes a contour::

    mm
    12001
          6.000000000000000,      5.302103104015436
          5.999000000000000,      5.300944749702272
    ...

Line 1 is the length unit of both columns (``mm``, ``um``, ``µm``, ``nm``, ``m``, or
spelled out), line 2 the number of points, then one ``x, z`` row per point (comma,
semicolon, tab or blank separated). The suffix ``.DAT`` is shared with the binary
ZYGO MetroPro files; the two are told apart by content: a Formtracer file is text
whose first line is a single unit word (:func:`_is_formtracer`), a MetroPro file
starts with a binary magic number.

What the reader does with the x coordinates
-------------------------------------------
* x must be finite and strictly monotonic. A contour stored from +x to -x (the
  real ``1022-contour.DAT`` runs from +6 to -6 mm) is reversed so that the
  :class:`~servosurf.metrology.Profile` runs towards +x; ``metadata["x_reversed"]``
  says so. Positions keep the instrument's frame (``x0`` is the smallest x).
* A uniform step (every position within 5 % of a step from ``x0 + k dx``, gaps of
  whole steps allowed and filled with NaN) is kept sample for sample.
* A non-uniform step is resampled by linear interpolation onto a uniform grid whose
  step is the median step of the file; grid points inside a gap longer than
  :data:`MAX_GAP_STEPS` median steps are NaN. ``metadata["resampled"]`` is True.

A height written as ``nan`` (or an empty field) is an invalid sample (NaN).
Damaged files (an unknown unit, a count that does not match the rows, a row that is
not two numbers, x not monotonic) raise
:class:`~servosurf.errors.CorruptedFileError` naming the line.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import UnitError
from ..metrology import Profile
from ..units import length_factor
from ._common import Source, corrupt, decode_text
from ._registry import register_reader

__all__ = ["read_formtracer", "MAX_GAP_STEPS", "UNIFORM_STEP_RTOL"]

#: A position further than this fraction of a step from the uniform grid makes the
#: step non-uniform (the contour is then resampled).
UNIFORM_STEP_RTOL = 0.05

#: When resampling a non-uniform contour, grid points inside a gap between two
#: samples longer than this many median steps are NaN instead of interpolated.
MAX_GAP_STEPS = 3.0

#: Largest resampled grid, as a multiple of the number of rows (+1024): guards
#: against a damaged file whose x range is enormous compared with its step.
_MAX_GRID_FACTOR = 64

_UNIT_LINE = re.compile(r"^[A-Za-z\u00b5\u03bc\u00c5\u00e5]{1,16}$")
_COUNT_LINE = re.compile(r"^\+?\d{1,12}$")
_SPLIT = re.compile(r"\s*[,;\t]\s*|\s+")
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_ROW = re.compile(rf"^\s*{_NUMBER}\s*[,;\t ]\s*{_NUMBER}\s*$")
_INVALID_Z = ("", "nan", "-nan", "no data", "nodata", "invalid")


def _is_formtracer(data: bytes) -> bool:
    """True when ``data`` looks like a Formtracer contour (never raises)."""
    head = data[:512]
    if b"\x00" in head:
        return False
    lines = head.decode("utf-8", errors="ignore").lstrip("\ufeff").splitlines()
    if not lines or not _UNIT_LINE.match(lines[0].strip()):
        return False
    if len(lines) == 1:  # truncated after the unit: only a known unit counts
        try:
            length_factor(lines[0].strip())
        except UnitError:
            return False
        return True
    if _COUNT_LINE.match(lines[1].strip()):
        return True
    return len(lines) > 2 and bool(_ROW.match(lines[2]))


def _fields(line: str) -> list[str]:
    return _SPLIT.split(line.strip())


def _grid(x: np.ndarray, z: np.ndarray, name: str) -> tuple[np.ndarray, float, bool]:
    """Put increasing ``x`` (m) on a uniform grid: (heights, step, resampled)."""
    steps = np.diff(x)
    step = float(np.median(steps))
    n_max = _MAX_GRID_FACTOR * x.size + 1024
    if not step > 0 or (x[-1] - x[0]) / step > n_max:
        raise corrupt(
            name,
            f"x spans {x[-1] - x[0]:.6g} m with a median step of {step:.6g} m",
            f"at most {n_max} steps",
        )
    pos = (x - x[0]) / step
    idx = np.rint(pos).astype(np.int64)
    uniform = bool(
        np.all(np.diff(idx) > 0)
        and np.max(np.abs(pos - idx)) <= UNIFORM_STEP_RTOL
    )
    if uniform:
        step = float((x[-1] - x[0]) / idx[-1])
        out = np.full(idx[-1] + 1, np.nan)
        out[idx] = z
        return out, step, False
    n = int(np.floor((x[-1] - x[0]) / step + 1e-9)) + 1
    grid = x[0] + step * np.arange(n)
    ok = np.isfinite(z)
    if ok.sum() < 2:
        return np.full(n, np.nan), step, True
    xv, zv = x[ok], z[ok]
    out = np.interp(grid, xv, zv)
    # NaN inside long gaps between valid samples and beyond the valid ends
    k = np.searchsorted(xv, grid, side="right")
    k = np.clip(k, 1, xv.size - 1)
    gap = xv[k] - xv[k - 1]
    out[gap > MAX_GAP_STEPS * step] = np.nan
    out[(grid < xv[0]) | (grid > xv[-1])] = np.nan
    return out, step, True


@register_reader(
    "formtracer",
    description="Mitutoyo Formtracer contour (.dat text): unit, point count, x, z",
    suffixes=(".dat",),
    sniff=_is_formtracer,
    kind="profile",
)
def read_formtracer(source: Source) -> Profile:
    """Read a Mitutoyo Formtracer contour export.

    Parameters
    ----------
    source : Source
        Loaded file.

    Returns
    -------
    Profile
        Heights in m (NaN for invalid samples) on a uniform grid of step ``dx`` in
        m, running towards +x from ``x0`` (m, the smallest x of the file). Metadata:
        ``instrument``, ``source_format``, ``unit`` (as written), ``points``,
        ``x_reversed`` (the file ran from +x to -x), ``resampled`` (non-uniform
        step interpolated, see the module docstring).

    Raises
    ------
    CorruptedFileError
        Unknown unit, bad or mismatched point count, a row that is not two
        numbers, non-finite or non-monotonic x, no valid height.
    """
    name = source.name
    if b"\x00" in source.data[:4096]:
        raise corrupt(name, "file holds binary data", "a Formtracer text contour")
    lines = decode_text(source.data).lstrip("\ufeff").splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if len(lines) < 2:
        raise corrupt(
            name,
            f"file has {len(lines)} line(s)",
            "a unit line, a point-count line and 'x, z' rows",
        )
    unit = lines[0].strip()
    try:
        factor = length_factor(unit)
    except UnitError:
        raise corrupt(
            name, f"line 1 unit is {unit[:30]!r}", "a length unit such as mm or um"
        ) from None
    count_text = lines[1].strip()
    if not _COUNT_LINE.match(count_text):
        raise corrupt(
            name, f"line 2 point count is {count_text[:30]!r}", "a positive integer"
        )
    count = int(count_text)
    rows = lines[2:]
    if count != len(rows):
        raise corrupt(
            name,
            f"line 2 declares {count} points but {len(rows)} rows follow",
            f"{count} 'x, z' rows",
        )
    if count < 2:
        raise corrupt(name, f"file has {count} point(s)", "at least 2 points")
    xs = np.empty(count)
    zs = np.empty(count)
    for i, ln in enumerate(rows):
        parts = _fields(ln)
        if len(parts) != 2:
            raise corrupt(
                name,
                f"line {i + 3} has {len(parts)} field(s) ({ln.strip()[:40]!r})",
                "two numbers 'x, z'",
            )
        try:
            xs[i] = float(parts[0])
        except ValueError:
            raise corrupt(
                name, f"line {i + 3} x is {parts[0][:30]!r}", "a number"
            ) from None
        zt = parts[1]
        if zt.lower() in _INVALID_Z:
            zs[i] = np.nan
            continue
        try:
            zs[i] = float(zt)
        except ValueError:
            raise corrupt(
                name, f"line {i + 3} z is {zt[:30]!r}", "a number"
            ) from None
    x = xs * factor
    z = zs * factor
    if not np.isfinite(x).all():
        k = int(np.flatnonzero(~np.isfinite(x))[0])
        raise corrupt(name, f"line {k + 3} x is {float(xs[k])!r}", "a finite position")
    d = np.diff(x)
    reversed_ = bool(d[0] < 0)
    bad = np.flatnonzero(d >= 0) if reversed_ else np.flatnonzero(d <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise corrupt(
            name,
            f"x is not strictly monotonic at line {k + 3} ({float(xs[k - 1])!r} "
            f"then {float(xs[k])!r})",
            "strictly increasing or strictly decreasing x",
        )
    if reversed_:
        x, z = x[::-1].copy(), z[::-1].copy()
    z[~np.isfinite(z)] = np.nan
    out, step, resampled = _grid(x, z, name)
    if not np.isfinite(out).any():
        raise corrupt(
            name, f"all {count} heights are invalid", "at least one valid height"
        )
    md = {
        "instrument": "Mitutoyo Formtracer",
        "source_format": "formtracer",
        "unit": unit,
        "points": count,
        "x_reversed": reversed_,
        "resampled": resampled,
    }
    return Profile(out, step, metadata=md, x0=float(x[0]))
