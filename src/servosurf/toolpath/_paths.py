"""Toolpath definitions: spiral face turning and sinusoidal micro-lens (lenslet) rings.

Frames and signs (SI: m, s, rad)
--------------------------------
The workpiece face lies in the x-y plane with the spindle axis at the origin; z is up,
away from the material, and the pre-cut surface is at z = 0. A lower tool height cuts
deeper. theta is the unwrapped angular position of the tool in the workpiece frame
(it grows with time at 2 pi times the spindle speed in rev/s). Both toolpaths run at
a constant spindle speed, so ``theta(t) = theta_start + 2 pi * spindle_speed * t``.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass
from dataclasses import field as _dc_field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from ..config import from_mapping, load_toml, param
from ..errors import ConfigError
from ._edge import tool_table_from_trace
from ._tool import Field, Tool, read_waviness_csv

if TYPE_CHECKING:
    pass

__all__ = [
    "FacingToolpath",
    "LensletToolpath",
    "ToolpathSpec",
    "load_toolpath",
    "builtin_toolpaths",
    "toolpath_from_mapping",
    "lenslet_chord",
    "lenslet_cut_fraction",
    "lenslet_surface_speed",
]


def lenslet_chord(nose_radius: float, depth: float) -> float:
    """Chord of the tool arc at ``depth`` below its tip: the lenslet width, in m.

    Parameters
    ----------
    nose_radius : float
        Tool nose radius R, in m.
    depth : float
        Lenslet depth d, in m (0 <= d <= R).

    Returns
    -------
    float
        ``2 sqrt(2 R d - d**2)`` in m.
    """
    R = float(nose_radius)
    d = float(depth)
    if not (R > 0 and 0 <= d <= R):
        raise ConfigError(
            f"depth must be in [0, nose_radius], got {d!r} m (R = {R!r} m)")
    return 2.0 * math.sqrt(2.0 * R * d - d * d)


def lenslet_cut_fraction(amplitude: float, depth: float) -> float:
    """Fraction of each sinusoid period during which the tool is in the material.

    Parameters
    ----------
    amplitude : float
        Zero-to-peak amplitude A of the tool motion, in m.
    depth : float
        Depth of cut d (lenslet depth), in m, 0 < d <= 2 A.

    Returns
    -------
    float
        ``(pi - 2 asin((A - d) / A)) / (2 pi)``; 1/3 for d = A / 2.
    """
    A = float(amplitude)
    d = float(depth)
    if not (A > 0 and 0 < d <= 2 * A):
        raise ConfigError(
            f"lenslet depth must be in (0, 2 * amplitude], got depth {d!r} m and "
            f"amplitude {A!r} m"
        )
    return (math.pi - 2.0 * math.asin((A - d) / A)) / (2.0 * math.pi)


def lenslet_surface_speed(nose_radius: float, depth: float, frequency: float,
                          amplitude: float | None = None) -> float:
    """Surface speed at which the lenslet's cutting length equals its cutting width.

    Parameters
    ----------
    nose_radius : float
        Tool nose radius R, in m.
    depth : float
        Lenslet depth d, in m.
    frequency : float
        Fast-tool-servo sinusoid frequency f, in Hz.
    amplitude : float, optional
        Zero-to-peak amplitude A, in m; default 2 d (the paper's d = A / 2).

    Returns
    -------
    float
        ``v = chord(R, d) * f / cut_fraction`` in m/s.

    Notes
    -----
    Seed paper section 4.2: "the cutting length was controlled to be the same with
    cutting width by adjusting the spindle speed". With d = A / 2 the tool cuts for a
    third of each period (sin > 1/2), so v = 2 sqrt(2 R d - d**2) * 3 f: 42.3 mm/s at
    d = 5 um and 59.7 mm/s at d = 10 um (R = 0.5 mm, f = 100 Hz; Table 2).

    Examples
    --------
    >>> round(lenslet_surface_speed(0.5e-3, 5e-6, 100.0) * 1e3, 1)
    42.3
    >>> round(lenslet_surface_speed(0.5e-3, 10e-6, 100.0) * 1e3, 1)
    59.7
    """
    A = 2.0 * float(depth) if amplitude is None else float(amplitude)
    frac = lenslet_cut_fraction(A, depth)
    return lenslet_chord(nose_radius, depth) * float(frequency) / frac


def _bisect_time(fn, level: float, t_hi: float, first_below: bool) -> float:
    """Time where a non-increasing r(t) crosses ``level`` on [0, t_hi] (bisection)."""
    lo, hi = 0.0, t_hi
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        v = float(fn(np.array([mid]))[0])
        if (v <= level) if first_below else (v < level):
            hi = mid
        else:
            lo = mid
    return lo if not first_below else hi


class _ConstantSpeedPath:
    """Shared helpers of toolpaths with a constant spindle speed."""

    @property
    def angular_speed(self) -> float:
        """2 pi times the spindle speed, in rad/s."""
        return 2.0 * math.pi * self.rev_per_s  # type: ignore[attr-defined]

    def theta_at(self, t: np.ndarray) -> np.ndarray:
        """Unwrapped tool angle in the workpiece frame at times ``t`` (s), in rad."""
        return self.theta0 + self.angular_speed * np.asarray(t, dtype=float)  # type: ignore[attr-defined]

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Path at times ``t``.

        Parameters
        ----------
        t : ndarray
            Times in s from the path start.

        Returns
        -------
        theta : ndarray
            Unwrapped tool angle, in rad.
        r : ndarray
            Tool-tip radius, in m.
        z : ndarray
            Commanded tool-tip height, in m.
        """
        t = np.asarray(t, dtype=float)
        return self.theta_at(t), self.radius_at(t), self.z_at(t)  # type: ignore[attr-defined]

    def time_span_for_radius(self, rlo: float,
                             rhi: float) -> tuple[float, float] | None:
        """Time interval during which the tool radius is within [rlo, rhi].

        Parameters
        ----------
        rlo, rhi : float
            Radial range in m.

        Returns
        -------
        tuple of float or None
            ``(t0, t1)`` in s, or None when the tool never enters the range. The tool
            radius is non-increasing in time.
        """
        T = self.duration  # type: ignore[attr-defined]
        f = self.radius_at  # type: ignore[attr-defined]
        r0 = float(f(np.array([0.0]))[0])
        r1 = float(f(np.array([T]))[0])
        if r1 > rhi or r0 < rlo:
            return None
        t0 = 0.0 if r0 <= rhi else _bisect_time(f, rhi, T, True)
        t1 = T if r1 >= rlo else _bisect_time(f, rlo, T, False)
        return (t0, t1) if t1 >= t0 else None


@dataclass(frozen=True)
class FacingToolpath(_ConstantSpeedPath):
    """Spiral face turning at constant feed per revolution and spindle speed.

    The tool moves inward: ``r(t) = r_start - feed_per_rev * spindle_speed * t`` until
    ``r_end``; the tip height is ``-depth_of_cut`` (the pre-cut face is at z = 0).

    Parameters
    ----------
    feed_per_rev : float, default: 2e-6
        Radial feed per revolution f, in m (Table 2: 2 um/rev).
    spindle_speed : float, default: 250 / 60
        Spindle speed, in rev/s (Table 2: 250 rpm). TOML may give
        ``spindle-speed-rpm`` instead.
    r_start : float, default: 5.5e-3
        Radius where the cut starts, in m.
    r_end : float, default: 4.5e-3
        Radius where it ends, in m (< r_start, >= 0).
    depth_of_cut : float, default: 5e-6
        Depth of cut d below the pre-cut face, in m (Table 2: 5 um).
    theta_start : float, default: 0.0
        Tool angle at t = 0, in rad.
    """

    feed_per_rev: float = param(2e-6, unit="m", doc="radial feed per revolution",
                                source="seed paper Table 2", low=0.0, low_open=True,
                                plausible=(1e-9, 1e-3))
    spindle_speed: float = param(250.0 / 60.0, unit="rev/s", doc="spindle speed",
                                 source="seed paper Table 2 (250 rpm)", low=0.0,
                                 low_open=True, plausible=(1e-3, 2000.0))
    r_start: float = param(5.5e-3, unit="m", doc="start radius", low=0.0,
                           plausible=(0.0, 1.0))
    r_end: float = param(4.5e-3, unit="m", doc="end radius", low=0.0,
                         plausible=(0.0, 1.0))
    depth_of_cut: float = param(5e-6, unit="m", doc="depth of cut below z = 0",
                                source="seed paper Table 2", low=0.0,
                                plausible=(0.0, 1e-3))
    theta_start: float = param(0.0, unit="rad", doc="tool angle at t = 0")

    def __post_init__(self) -> None:
        if not self.r_end < self.r_start:
            raise ConfigError(
                f"facing.r-end must be < facing.r-start (the tool moves inward), got "
                f"r-start {self.r_start!r} m and r-end {self.r_end!r} m"
            )

    @property
    def rev_per_s(self) -> float:
        """Spindle speed, in rev/s."""
        return self.spindle_speed

    @property
    def theta0(self) -> float:
        """Tool angle at t = 0, in rad."""
        return self.theta_start

    @property
    def duration(self) -> float:
        """Cutting time from r_start to r_end, in s."""
        return (self.r_start - self.r_end) / (self.feed_per_rev * self.spindle_speed)

    @property
    def n_revolutions(self) -> float:
        """Number of revolutions of the cut."""
        return (self.r_start - self.r_end) / self.feed_per_rev

    def radius_at(self, t: np.ndarray) -> np.ndarray:
        """Tool-tip radius at times ``t`` (s), in m."""
        t = np.asarray(t, dtype=float)
        return self.r_start - (self.feed_per_rev * self.spindle_speed) * t

    def z_at(self, t: np.ndarray) -> np.ndarray:
        """Commanded tool-tip height at times ``t`` (s), in m."""
        return np.full(np.shape(t), -self.depth_of_cut)

    @property
    def max_depth(self) -> float:
        """Deepest commanded point below z = 0, in m."""
        return self.depth_of_cut

    def _fill(self, starts, stops, fs, t, theta, r, z) -> None:
        """Write samples k in [starts[m], stops[m]) into t, theta, r, z (numba)."""
        from ..kernels._paths import _sample_facing

        _sample_facing(starts, stops, fs, self.theta0, self.angular_speed, self.r_start,
                       self.feed_per_rev * self.spindle_speed, -self.depth_of_cut, t,
                       theta, r, z)


@dataclass(frozen=True)
class LensletToolpath(_ConstantSpeedPath):
    """Rings of lenslets cut by a sinusoidal fast-tool-servo motion (seed paper 4.2).

    The tool height is ``z(t) = (A - d) - A sin(2 pi f t)``: the path centre sits
    A - d above the pre-cut face (z = 0), so the tool cuts while
    sin(2 pi f t) > (A - d) / A, a third of each period for d = A / 2, leaving one
    lenslet of depth d per period.

    Rings and phase: ``lenslets_per_ring`` N = round(2 pi r_ring f / v) with r_ring
    the first ring radius and v the nominal surface speed; the spindle turns at
    f / N rev/s, so every revolution holds exactly N periods and every lenslet is
    complete. The actual surface speed at the first ring, 2 pi r_ring f / N, differs
    from v by less than 1/(2N). Lenslet centres sit at angles 2 pi m / N (one on the
    +x axis). Ring k (k = 0 .. ring_count - 1) is cut at radius
    ``ring_radius - k * ring_pitch`` during revolution k; between rings the tool moves
    inward by ``ring_pitch`` with a half-cosine ramp during the second half of the
    ring's last period, where sin < 0 and the tool is at least A - d above the face.
    That ramp, and the start of each ring, lie half a turn from the +x axis.

    Parameters
    ----------
    frequency : float, default: 100.0
        Sinusoid frequency f, in Hz (Table 2).
    amplitude : float, default: 10e-6
        Zero-to-peak amplitude A of the tool motion, in m (Table 2: 10 and 20 um).
    depth_of_cut : float, default: 5e-6
        Lenslet depth d, in m (Table 2: 5 and 10 um; d = A / 2).
    surface_speed : float, default: 42.3e-3
        Nominal surface speed v at the first ring, in m/s (see
        :func:`lenslet_surface_speed`).
    ring_radius : float, default: 10e-3
        Radius of the first ring, in m ("a relatively large radius", section 4.2).
    ring_count : int, default: 3
        Number of rings.
    ring_pitch : float, default: 0.2e-3
        Radial distance between rings, in m (rings step inward).
    """

    frequency: float = param(100.0, unit="Hz", doc="FTS sinusoid frequency",
                             source="seed paper Table 2", low=0.0, low_open=True,
                             plausible=(1e-2, 5e4))
    amplitude: float = param(10e-6, unit="m", doc="FTS zero-to-peak amplitude",
                             source="seed paper Table 2", low=0.0, low_open=True,
                             plausible=(1e-9, 5e-3))
    depth_of_cut: float = param(5e-6, unit="m", doc="lenslet depth",
                                source="seed paper Table 2", low=0.0, low_open=True,
                                plausible=(1e-9, 5e-3))
    surface_speed: float = param(42.3e-3, unit="m/s", doc="nominal surface speed",
                                 source="seed paper section 5.3 (cut length = width)",
                                 low=0.0, low_open=True, plausible=(1e-5, 100.0))
    ring_radius: float = param(10e-3, unit="m", doc="radius of the first ring",
                               low=0.0, low_open=True, plausible=(1e-5, 1.0))
    ring_count: int = param(3, doc="number of rings", low=1)
    ring_pitch: float = param(0.2e-3, unit="m", doc="radial ring pitch", low=0.0,
                              plausible=(0.0, 0.1))

    def __post_init__(self) -> None:
        lenslet_cut_fraction(self.amplitude, self.depth_of_cut)  # checks d <= 2 A
        if self.ring_count > 1 and not self.ring_pitch > 0:
            raise ConfigError(
                f"lenslet.ring-pitch must be > 0 m with several rings, got "
                f"{self.ring_pitch!r}"
            )
        last = self.ring_radius - (self.ring_count - 1) * self.ring_pitch
        if last <= 0:
            raise ConfigError(
                f"lenslet rings must stay at positive radius: the last ring is at "
                f"{last:g} m (ring-radius {self.ring_radius:g} m, ring-count "
                f"{self.ring_count}, ring-pitch {self.ring_pitch:g} m)"
            )

    @property
    def lenslets_per_ring(self) -> int:
        """Number N of lenslets per ring (sinusoid periods per revolution)."""
        n = 2.0 * math.pi * self.ring_radius * self.frequency / self.surface_speed
        return max(1, round(n))

    @property
    def rev_per_s(self) -> float:
        """Spindle speed f / N, in rev/s."""
        return self.frequency / self.lenslets_per_ring

    @property
    def actual_surface_speed(self) -> float:
        """Surface speed at the first ring with the rounded N, in m/s."""
        return 2.0 * math.pi * self.ring_radius * self.rev_per_s

    @property
    def theta0(self) -> float:
        """Tool angle at t = 0 (start of ring 0, half a turn from lenslet 0), rad."""
        n = self.lenslets_per_ring
        return (2.0 * math.pi * (n // 2) - 0.5 * math.pi) / n

    @property
    def duration(self) -> float:
        """Time to cut all rings, in s."""
        return self.ring_count * self.lenslets_per_ring / self.frequency

    @property
    def cut_length(self) -> float:
        """Lenslet length along the cut at the first ring, in m."""
        frac = lenslet_cut_fraction(self.amplitude, self.depth_of_cut)
        return self.actual_surface_speed * frac / self.frequency

    def ring_radii(self) -> np.ndarray:
        """Radii of the rings, in m, shape (ring_count,)."""
        return self.ring_radius - self.ring_pitch * np.arange(self.ring_count)

    def radius_at(self, t: np.ndarray) -> np.ndarray:
        """Tool-tip radius at times ``t`` (s), in m."""
        t = np.asarray(t, dtype=float)
        n = self.lenslets_per_ring
        t_ring = n / self.frequency
        k = np.clip(np.floor(t / t_ring), 0, self.ring_count - 1)
        tau = t - k * t_ring
        ramp_start = (n - 0.5) / self.frequency
        u = np.clip((tau - ramp_start) * (2.0 * self.frequency), 0.0, 1.0)
        step = np.where(k < self.ring_count - 1, 0.5 * (1.0 - np.cos(np.pi * u)), 0.0)
        return self.ring_radius - self.ring_pitch * (k + step)

    def z_at(self, t: np.ndarray) -> np.ndarray:
        """Commanded tool-tip height at times ``t`` (s), in m."""
        t = np.asarray(t, dtype=float)
        A = self.amplitude
        return (A - self.depth_of_cut) - A * np.sin(2.0 * np.pi * self.frequency * t)

    @property
    def max_depth(self) -> float:
        """Deepest commanded point below z = 0, in m."""
        return self.depth_of_cut

    def _fill(self, starts, stops, fs, t, theta, r, z) -> None:
        """Write samples k in [starts[m], stops[m]) into t, theta, r, z (numba)."""
        from ..kernels._paths import _sample_lenslet

        _sample_lenslet(starts, stops, fs, self.theta0, self.angular_speed,
                        self.frequency, self.amplitude, self.depth_of_cut,
                        self.ring_radius, self.ring_pitch, self.ring_count,
                        self.lenslets_per_ring, t, theta, r, z)


@dataclass(frozen=True)
class ToolpathSpec:
    """A toolpath file: the path, the tool and the simulated field.

    Parameters
    ----------
    kind : {"facing", "lenslet", "surface", "nc"}
        Which toolpath.
    path : FacingToolpath, LensletToolpath, DesignToolpath or BlockPath
        The path definition (``"nc"``: an NC program's cutting blocks).
    tool : Tool
        The diamond tool.
    field : Field
        The simulated grid.
    description : str, default: ""
        Free text.
    """

    kind: Literal["facing", "lenslet", "surface", "nc"]
    path: Any
    tool: Tool = _dc_field(default_factory=Tool)
    field: Field = _dc_field(default_factory=Field)
    description: str = ""

    def __post_init__(self) -> None:
        expected = _path_types().get(self.kind)
        if expected is None:
            raise ConfigError(
                f"kind must be 'facing', 'lenslet', 'surface' or 'nc', got "
                f"{self.kind!r}")
        if not isinstance(self.path, expected):
            raise ConfigError(
                f"kind {self.kind!r} needs a {expected.__name__}, got "
                f"{type(self.path).__name__}"
            )


_PATH_TYPES: dict[str, type] = {"facing": FacingToolpath, "lenslet": LensletToolpath}


def _path_types() -> dict[str, type]:
    """Path class of every toolpath kind (``surface`` and ``nc`` imported on use)."""
    from ._design import DesignToolpath
    from ._trajectory import BlockPath

    return {**_PATH_TYPES, "surface": DesignToolpath, "nc": BlockPath}


#: The tables each kind reads (a table of another kind is an error).
_KIND_TABLES = {"facing": ("facing",), "lenslet": ("lenslet",),
                "surface": ("surface", "spiral")}
_ROOT_KEYS = ("kind", "description", "facing", "lenslet", "surface", "spiral", "tool",
              "field")
_DEG_KEYS = ("rake-angle", "clearance-angle", "arc-half-angle")


def _pop_alias(table: dict[str, Any], key: str, alias: str, scale: float,
               prefix: str) -> None:
    if alias in table:
        if key in table:
            raise ConfigError(f"{prefix}: give either {key!r} or {alias!r}, not both")
        v = table.pop(alias)
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ConfigError(
                f"{prefix}.{alias}: expected float, got {type(v).__name__}")
        table[key] = float(v) * scale


def toolpath_from_mapping(data: Mapping[str, Any], *,
                          base_dir: str | Path | None = None,
                          nose_radius: float | None = None,
                          nc_overrides: Mapping[str, Any] | None = None
                          ) -> ToolpathSpec:
    """Build a :class:`ToolpathSpec` from a parsed TOML mapping.

    Parameters
    ----------
    data : Mapping
        The TOML document (kebab-case keys). Boundary aliases: ``spindle-speed-rpm``
        (rpm) for ``facing.spindle-speed`` (rev/s); ``<angle>-deg`` (degree) for the
        tool's ``rake-angle``, ``clearance-angle`` and ``arc-half-angle`` (rad);
        ``tool.edge-waviness`` names a CSV file (see :func:`read_waviness_csv`);
        ``tool.edge-trace`` names a measured edge trace that gives the nose radius,
        arc and waviness (see :func:`~servosurf.toolpath.tool_table_from_trace`
        for its ``edge-*`` keys, e.g. ``edge-compensated = true``).
    base_dir : str or Path, optional
        Directory against which a relative ``edge-waviness`` path (and an NC
        program) is resolved.
    nose_radius : float, optional
        Tool nose radius in m replacing the file's (``--tool-radius``).
    nc_overrides : Mapping, optional
        Kind ``"nc"``: :class:`~servosurf.toolpath.NCSettings` fields replacing the
        file's (see :func:`~servosurf.toolpath.nc_spec_from_mapping`).

    Returns
    -------
    ToolpathSpec
        The validated specification.

    Raises
    ------
    ConfigError
        On unknown keys (with suggestions), a missing or wrong ``kind``, bad values.
    """
    kind = data.get("kind")
    if kind == "nc":
        from ._trajectory import nc_spec_from_mapping

        return nc_spec_from_mapping(
            data, base_dir=base_dir, overrides=nc_overrides, nose_radius=nose_radius,
            tool_from_table=lambda tab: _tool_from_table(tab, base_dir))
    for key in data:
        if key not in _ROOT_KEYS:
            sugg = difflib.get_close_matches(str(key), _ROOT_KEYS, n=1)
            hint = f" Did you mean: {sugg[0]}?" if sugg else ""
            raise ConfigError(
                f"unknown key {key!r}.{hint} Allowed keys here: {', '.join(_ROOT_KEYS)}"
            )
    if kind not in _KIND_TABLES:
        raise ConfigError(
            f"kind must be 'facing', 'lenslet', 'surface' or 'nc', got {kind!r}")
    for other, tables in _KIND_TABLES.items():
        for t in tables:
            if other != kind and t not in _KIND_TABLES[kind] and t in data:
                raise ConfigError(f"[{t}] table given but kind = {kind!r}")
    path_tab = dict(data.get(kind, {}))
    if kind == "facing":
        _pop_alias(path_tab, "spindle-speed", "spindle-speed-rpm", 1.0 / 60.0, kind)
    tool_tab = dict(data.get("tool", {}))
    if nose_radius is not None:
        tool_tab.pop("nose_radius", None)
        tool_tab["nose-radius"] = float(nose_radius)
    tool = _tool_from_table(tool_tab, base_dir)
    if kind == "surface":
        from ._design import design_toolpath_from_mapping

        path = design_toolpath_from_mapping(data.get("surface", {}),
                                            data.get("spiral", {}), tool)
    else:
        path = from_mapping(_PATH_TYPES[kind], path_tab, prefix=kind)
    fld = from_mapping(Field, dict(data.get("field", {})), prefix="field")
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise ConfigError(f"description: expected str, got {type(desc).__name__}")
    return ToolpathSpec(kind=kind, path=path, tool=tool, field=fld, description=desc)


def _tool_from_table(tool_tab: dict[str, Any], base_dir: str | Path | None) -> Tool:
    """The :class:`Tool` of a ``[tool]`` table, with the degree, CSV and measured
    edge-trace aliases."""
    tool_tab, _ = tool_table_from_trace(dict(tool_tab), base_dir=base_dir)
    for key in _DEG_KEYS:
        _pop_alias(tool_tab, key, key + "-deg", math.pi / 180.0, "tool")
    if "waviness-angle-deg" in tool_tab:
        if "waviness-angle" in tool_tab:
            raise ConfigError("tool: give either 'waviness-angle' or "
                              "'waviness-angle-deg', not both")
        v = tool_tab.pop("waviness-angle-deg")
        if not isinstance(v, list) or not all(
                isinstance(x, int | float) and not isinstance(x, bool) for x in v):
            raise ConfigError("tool.waviness-angle-deg: expected a list of numbers")
        tool_tab["waviness-angle"] = [math.radians(float(x)) for x in v]
    if "edge-waviness" in tool_tab:
        if "waviness-angle" in tool_tab or "waviness-deviation" in tool_tab:
            raise ConfigError("tool: give either edge-waviness (a CSV file) or "
                              "waviness-angle/waviness-deviation, not both")
        fname = tool_tab.pop("edge-waviness")
        if not isinstance(fname, str):
            raise ConfigError("tool.edge-waviness must be a file name (str)")
        p = Path(fname)
        if not p.is_absolute() and base_dir is not None:
            p = Path(base_dir) / p
        ang, dev = read_waviness_csv(p)
        tool_tab["waviness-angle"] = list(ang)
        tool_tab["waviness-deviation"] = list(dev)
    return from_mapping(Tool, tool_tab, prefix="tool")


def builtin_toolpaths() -> dict[str, Path]:
    """Return ``{name: path}`` of the toolpath files shipped with servosurf.

    The names work wherever a toolpath path does (``load_toolpath("lenslet_5um")``,
    ``servosurf simulate lenslet_5um``); ``servosurf toolpaths`` lists them.
    """
    from .._builtins import builtin_files

    return builtin_files("toolpath")


def load_toolpath(path: str | Path, *, nose_radius: float | None = None,
                  nc_overrides: Mapping[str, Any] | None = None) -> ToolpathSpec:
    """Read a toolpath TOML file (``toolpaths/*.toml``) or a built-in by name.

    Parameters
    ----------
    path : str or Path
        The TOML file: ``kind = "facing" | "lenslet" | "surface" | "nc"``, a
        ``[facing]``, ``[lenslet]`` or ``[nc]`` table or the ``[surface]`` and
        ``[spiral]`` tables of a design surface
        (:func:`~servosurf.toolpath.design_toolpath_from_mapping`), ``[tool]`` and
        ``[field]``; or the name of a built-in toolpath (see
        :func:`builtin_toolpaths`), e.g. ``"lenslet_5um"``.
    nose_radius : float, optional
        Tool nose radius in m replacing the file's.
    nc_overrides : Mapping, optional
        Kind ``"nc"``: settings replacing the file's ``[nc]`` values.

    Returns
    -------
    ToolpathSpec
        The validated specification.

    Raises
    ------
    ConfigError
        If the file is missing, not TOML, or has unknown keys or bad values.
    """
    from .._builtins import resolve_file

    p = resolve_file(path, kind="toolpath")
    return toolpath_from_mapping(load_toml(p), base_dir=p.parent,
                                 nose_radius=nose_radius, nc_overrides=nc_overrides)
