"""The round-nose diamond tool and the simulated field (grid specification)."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import param
from ..errors import ConfigError

__all__ = ["Tool", "Field", "ToolpathWarning", "read_waviness_csv"]


class ToolpathWarning(UserWarning):
    """A toolpath is geometrically questionable (for example clearance violated)."""


#: Number of points of the waviness table, uniform in s = sin(phi) (see Tool).
WAVINESS_TABLE_SIZE = 4097

#: Largest accepted cutting-edge radius, in m (1 um: a worn diamond is below 0.2 um;
#: larger values are unit slips).
EDGE_RADIUS_MAX = 1e-6


@dataclass(frozen=True)
class Tool:
    """Round-nose diamond tool: a circular edge arc in the radial-axial plane.

    Angles are stored in rad. In TOML the same keys may be given in degrees with a
    ``-deg`` suffix (``clearance-angle-deg = 15``), converted on load.

    Parameters
    ----------
    nose_radius : float, default: 0.5e-3
        Nose radius R, in m (seed paper Table 2).
    rake_angle : float, default: 0.0
        Rake angle, in rad (Table 2: 0 degree). Geometry only; not used by the sweep.
    clearance_angle : float, default: radians(15)
        Clearance angle, in rad (Table 2: 15 degree). The path's slope along the
        cutting direction must stay below ``tan(clearance_angle)``.
    arc_half_angle : float, default: radians(60)
        Half-angle phi_max of the edge arc about the tool axis, in rad. The edge
        exists for |r_p - r| <= R sin(phi_max).
    edge_radius : float, default: 20e-9
        Cutting-edge (hone) radius r_n of the diamond, in m. It sets the scale of the
        material parts of the forward model (minimum chip thickness
        ``h_min = ratio * r_n``, side-flow ridges, elastic recovery; see
        :class:`servosurf.cutting.Material`); the envelope sweep does not use it.
    waviness_angle : tuple of float, default: ()
        Contact angles phi of the edge-waviness profile, in rad, strictly increasing
        (phi = asin((r_p - r) / R), positive outward).
    waviness_deviation : tuple of float, default: ()
        Radius deviation of the edge at those angles, in m, along the edge normal,
        positive outward (the edge protrudes and cuts deeper).

    Notes
    -----
    The waviness enters to first order: at radial offset dr the edge height drops by
    ``dR(phi) / cos(phi)``. The kernel reads it from a table uniform in
    s = sin(phi) = dr / R (:meth:`waviness_table`, 4097 points), built by linear
    interpolation of the profile in phi (constant beyond its ends).
    """

    nose_radius: float = param(0.5e-3, unit="m", doc="nose radius R",
                               source="seed paper Table 2", low=0.0, low_open=True,
                               plausible=(1e-7, 0.05))
    rake_angle: float = param(0.0, unit="rad", doc="rake angle",
                              source="seed paper Table 2 (0 degree)",
                              low=-math.pi / 2, high=math.pi / 2)
    clearance_angle: float = param(math.radians(15.0), unit="rad",
                                   doc="clearance angle",
                                   source="seed paper Table 2 (15 degree)",
                                   low=0.0, high=math.pi / 2, low_open=True)
    arc_half_angle: float = param(math.radians(60.0), unit="rad",
                                  doc="half-angle phi_max of the edge arc",
                                  low=0.0, high=math.pi / 2, low_open=True)
    edge_radius: float = param(
        20e-9, unit="m", doc="cutting-edge (hone) radius r_n",
        source="sharp single-crystal diamond: 5-50 nm (Ikawa et al., CIRP Ann. 40 "
               "(1991) 587: a few nm; conventional polishing limit 25-45 nm, Semba et "
               "al., Trans. JSME 88 (907) (2022)); used by the material parts only",
        low=0.0, low_open=True)
    waviness_angle: tuple[float, ...] = param(
        default_factory=tuple, unit="rad", doc="contact angles of the waviness profile")
    waviness_deviation: tuple[float, ...] = param(
        default_factory=tuple, unit="m", doc="edge radius deviation (outward +)")

    def __post_init__(self) -> None:
        r_n = self.edge_radius
        if not (isinstance(r_n, int | float) and math.isfinite(r_n) and r_n > 0):
            raise ConfigError(f"tool.edge-radius must be > 0 m, got {r_n!r}")
        if r_n > EDGE_RADIUS_MAX:
            raise ConfigError(
                f"tool.edge-radius must be <= {EDGE_RADIUS_MAX:g} m (a diamond cutting "
                f"edge is 5-100 nm), got {r_n!r} m; was it meant in nm "
                f"({r_n * 1e-9:g} m)?"
            )
        a = tuple(float(v) for v in self.waviness_angle)
        d = tuple(float(v) for v in self.waviness_deviation)
        object.__setattr__(self, "waviness_angle", a)
        object.__setattr__(self, "waviness_deviation", d)
        if len(a) != len(d):
            raise ConfigError(
                "tool.waviness-angle and tool.waviness-deviation must have the same "
                f"length, got {len(a)} and {len(d)}"
            )
        if a:
            arr = np.asarray(a)
            if len(a) < 2 or not np.all(np.diff(arr) > 0):
                raise ConfigError(
                    "tool.waviness-angle must hold >= 2 strictly increasing angles "
                    f"in rad, got {a[:5]}..."
                )
            if not (np.all(np.isfinite(arr)) and np.all(np.isfinite(d))):
                raise ConfigError("tool waviness profile must have finite values")
            if np.max(np.abs(d)) > 0.01 * self.nose_radius:
                raise ConfigError(
                    "tool.waviness-deviation must stay below 1 % of the nose radius "
                    f"(first-order model), got max {np.max(np.abs(d)):g} m"
                )

    @property
    def half_width(self) -> float:
        """Radial half-width of the edge arc R sin(phi_max), in m."""
        return self.nose_radius * math.sin(self.arc_half_angle)

    @property
    def has_waviness(self) -> bool:
        """True when an edge-waviness profile is set."""
        return len(self.waviness_angle) > 0

    def chord_half_width(self, depth: float) -> float:
        """Half chord of the arc at ``depth`` below the tip, in m.

        Parameters
        ----------
        depth : float
            Depth below the tool tip, in m.

        Returns
        -------
        float
            ``sqrt(2 R depth - depth**2)``, capped at the arc half-width, in m.
        """
        R = self.nose_radius
        d = min(max(float(depth), 0.0), R)
        return min(math.sqrt(max(2.0 * R * d - d * d, 0.0)), self.half_width)

    def waviness_table(self) -> tuple[float, float, np.ndarray]:
        """Waviness height correction c(s) tabulated uniformly in s = sin(phi).

        Returns
        -------
        s0 : float
            First grid value of s (dimensionless).
        ds : float
            Grid step of s (dimensionless).
        table : ndarray of shape (m,)
            ``c(s) = dR(asin s) / cos(asin s)`` in m; empty without waviness.
        """
        if not self.has_waviness:
            return 0.0, 1.0, np.zeros(0)
        smax = math.sin(self.arc_half_angle)
        s = np.linspace(-smax, smax, WAVINESS_TABLE_SIZE)
        phi = np.arcsin(s)
        dev = np.interp(phi, np.asarray(self.waviness_angle),
                        np.asarray(self.waviness_deviation))
        table = np.ascontiguousarray(dev / np.cos(phi))
        return float(s[0]), float(s[1] - s[0]), table


def read_waviness_csv(path: str | Path) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Read an edge-waviness profile: two columns, contact angle and deviation.

    Parameters
    ----------
    path : str or Path
        CSV file. An optional header names the angle unit: ``angle_deg`` or
        ``angle_rad`` (default rad without header); the deviation is in m
        (``deviation_m``). Lines starting with ``#`` are comments.

    Returns
    -------
    angle : tuple of float
        Contact angles in rad.
    deviation : tuple of float
        Edge radius deviation in m (outward positive).

    Raises
    ------
    ConfigError
        If the file is missing or malformed.
    """
    p = Path(path)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise ConfigError(f"{p}: edge-waviness file not found") from None
    lines = [ln for ln in text.splitlines()
             if ln.strip() and not ln.lstrip().startswith("#")]
    rows = list(csv.reader(lines))
    if not rows:
        raise ConfigError(f"{p}: edge-waviness file is empty")
    scale = 1.0
    head = [c.strip().lower() for c in rows[0]]
    try:
        float(head[0])
    except ValueError:
        if "deg" in head[0]:
            scale = math.pi / 180.0
        elif "rad" not in head[0]:
            raise ConfigError(
                f"{p}: first header must be angle_deg or angle_rad, got {rows[0][0]!r}"
            ) from None
        if len(head) > 1 and "_m" not in head[1] and head[1] not in ("m", "deviation"):
            raise ConfigError(
                f"{p}: second column must be the deviation in m (deviation_m), "
                f"got {rows[0][1]!r}"
            )
        rows = rows[1:]
    try:
        vals = np.array([[float(c) for c in r[:2]] for r in rows], dtype=float)
    except (ValueError, IndexError):
        raise ConfigError(
            f"{p}: expected two numeric columns (angle, deviation in m)") from None
    if vals.ndim != 2 or vals.shape[1] != 2:
        raise ConfigError(f"{p}: expected two numeric columns (angle, deviation in m)")
    return tuple(vals[:, 0] * scale), tuple(vals[:, 1])


@dataclass(frozen=True)
class Field:
    """A rectangular simulation grid on the workpiece face.

    Pixel (i, j) (row i = y, column j = x) sits at
    ``x = x0 + j * pitch_x``, ``y = y0 + i * pitch_y`` with the field centred on
    (``center_x``, ``center_y``), the convention of :meth:`Surface.coords`. The
    workpiece frame has its origin on the spindle axis.

    Parameters
    ----------
    pitch_x : float, default: 0.55e-6
        Grid pitch along x (columns), in m.
    pitch_y : float, default: 0.55e-6
        Grid pitch along y (rows), in m.
    nx : int, default: 640
        Number of columns.
    ny : int, default: 480
        Number of rows.
    center_x : float, default: 5e-3
        x of the field centre, in m.
    center_y : float, default: 0.0
        y of the field centre, in m.

    Notes
    -----
    The default, 640 x 480 pixels at 0.55 um (0.352 x 0.264 mm), is the field of a
    20X objective on a white-light interferometer like the ZYGO CP300 the seed paper
    used (section 4.2).
    """

    pitch_x: float = param(0.55e-6, unit="m", doc="grid pitch along x (columns)",
                           source="20X objective, 640 px over 0.352 mm",
                           low=0.0, low_open=True, plausible=(1e-9, 1e-3))
    pitch_y: float = param(0.55e-6, unit="m", doc="grid pitch along y (rows)",
                           low=0.0, low_open=True, plausible=(1e-9, 1e-3))
    nx: int = param(640, doc="number of columns", low=1)
    ny: int = param(480, doc="number of rows", low=1)
    center_x: float = param(5e-3, unit="m", doc="x of the field centre",
                            plausible=(-1.0, 1.0))
    center_y: float = param(0.0, unit="m", doc="y of the field centre",
                            plausible=(-1.0, 1.0))

    def __post_init__(self) -> None:
        for name in ("nx", "ny"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or v < 1:
                raise ConfigError(f"field.{name} must be a positive integer, got {v!r}")
            object.__setattr__(self, name, int(v))
        for name in ("pitch_x", "pitch_y"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"field.{name.replace('_', '-')} must be > 0 m, "
                                  f"got {v!r}")
            object.__setattr__(self, name, v)

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx): rows and columns."""
        return self.ny, self.nx

    @property
    def x0(self) -> float:
        """x of the centre of pixel (0, 0), in m."""
        return self.center_x - 0.5 * (self.nx - 1) * self.pitch_x

    @property
    def y0(self) -> float:
        """y of the centre of pixel (0, 0), in m."""
        return self.center_y - 0.5 * (self.ny - 1) * self.pitch_y

    def coords(self) -> tuple[np.ndarray, np.ndarray]:
        """Pixel-centre coordinates.

        Returns
        -------
        x : ndarray of shape (nx,)
            Column positions, in m.
        y : ndarray of shape (ny,)
            Row positions, in m.
        """
        return (self.x0 + self.pitch_x * np.arange(self.nx),
                self.y0 + self.pitch_y * np.arange(self.ny))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the pixel centres, in m."""
        return (self.x0, self.x0 + (self.nx - 1) * self.pitch_x,
                self.y0, self.y0 + (self.ny - 1) * self.pitch_y)

    def radial_range(self) -> tuple[float, float]:
        """Smallest and largest distance of a pixel centre from the axis, in m.

        Returns
        -------
        rmin, rmax : float
            Bounds in m (rmin is 0 when the field contains the axis).
        """
        xmin, xmax, ymin, ymax = self.bounds
        cx = min(max(0.0, xmin), xmax)
        cy = min(max(0.0, ymin), ymax)
        rmin = math.hypot(cx, cy)
        rmax = max(math.hypot(x, y) for x in (xmin, xmax) for y in (ymin, ymax))
        return rmin, rmax

    def angular_window(self, reach: float = 0.0) -> tuple[float, float, float] | None:
        """Angular extent of the field seen from the spindle axis.

        Parameters
        ----------
        reach : float, default: 0.0
            Radial reach of the tool edge, in m; a field closer than this to the axis
            is also cut across the axis, so it needs every angle.

        Returns
        -------
        tuple of float or None
            ``(centre, lo, hi)`` in rad: the pixels' angles lie in
            ``[centre + lo, centre + hi]`` (``lo <= 0 <= hi``); None when every angle
            is needed.
        """
        rmin, _ = self.radial_range()
        if rmin <= reach or rmin == 0.0:
            return None
        xmin, xmax, ymin, ymax = self.bounds
        centre = math.atan2(self.center_y, self.center_x)
        rel = []
        for x in (xmin, xmax):
            for y in (ymin, ymax):
                a = math.atan2(y, x) - centre
                rel.append((a + math.pi) % (2 * math.pi) - math.pi)
        return centre, min(min(rel), 0.0), max(max(rel), 0.0)

    def subfield(self, row0: int, row1: int, col0: int, col1: int) -> Field:
        """Return the field of rows ``row0:row1`` and columns ``col0:col1``.

        Parameters
        ----------
        row0, row1, col0, col1 : int
            Half-open index ranges (rows = y, columns = x).

        Returns
        -------
        Field
            A field with the same pitch whose pixels coincide with those of ``self``.
        """
        if not (0 <= row0 < row1 <= self.ny and 0 <= col0 < col1 <= self.nx):
            raise ConfigError(
                f"subfield rows {row0}:{row1} and columns {col0}:{col1} must lie in "
                f"the field of shape {self.shape}"
            )
        nx = col1 - col0
        ny = row1 - row0
        cx = self.x0 + (col0 + 0.5 * (nx - 1)) * self.pitch_x
        cy = self.y0 + (row0 + 0.5 * (ny - 1)) * self.pitch_y
        return Field(pitch_x=self.pitch_x, pitch_y=self.pitch_y, nx=nx, ny=ny,
                     center_x=cx, center_y=cy)
