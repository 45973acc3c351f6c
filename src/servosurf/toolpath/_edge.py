"""Measured tool edges: read a trace of the nose, fit it, derive the edge deviation.

Files
-----
* **Laser-probe CSV** (Mitaka-style export): header lines ``key,value`` (for
  example ``Number of points in X direction,972``), a column line ``X,Y,Z``, then
  one ``x,y,z`` row per point. When the header states the number of points in X and
  Y, their product must equal the number of rows.
* **Plain CSV**: ``x,y,z`` or ``x,z`` rows without a header (comma, semicolon, tab
  or blank separated), like the raw trace ``tool/r200.csv`` of the shared data.

Coordinates are in mm unless ``unit`` says otherwise; they are converted to m on
read. The edge is traced in one plane (the rake face): with two columns that plane
is (column 0, column 1); with three, the column with the smallest spread (the probe's
stepping axis, constant along a trace) is left out unless ``columns`` names the two
in-plane columns. Call the two in-plane coordinates (u, v).

Processing (all lengths in m, angles in rad)
--------------------------------------------
1. **Nose location.** The trace's apex is the median of the 1 % of points
   farthest from the line through its two ends (the two points farthest apart);
   a first circle is fitted (algebraic, Kasa, refitted without points beyond 3
   robust standard deviations) to the points within 15 % of the chord from it
   (at least 20).
2. **Tool axis and nose arc from the flanks.** On each side of the nose, the
   trace between 1.2 and 4 radii from the centre is fitted with a straight line
   (principal axis, refitted 8 times without the points beyond 3 robust standard
   deviations). With both flanks found, the tool axis (centre to tip) is their
   bisector and the nose arc runs between the two tangent points (the feet of the
   perpendiculars from the centre onto the flanks); otherwise the axis points from
   the centre to the apex and the nose arc is +-90 degrees. ``axis_angle``
   overrides the axis.
3. **Angular crop.** The usable arc is the nose arc less ``flank_margin``
   (default 5 degrees) at each tangent point, and at most ``half_angle`` (default
   45 degrees) on each side of the axis. A fixed crop keeps the fit
   reproducible: a real nose is not a perfect circle, and a crop that follows the
   residual would trade radius against arc length (on ``tool/r200.csv`` a circle
   over +-10 .. +-60 degrees has radii from 184 to 192 um).
4. **Spikes and circle fit, iterated until the kept points settle.** Every point
   gets its radial residual ``e = |p - c| - R`` and its contact angle phi. Points
   with ``|e| > GROSS_FRACTION R`` are gross outliers (stray probe readings).
   Inside the arc, a point whose residual differs from the median of its
   ``spike_neighbours`` neighbours on each side in angle (default 3: a Hampel
   filter without the point itself) by more than
   ``spike_threshold`` (default 4) robust standard deviations (1.4826 x the median
   absolute deviation of those differences) is a spike. The circle is refitted to
   the kept points by geometric least squares (Gauss-Newton on the orthogonal
   distances).
5. **Smoothing.** The residuals of the kept points are smoothed along the arc
   with the ISO 16610-21 Gaussian weighting function of cut-off ``smoothing``
   (default 25 um of arc length: 50 % amplitude transmission at that
   wavelength), evaluated as a normalised (Nadaraya-Watson) kernel average at
   angles spaced ``angle_step`` (default 0.25 degree) across the usable arc.

Which model when the path compensates the edge
-----------------------------------------------
Sweep the whole measured edge (the default), whether or not the path was planned
to compensate it. A compensating planner (like the one that wrote case 1022)
moves the tool along Z by the edge's deviation at the *contact point* of each
radius, so that the part's form follows the design; the surface between two
passes is still the imprint of the edge *around* that point (about +-f / (2 R)
of contact angle, +-4.4 degrees on 1022), which sets the cusps' shape and
height. ``compensated=True`` (``--edge-compensated``, TOML ``edge-compensated``)
is the *radius-only* model: a round nose of the fitted radius, the edge's shape
left out. It is kept as a model to compare with. On case 1022
(``benchmarks/real_cut_1022.py``) every round nose (186.4 to 191.8 um, and the
trace's 188.3 um) over-predicts Ra, by 13-16 % on the white-light profile and
33-37 % on the Formtracer contour (by 20-45 % in every 0.1 mm of radius);
the swept trace brings the contour to +13 % (within 10 % over radii below
0.4 mm) and Rz to -4 % / +18 % (round nose +22 % / +43 %), but puts the
white-light profile's Ra 13 % low; its result depends on which side of the trace
is outward (``mirror``), which the trace cannot tell: the default orientation
fits the contour much better than the mirrored one (+13 % against +53 %) and the
white-light profile as well (-13 % against +13 %).

Tool convention
---------------
The result is what :class:`~servosurf.toolpath.Tool` uses: ``nose_radius`` = the
fitted radius, ``waviness_angle`` = phi (0 on the tool axis, positive *outward*:
towards larger workpiece radius), ``waviness_deviation`` = the smoothed residual
(positive where the edge protrudes beyond the fitted circle and cuts deeper), and
``arc_half_angle`` = the smaller half of the usable arc. Which side of the trace
is outward cannot be read from the trace: by default the side of larger u (the
first in-plane column) is outward; ``mirror=True`` takes the other side.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from .._validation import check_nonnegative, check_positive
from ..errors import ConfigError, CorruptedFileError, UnitError
from ..units import length_factor
from ._tool import Tool

__all__ = [
    "ToolEdge",
    "EdgeSettings",
    "read_edge_trace",
    "read_tool_edge",
    "fit_tool_edge",
    "MeasuredEdge",
    "tool_table_from_trace",
    "EDGE_KEYS",
    "GROSS_FRACTION",
    "FLANK_RANGE",
    "NOSE_RADIUS_RANGE",
]

#: A residual larger than this fraction of the radius is a gross outlier.
GROSS_FRACTION: float = 0.1

#: Flank fits use the trace between these multiples of the radius from the centre.
FLANK_RANGE: tuple[float, float] = (1.2, 4.0)

#: The first circle is fitted to the points within this fraction of the trace's
#: chord (the distance between its two ends) from the apex.
INITIAL_REACH: float = 0.15

#: Fewest points for a flank line.
_MIN_FLANK_POINTS: int = 10

#: Plausible nose radii in m; a fit outside is refused (likely a unit slip).
NOSE_RADIUS_RANGE: tuple[float, float] = (5e-6, 20e-3)

#: Largest number of fit / crop / spike passes.
_MAX_PASSES: int = 30

#: Fewest points on the usable arc.
_MIN_ARC_POINTS: int = 8

_SPLIT = re.compile(r"\s*[,;\t]\s*|\s+")


@dataclass(frozen=True)
class EdgeSettings:
    """Processing parameters of a tool-edge trace (SI units).

    Parameters
    ----------
    half_angle : float, default: radians(45)
        Largest |phi| of the usable arc, in rad.
    flank_margin : float, default: radians(5)
        Angle left out at each flank tangent point, in rad.
    spike_threshold : float, default: 4.0
        Spike rejection threshold in robust standard deviations.
    spike_neighbours : int, default: 3
        Neighbours on each side (in angle) in the running median of the spike
        test (a Hampel filter of ``2 k + 1`` points).
    smoothing : float, default: 25e-6
        Cut-off wavelength of the Gaussian smoothing along the arc, in m.
    angle_step : float, default: radians(0.25)
        Spacing of the output deviation table, in rad.
    mirror : bool, default: False
        Take the side of smaller u (first in-plane column) as outward.
    axis_angle : float or None, default: None
        Direction of the tool axis (centre to tip) in the trace plane, in rad from
        the +u axis; None: the flank bisector (or the apex direction).
    """

    half_angle: float = math.radians(45.0)
    flank_margin: float = math.radians(5.0)
    spike_threshold: float = 4.0
    spike_neighbours: int = 3
    smoothing: float = 25e-6
    angle_step: float = math.radians(0.25)
    mirror: bool = False
    axis_angle: float | None = None

    def __post_init__(self) -> None:
        for name in ("half_angle", "spike_threshold", "smoothing", "angle_step"):
            check_positive(getattr(self, name), name=f"edge {name.replace('_', '-')}")
        check_nonnegative(self.flank_margin, name="edge flank-margin")
        if self.half_angle > math.pi / 2:
            raise ConfigError(
                f"edge half-angle must be an angle in rad in (0, {math.pi / 2:.4g}], "
                f"got {self.half_angle!r} (degrees given as rad?)"
            )
        if self.smoothing > 1e-3:
            raise ConfigError(
                f"edge smoothing must be a cut-off wavelength in m below 1e-3, got "
                f"{self.smoothing!r} (um given as m?)"
            )
        k = self.spike_neighbours
        if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= 50:
            raise ConfigError(
                f"edge spike-neighbours must be an integer in [1, 50], got {k!r}"
            )
        for name in ("flank_margin", "angle_step"):
            if getattr(self, name) > math.radians(30.0):
                raise ConfigError(
                    f"edge {name.replace('_', '-')} must be an angle in rad below "
                    f"{math.radians(30.0):.3g}, got {getattr(self, name)!r} "
                    "(degrees given as rad?)"
                )
        if self.axis_angle is not None and not math.isfinite(self.axis_angle):
            raise ConfigError(f"edge axis-angle must be finite, got {self.axis_angle}")


@dataclass(frozen=True, eq=False)
class ToolEdge:
    """A measured tool edge: the trace, the fitted nose and the edge deviation.

    Attributes
    ----------
    u, v : ndarray of shape (n,)
        In-plane coordinates of every trace point, in m.
    centre : tuple of float
        Fitted circle centre (u, v), in m.
    radius : float
        Fitted nose radius, in m.
    axis_angle : float
        Direction of the tool axis (centre to tip) from the +u axis, in rad.
    angle : ndarray of shape (n,)
        Contact angle phi of each point, in rad (Tool convention, outward +).
    residual : ndarray of shape (n,)
        ``|p - centre| - radius`` of each point, in m (outward +).
    in_arc : ndarray of bool, shape (n,)
        Points inside the usable arc.
    spike : ndarray of bool, shape (n,)
        Points inside the arc rejected as spikes (or gross outliers).
    arc : tuple of float
        Usable arc ``(phi_min, phi_max)``, in rad.
    waviness_angle : ndarray of shape (m,)
        Angles of the smoothed deviation table, in rad.
    waviness_deviation : ndarray of shape (m,)
        Smoothed edge deviation, in m (outward +).
    noise : float
        Robust standard deviation of the kept points about the smoothed deviation,
        in m.
    settings : EdgeSettings
        The processing parameters.
    metadata : dict
        Source file, header items, in-plane columns, unit, counts.
    """

    u: np.ndarray
    v: np.ndarray
    centre: tuple[float, float]
    radius: float
    axis_angle: float
    angle: np.ndarray
    residual: np.ndarray
    in_arc: np.ndarray
    spike: np.ndarray
    arc: tuple[float, float]
    waviness_angle: np.ndarray
    waviness_deviation: np.ndarray
    noise: float
    settings: EdgeSettings = field(default_factory=EdgeSettings)
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def used(self) -> np.ndarray:
        """Points that enter the fit and the deviation (arc, not spikes)."""
        return self.in_arc & ~self.spike

    @property
    def arc_half_angle(self) -> float:
        """The smaller half of the usable arc, in rad."""
        return float(min(-self.arc[0], self.arc[1]))

    def tool(
        self,
        base: Tool | None = None,
        *,
        compensated: bool = False,
        arc_half_angle: float | None = None,
    ) -> Tool:
        """Return the :class:`Tool` this edge describes.

        Parameters
        ----------
        base : Tool, optional
            Tool whose rake and clearance angles are kept (default: a default
            Tool).
        compensated : bool, default: False
            The radius-only model: only the fitted radius enters, not the
            deviation (a round nose). Not what a path that compensates this edge
            needs: the compensation is in the path's Z, the cusps are still
            imprints of the edge's shape (see "Which model" in the module
            docstring); kept to compare with.
        arc_half_angle : float, optional
            Arc half-angle in rad; default :attr:`arc_half_angle` (the usable arc).

        Returns
        -------
        Tool
            Nose radius from the fit (m), waviness from the smoothed deviation
            (rad, m) unless ``compensated``.

        Raises
        ------
        ConfigError
            If the deviation exceeds 1 % of the radius (the first-order model of
            :class:`Tool`) or the arc half-angle is not in (0, pi/2].
        """
        base = base if base is not None else Tool()
        half = self.arc_half_angle if arc_half_angle is None else float(arc_half_angle)
        if not 0.0 < half <= math.pi / 2:
            raise ConfigError(
                f"tool arc half-angle from the edge trace must be in (0, pi/2] rad, "
                f"got {half!r}"
            )
        dev = np.asarray(self.waviness_deviation)
        if not compensated and np.max(np.abs(dev)) > 0.01 * self.radius:
            raise ConfigError(
                f"{self.metadata.get('source', 'edge trace')}: the smoothed edge "
                f"deviation reaches {np.max(np.abs(dev)):.3g} m, above 1 % of the "
                f"fitted radius {self.radius:.4g} m (the first-order edge model); "
                "lower the arc tolerance or check the trace"
            )
        if compensated:
            ang: tuple[float, ...] = ()
            wav: tuple[float, ...] = ()
        else:
            ang = tuple(float(a) for a in self.waviness_angle)
            wav = tuple(float(d) for d in dev)
        return Tool(
            nose_radius=float(self.radius),
            rake_angle=base.rake_angle,
            clearance_angle=base.clearance_angle,
            arc_half_angle=half,
            waviness_angle=ang,
            waviness_deviation=wav,
        )

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary in SI units (keys carry their unit)."""
        used = self.used
        return {
            "source": self.metadata.get("source"),
            "nose_radius_m": float(self.radius),
            "centre_m": [float(self.centre[0]), float(self.centre[1])],
            "axis_angle_rad": float(self.axis_angle),
            "arc_rad": [float(self.arc[0]), float(self.arc[1])],
            "arc_half_angle_rad": self.arc_half_angle,
            "points": int(self.u.size),
            "points_in_arc": int(self.in_arc.sum()),
            "points_used": int(used.sum()),
            "spikes": int(self.spike.sum()),
            "noise_m": float(self.noise),
            "fit_rms_m": float(np.sqrt(np.mean(self.residual[used] ** 2))),
            "deviation_pv_m": float(np.ptp(self.waviness_deviation)),
            "deviation_rms_m": float(np.sqrt(np.mean(self.waviness_deviation ** 2))),
            "mirror": bool(self.settings.mirror),
            "plane_columns": self.metadata.get("plane_columns"),
            "settings": {
                "half_angle_rad": self.settings.half_angle,
                "flank_margin_rad": self.settings.flank_margin,
                "spike_threshold_sigma": self.settings.spike_threshold,
                "spike_neighbours": self.settings.spike_neighbours,
                "smoothing_cutoff_m": self.settings.smoothing,
                "angle_step_rad": self.settings.angle_step,
            },
        }

    def plot(self, path: str | os.PathLike[str]) -> Path:
        """Write the trace, the fit, the spikes and the deviation to a PNG.

        Parameters
        ----------
        path : str or path-like
            Destination PNG file.

        Returns
        -------
        Path
            The written file.
        """
        from ..viz._edge_plots import plot_tool_edge

        return plot_tool_edge(self, path)


# ------------------------------------------------------------------ reading
def _load(source: str | os.PathLike | IO[bytes] | bytes) -> tuple[str, str]:
    from ..io._common import decode_text, load_source

    src = load_source(source)
    return decode_text(src.data), src.name


def _numbers(line: str) -> list[float] | None:
    parts = _SPLIT.split(line.strip())
    try:
        return [float(p) for p in parts]
    except ValueError:
        return None


def read_edge_trace(
    source: str | os.PathLike | IO[bytes] | bytes, *, unit: str = "mm"
) -> tuple[np.ndarray, dict[str, Any]]:
    """Read the points of a tool-edge trace (laser-probe CSV or plain x,[y,]z).

    Parameters
    ----------
    source : str, path-like, binary file-like or bytes
        The trace file.
    unit : str, default: "mm"
        Length unit of the coordinates in the file.

    Returns
    -------
    points : ndarray of shape (n, 2) or (n, 3)
        Coordinates in m, in the file's column order.
    metadata : dict
        ``source`` (name), ``unit``, ``columns`` (labels, or None), ``header``
        (the ``key: value`` items of a laser-probe header).

    Raises
    ------
    CorruptedFileError
        Rows that are not 2 or 3 numbers, a changing column count, a declared
        point count that does not match, fewer than 10 points, non-finite values.
    UnitError
        For an unknown ``unit``.
    """
    try:
        factor = length_factor(unit)
    except UnitError:
        raise UnitError(
            f"edge trace unit {unit!r} is unknown; expected a length unit such as "
            "mm or um"
        ) from None
    text, name = _load(source)
    lines = text.lstrip("\ufeff").splitlines()
    header: dict[str, str] = {}
    labels: list[str] | None = None
    start = None
    for i, ln in enumerate(lines):
        if not ln.strip():
            continue
        if _numbers(ln) is not None:
            start = i
            break
        parts = [p.strip() for p in ln.split(",")]
        if all(p.lower() in ("x", "y", "z") for p in parts if p) and len(parts) >= 2:
            labels = [p.upper() for p in parts if p]
        elif len(parts) >= 2 and len(header) < 64:
            header[parts[0][:60]] = ",".join(parts[1:]).strip()[:120]
    if start is None:
        raise CorruptedFileError(
            f"{name}: no numeric rows found; expected 'x,y,z' or 'x,z' rows in "
            f"{unit} (after an optional header)"
        )
    rows: list[list[float]] = []
    ncol = None
    for i in range(start, len(lines)):
        ln = lines[i]
        if not ln.strip():
            continue
        vals = _numbers(ln)
        if vals is None:
            raise CorruptedFileError(
                f"{name}: line {i + 1} is {ln.strip()[:40]!r}; expected numbers "
                "'x,y,z' or 'x,z'"
            )
        if ncol is None:
            ncol = len(vals)
            if ncol not in (2, 3):
                raise CorruptedFileError(
                    f"{name}: line {i + 1} has {ncol} values; expected 2 (x,z) or "
                    "3 (x,y,z)"
                )
        elif len(vals) != ncol:
            raise CorruptedFileError(
                f"{name}: line {i + 1} has {len(vals)} values after rows of {ncol}; "
                f"expected {ncol} on every row"
            )
        rows.append(vals)
    pts = np.asarray(rows, dtype=float) * factor
    declared = _declared_count(header)
    if declared is not None and declared != len(rows):
        raise CorruptedFileError(
            f"{name}: header declares {declared} points but {len(rows)} rows follow; "
            f"expected {declared} rows (truncated file?)"
        )
    if len(rows) < 10:
        raise CorruptedFileError(
            f"{name}: trace has {len(rows)} point(s); expected at least 10"
        )
    if not np.isfinite(pts).all():
        k = int(np.flatnonzero(~np.isfinite(pts).all(axis=1))[0])
        raise CorruptedFileError(
            f"{name}: point {k + 1} is not finite; expected finite coordinates"
        )
    if labels is not None and len(labels) != ncol:
        labels = None
    md = {"source": name, "unit": unit, "columns": labels, "header": header}
    return pts, md


def _declared_count(header: dict[str, str]) -> int | None:
    nx = ny = None
    for key, value in header.items():
        k = key.lower()
        m = re.match(r"\s*(\d+)", value)
        if not m:
            continue
        if k.startswith("number of points in x"):
            nx = int(m.group(1))
        elif k.startswith("number of points in y"):
            ny = int(m.group(1))
    if nx is None:
        return None
    return nx * (ny if ny is not None else 1)


def _plane(points: np.ndarray, columns: tuple[int, int] | None,
           name: str) -> tuple[int, int]:
    ncol = points.shape[1]
    if columns is not None:
        cols = tuple(int(c) for c in columns)
        if len(cols) != 2 or cols[0] == cols[1] or not all(
                0 <= c < ncol for c in cols):
            raise ConfigError(
                f"edge trace columns must be two different column indices in "
                f"[0, {ncol - 1}], got {columns!r}"
            )
        return cols  # type: ignore[return-value]
    if ncol == 2:
        return (0, 1)
    q = np.percentile(points, [25, 75], axis=0)
    spread = q[1] - q[0]
    drop = int(np.argmin(spread))
    keep = tuple(c for c in range(3) if c != drop)
    if spread[list(keep)].min() <= 0:
        raise CorruptedFileError(
            f"{name}: the trace does not span a plane (column spreads "
            f"{spread.tolist()} m); expected a 2-D edge trace"
        )
    return keep  # type: ignore[return-value]


# ----------------------------------------------------------------- fitting
def _kasa(u: np.ndarray, v: np.ndarray) -> tuple[float, float, float]:
    """Algebraic circle fit (Kasa): centre (m) and radius (m)."""
    mu, mv = u.mean(), v.mean()
    x, y = u - mu, v - mv
    a = np.column_stack([x, y, np.ones_like(x)])
    b = x * x + y * y
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    cu, cv = sol[0] / 2.0, sol[1] / 2.0
    r2 = sol[2] + cu * cu + cv * cv
    return float(cu + mu), float(cv + mv), float(math.sqrt(max(r2, 0.0)))


def _robust_kasa(u: np.ndarray, v: np.ndarray) -> tuple[float, float, float]:
    """Kasa fit refitted 6 times without points beyond 3 robust standard deviations
    (stray readings inside the V must not pull the first circle)."""
    keep = np.ones(u.size, dtype=bool)
    cu, cv, r = _kasa(u, v)
    for _ in range(6):
        res = np.hypot(u - cu, v - cv) - r
        dev = np.abs(res - np.median(res[keep]))
        sigma = 1.4826 * float(np.median(dev[keep]))
        new = dev <= 3.0 * sigma
        if new.sum() < 10 or not sigma > 0 or np.array_equal(new, keep):
            break
        keep = new
        cu, cv, r = _kasa(u[keep], v[keep])
    return cu, cv, r


def _geometric(u: np.ndarray, v: np.ndarray, cu: float, cv: float,
               r: float) -> tuple[float, float, float]:
    """Orthogonal-distance circle fit by Gauss-Newton, from (cu, cv, r)."""
    for _ in range(100):
        du, dv = u - cu, v - cv
        rho = np.hypot(du, dv)
        rho = np.where(rho > 0, rho, 1e-300)
        res = rho - r
        jac = np.column_stack([-du / rho, -dv / rho, -np.ones_like(rho)])
        step, *_ = np.linalg.lstsq(jac, -res, rcond=None)
        cu, cv, r = cu + step[0], cv + step[1], r + step[2]
        if np.max(np.abs(step)) < 1e-15 + 1e-12 * abs(r):
            break
    return float(cu), float(cv), float(r)


def _frame(axis: float, mirror: bool) -> tuple[float, float, float, float]:
    """Unit axis (au, av) and outward (ou, ov) directions in the trace plane.

    Outward is the perpendicular of the axis with a positive u component (a
    positive v component when the axis lies along u), reversed by ``mirror``.
    """
    au, av = math.cos(axis), math.sin(axis)
    ou, ov = av, -au
    if ou < -1e-12 or (abs(ou) <= 1e-12 and ov < 0):
        ou, ov = -ou, -ov
    if mirror:
        ou, ov = -ou, -ov
    return au, av, ou, ov


def _angles(u, v, cu, cv, axis, mirror) -> np.ndarray:
    """Contact angle phi of each point (0 on the axis, outward +), rad."""
    au, av, ou, ov = _frame(axis, mirror)
    du, dv = u - cu, v - cv
    return np.arctan2(du * ou + dv * ov, du * au + dv * av)


def _running_median(phi: np.ndarray, e: np.ndarray, k: int) -> np.ndarray:
    """Median of ``e`` over the ``k`` neighbours on each side in phi of each point.

    The point itself is left out, so that a spike does not pull its own reference
    and the differences keep the noise's distribution.
    """
    order = np.argsort(phi, kind="stable")
    es = e[order]
    n = es.size
    med = np.array([
        np.median(np.concatenate([es[max(0, i - k): i], es[i + 1: i + k + 1]]))
        if n > 1 else es[i]
        for i in range(n)
    ])
    out = np.empty_like(med)
    out[order] = med
    return out


def _flank(u: np.ndarray, v: np.ndarray, cu: float, cv: float, r: float,
           axis: float, side: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Straight-line fit of one flank: (point on it, unit direction towards the tip).

    ``side`` +1 / -1 selects the half-plane on either side of the axis. Uses the
    points between FLANK_RANGE radii from the centre; None with too few points.
    """
    au, av = math.cos(axis), math.sin(axis)
    du, dv = u - cu, v - cv
    dist = np.hypot(du, dv)
    across = du * av - dv * au
    m = (dist > FLANK_RANGE[0] * r) & (dist < FLANK_RANGE[1] * r) & (
        side * across > 0)
    q = np.column_stack([u[m], v[m]])
    for _ in range(8):
        if q.shape[0] < _MIN_FLANK_POINTS:
            return None
        mu = np.median(q, axis=0)
        _, _, vt = np.linalg.svd(q - mu, full_matrices=False)
        t = vt[0]
        res = (q - mu) @ np.array([-t[1], t[0]])
        dev = np.abs(res - np.median(res))
        sigma = 1.4826 * float(np.median(dev))
        if not sigma > 0:
            break
        q = q[dev <= 3.0 * sigma]
    if q.shape[0] < _MIN_FLANK_POINTS:
        return None
    mu = q.mean(axis=0)
    _, _, vt = np.linalg.svd(q - mu, full_matrices=False)
    t = vt[0]
    if t[0] * au + t[1] * av < 0:
        t = -t
    return mu, t


def _apex(u: np.ndarray, v: np.ndarray) -> tuple[float, float, float]:
    """Robust apex of a V-shaped trace and the length of its chord (m).

    The chord joins the two points farthest apart (the flank ends: a diameter of
    the convex hull); the apex is the median of the 1 % of points (at least 5)
    farthest from the chord on the side where most points lie.
    """
    from scipy.spatial import ConvexHull, QhullError

    pts = np.column_stack([u, v])
    try:
        hull = pts[ConvexHull(pts).vertices]
    except (QhullError, ValueError):  # collinear points: no nose
        hull = pts
    if hull.shape[0] > 2000:  # pragma: no cover - a hull of a trace is small
        hull = hull[:: hull.shape[0] // 2000 + 1]
    d2 = ((hull[:, None, :] - hull[None, :, :]) ** 2).sum(axis=-1)
    i, j = np.unravel_index(int(np.argmax(d2)), d2.shape)
    a, b = hull[i], hull[j]
    d = b - a
    n = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-300)
    dist = (pts - a) @ n
    if np.median(dist) < 0:  # the bulk (the nose side) lies on the +n side
        n, dist = -n, -dist
    k = max(5, u.size // 100)
    top = np.argsort(dist)[-k:]
    apex = np.median(pts[top], axis=0)
    return float(apex[0]), float(apex[1]), float(np.hypot(*d))


def _smooth(phi: np.ndarray, e: np.ndarray, grid: np.ndarray, radius: float,
            cutoff: float) -> np.ndarray:
    """Gaussian (ISO 16610-21 weights) kernel average along the arc length."""
    alpha = math.sqrt(math.log(2.0) / math.pi)
    scale = alpha * cutoff
    d = radius * (grid[:, None] - phi[None, :]) / scale
    w = np.exp(-np.pi * d * d)
    sw = w.sum(axis=1)
    out = np.empty(grid.size)
    good = sw > 1e-12
    out[good] = (w[good] @ e) / sw[good]
    if (~good).any():  # no point within several cut-offs: the nearest value
        near = np.argmin(np.abs(grid[~good, None] - phi[None, :]), axis=1)
        out[~good] = e[near]
    return out


def fit_tool_edge(
    points: np.ndarray,
    *,
    settings: EdgeSettings | None = None,
    columns: tuple[int, int] | None = None,
    metadata: dict[str, Any] | None = None,
) -> ToolEdge:
    """Fit the nose of a tool-edge trace and derive the edge deviation.

    Parameters
    ----------
    points : ndarray of shape (n, 2) or (n, 3)
        Trace coordinates in m.
    settings : EdgeSettings, optional
        Processing parameters (defaults: see :class:`EdgeSettings`).
    columns : (int, int), optional
        The two in-plane columns of a 3-column trace (default: leave out the
        column with the smallest spread).
    metadata : dict, optional
        Carried into the result (``source`` names the file in messages).

    Returns
    -------
    ToolEdge
        Fit, crop, spikes and the smoothed deviation (see the module docstring).

    Raises
    ------
    ConfigError
        When no usable arc is found, too few points remain, or the radius is
        implausible (a unit slip: the message says which unit would fit).
    """
    s = settings if settings is not None else EdgeSettings()
    md = dict(metadata or {})
    name = str(md.get("source", "edge trace"))
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3) or pts.shape[0] < 10:
        raise ConfigError(
            f"{name}: points must have shape (n >= 10, 2 or 3), got {pts.shape}"
        )
    c0, c1 = _plane(pts, columns, name)
    md["plane_columns"] = [c0, c1]
    u, v = pts[:, c0].copy(), pts[:, c1].copy()
    au, av, chord = _apex(u, v)
    dist = np.hypot(u - au, v - av)
    near = dist <= INITIAL_REACH * chord
    if near.sum() < 20:
        near = np.argsort(dist)[:20]
    cu, cv, r = _robust_kasa(u[near], v[near])
    if not (math.isfinite(r) and r > 0):
        raise ConfigError(f"{name}: no circular nose found near the trace's apex")
    apex_axis = math.atan2(av - cv, au - cu)
    used = np.zeros(u.size, dtype=bool)
    in_arc = spike = used
    arc = (0.0, 0.0)
    axis = apex_axis
    flanks: list[tuple[np.ndarray, np.ndarray] | None] = [None, None]
    for outer in range(2):  # flanks from the first circle, then from the fitted one
        flanks = [_flank(u, v, cu, cv, r, apex_axis, side) for side in (1, -1)]
        if s.axis_angle is not None:
            axis = float(s.axis_angle)
        elif flanks[0] is not None and flanks[1] is not None:
            t = flanks[0][1] + flanks[1][1]
            axis = math.atan2(t[1], t[0])
        else:
            axis = apex_axis
        nose = [-math.pi / 2, math.pi / 2]
        for fl in flanks:
            if fl is None:
                continue
            p0, t = fl
            foot = p0 + ((np.array([cu, cv]) - p0) @ t) * t
            ph = float(_angles(np.array([foot[0]]), np.array([foot[1]]), cu, cv,
                               axis, s.mirror)[0])
            if ph < 0:
                nose[0] = max(nose[0], ph)
            else:
                nose[1] = min(nose[1], ph)
        arc = (max(nose[0] + s.flank_margin, -s.half_angle),
               min(nose[1] - s.flank_margin, s.half_angle))
        prev = None
        for _ in range(_MAX_PASSES):
            e = np.hypot(u - cu, v - cv) - r
            phi = _angles(u, v, cu, cv, axis, s.mirror)
            gross = np.abs(e) > GROSS_FRACTION * r
            in_arc = (phi >= arc[0]) & (phi <= arc[1])
            cand = in_arc & ~gross
            if cand.sum() < _MIN_ARC_POINTS:
                break
            trend = np.zeros(u.size)
            trend[cand] = _running_median(phi[cand], e[cand], s.spike_neighbours)
            d = e - trend
            sigma = 1.4826 * float(np.median(np.abs(d[cand] - np.median(d[cand]))))
            spike = in_arc & (gross | (np.abs(d) > s.spike_threshold * sigma))
            used = in_arc & ~spike
            if used.sum() < _MIN_ARC_POINTS:
                break
            key = used.tobytes()
            cu, cv, r = _geometric(u[used], v[used], cu, cv, r)
            if key == prev:
                break
            prev = key
        if used.sum() < _MIN_ARC_POINTS or arc[1] <= arc[0]:
            break
    md["flanks_found"] = int(sum(f is not None for f in flanks))
    if used.sum() < _MIN_ARC_POINTS or arc[1] <= arc[0]:
        raise ConfigError(
            f"{name}: no usable nose arc found (fewer than {_MIN_ARC_POINTS} points "
            f"within {GROSS_FRACTION:.0%} of the radius on the arc "
            f"{math.degrees(arc[0]):.1f} .. {math.degrees(arc[1]):.1f} degrees about "
            "the tool axis); check the unit and the columns"
        )
    lo_r, hi_r = NOSE_RADIUS_RANGE
    if not lo_r <= r <= hi_r:
        hint = ""
        for alt in ("m", "mm", "um", "nm"):
            try:
                f = length_factor(alt) / length_factor(md.get("unit", "mm"))
            except (UnitError, KeyError):  # pragma: no cover - unit checked on read
                continue
            if lo_r <= r * f <= hi_r and alt != md.get("unit", "mm"):
                hint = f"; the file is probably in {alt} (pass unit={alt!r})"
                break
        raise ConfigError(
            f"{name}: fitted nose radius {r:.4g} m lies outside the plausible range "
            f"{lo_r:g} .. {hi_r:g} m{hint}"
        )
    e = np.hypot(u - cu, v - cv) - r
    phi = _angles(u, v, cu, cv, axis, s.mirror)
    n_steps = max(1, int(math.floor((arc[1] - arc[0]) / s.angle_step)))
    grid = np.linspace(arc[0], arc[1], n_steps + 1)
    dev = _smooth(phi[used], e[used], grid, r, s.smoothing)
    fit_at = np.interp(phi[used], grid, dev)
    resid = e[used] - fit_at
    noise = 1.4826 * float(np.median(np.abs(resid - np.median(resid))))
    return ToolEdge(
        u=u,
        v=v,
        centre=(cu, cv),
        radius=r,
        axis_angle=float(axis),
        angle=phi,
        residual=e,
        in_arc=in_arc,
        spike=spike,
        arc=(float(arc[0]), float(arc[1])),
        waviness_angle=grid,
        waviness_deviation=dev,
        noise=noise,
        settings=s,
        metadata=md,
    )


def read_tool_edge(
    source: str | os.PathLike | IO[bytes] | bytes,
    *,
    unit: str = "mm",
    columns: tuple[int, int] | None = None,
    mirror: bool | None = None,
    settings: EdgeSettings | None = None,
) -> ToolEdge:
    """Read a tool-edge trace and fit it (see the module docstring).

    Parameters
    ----------
    source : str, path-like, binary file-like or bytes
        Laser-probe CSV (with its header) or plain ``x,y,z`` / ``x,z`` rows.
    unit : str, default: "mm"
        Length unit of the file's coordinates.
    columns : (int, int), optional
        The two in-plane columns of a 3-column trace.
    mirror : bool, optional
        Take the side of smaller u as outward (the trace was taken the other way
        round); when given, overrides ``settings.mirror`` (default False).
    settings : EdgeSettings, optional
        Processing parameters.

    Returns
    -------
    ToolEdge
        The fitted edge; ``.tool()`` gives the :class:`Tool`.

    Raises
    ------
    CorruptedFileError
        A damaged file (see :func:`read_edge_trace`).
    ConfigError
        No usable arc, or an implausible radius (unit slip).

    Examples
    --------
    >>> import numpy as np
    >>> from servosurf.toolpath import read_tool_edge
    >>> phi = np.radians(np.linspace(-50, 50, 400))
    >>> x, z = 0.2 * np.sin(phi), 0.2 * (1 - np.cos(phi))  # R = 0.2 mm, mm
    >>> text = "\\n".join(f"{a:.6f},{b:.6f}" for a, b in zip(x, z))
    >>> edge = read_tool_edge(text.encode())
    >>> round(edge.radius * 1e6, 3)  # um
    200.0
    """
    pts, md = read_edge_trace(source, unit=unit)
    s = settings if settings is not None else EdgeSettings()
    if mirror is not None and bool(mirror) != s.mirror:
        from dataclasses import replace

        s = replace(s, mirror=bool(mirror))
    return fit_tool_edge(pts, settings=s, columns=columns, metadata=md)


@dataclass(frozen=True, eq=False)
class MeasuredEdge:
    """Simulation hook: replace the toolpath's tool by a measured edge.

    Parameters
    ----------
    edge : ToolEdge
        The fitted trace.
    compensated : bool, default: False
        Radius-only model: only the fitted radius enters, not the edge's shape
        (see "Which model" in the module docstring: sweeping the shape is right
        for compensating paths too).

    Notes
    -----
    :func:`servosurf.simulation.simulate` calls ``hook.tool(tool)``; the returned
    tool keeps the toolpath tool's rake and clearance angles.
    """

    edge: ToolEdge
    compensated: bool = False

    def tool(self, tool: Tool) -> Tool:
        """Return the measured tool built on ``tool``'s rake and clearance angles."""
        return self.edge.tool(tool, compensated=self.compensated)


#: TOML keys of the ``[tool]`` table that describe a measured edge.
EDGE_KEYS: tuple[str, ...] = (
    "edge-trace",
    "edge-compensated",
    "edge-mirror",
    "edge-unit",
    "edge-half-angle",
    "edge-half-angle-deg",
    "edge-smoothing",
)

#: ``[tool]`` keys that an edge trace replaces (given together: an error).
_REPLACED_KEYS: tuple[str, ...] = (
    "nose-radius",
    "waviness-angle",
    "waviness-angle-deg",
    "waviness-deviation",
    "edge-waviness",
)


def _toml_value(table: dict[str, Any], key: str, kind: type, default: Any) -> Any:
    if key not in table:
        return default
    v = table.pop(key)
    if kind is float:
        ok = isinstance(v, int | float) and not isinstance(v, bool)
    else:
        ok = isinstance(v, kind)
    if not ok:
        raise ConfigError(
            f"tool.{key}: expected {kind.__name__}, got {type(v).__name__}"
        )
    return float(v) if kind is float else v


def tool_table_from_trace(
    table: dict[str, Any], *, base_dir: str | os.PathLike | None = None
) -> tuple[dict[str, Any], ToolEdge | None]:
    """Resolve the edge-trace keys of a ``[tool]`` TOML table.

    Parameters
    ----------
    table : dict
        The ``[tool]`` table (kebab-case keys); it is not modified.
    base_dir : str or path-like, optional
        Folder against which a relative ``edge-trace`` path is resolved.

    Returns
    -------
    table : dict
        The table without the ``edge-*`` keys and, when ``edge-trace`` is given,
        with ``nose-radius`` (m), ``arc-half-angle`` (rad, unless given) and the
        waviness (``waviness-angle`` in rad, ``waviness-deviation`` in m; left
        out with ``edge-compensated = true``) of the fitted edge.
    edge : ToolEdge or None
        The fitted edge.

    Raises
    ------
    ConfigError
        An ``edge-*`` key without ``edge-trace``, ``edge-trace`` together with
        ``nose-radius`` or a waviness, a wrong type, or what
        :func:`read_tool_edge` raises.

    Notes
    -----
    Keys: ``edge-trace`` (file name), ``edge-compensated`` (bool, default false;
    true: the radius-only model, the edge's shape left out, which a path that
    compensates the edge does not need, see the module docstring),
    ``edge-mirror`` (bool, default false), ``edge-unit`` (default ``"mm"``),
    ``edge-half-angle`` (rad) or ``edge-half-angle-deg`` (degree), and
    ``edge-smoothing`` (m).
    """
    tab = dict(table)
    given = [k for k in EDGE_KEYS if k in tab]
    if not given:
        return tab, None
    if "edge-trace" not in tab:
        raise ConfigError(
            f"tool.{given[0]} needs tool.edge-trace (the measured edge file)"
        )
    clash = [k for k in _REPLACED_KEYS if k in tab]
    if clash:
        raise ConfigError(
            f"tool: give either edge-trace (a measured edge: radius and deviation) "
            f"or {clash[0]}, not both"
        )
    fname = _toml_value(tab, "edge-trace", str, None)
    compensated = _toml_value(tab, "edge-compensated", bool, False)
    mirror = _toml_value(tab, "edge-mirror", bool, False)
    unit = _toml_value(tab, "edge-unit", str, "mm")
    half = _toml_value(tab, "edge-half-angle", float, None)
    half_deg = _toml_value(tab, "edge-half-angle-deg", float, None)
    smoothing = _toml_value(tab, "edge-smoothing", float, None)
    if half is not None and half_deg is not None:
        raise ConfigError(
            "tool: give either edge-half-angle or edge-half-angle-deg, not both"
        )
    kw: dict[str, Any] = {}
    if half_deg is not None:
        half = math.radians(half_deg)
    if half is not None:
        kw["half_angle"] = half
    if smoothing is not None:
        kw["smoothing"] = smoothing
    settings = EdgeSettings(mirror=mirror, **kw)
    p = Path(fname)
    if not p.is_absolute() and base_dir is not None:
        p = Path(base_dir) / p
    if not p.is_file():
        raise ConfigError(f"tool.edge-trace: file {str(p)!r} not found")
    edge = read_tool_edge(p, unit=unit, settings=settings)
    explicit_half = tab.pop("arc-half-angle", None)
    explicit_half_deg = tab.pop("arc-half-angle-deg", None)
    tool = edge.tool(compensated=compensated)
    tab["nose-radius"] = tool.nose_radius
    if explicit_half is not None:
        tab["arc-half-angle"] = explicit_half
    elif explicit_half_deg is not None:
        tab["arc-half-angle-deg"] = explicit_half_deg
    else:
        tab["arc-half-angle"] = tool.arc_half_angle
    if tool.has_waviness:
        tab["waviness-angle"] = list(tool.waviness_angle)
        tab["waviness-deviation"] = list(tool.waviness_deviation)
    return tab, edge
