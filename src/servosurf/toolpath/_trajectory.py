"""An NC program as a toolpath: its cutting blocks interpolated over time.

:class:`BlockPath` turns the cutting blocks of an :class:`~servosurf.toolpath.NCProgram`
into the path protocol the sweep and the simulation use (``theta_at``, ``radius_at``,
``z_at``, ``duration``, ``time_span_for_radius``, ``_fill``, ...).

Decisions (SI units: m, s, rad)
-------------------------------
* **Interpolation.** The machine interpolates every block linearly in (C, X, Z)
  over the block's time. X and Z are therefore linear in C within a block, which is
  exactly what the sweep kernel does between two samples (linear in the angle), so
  the block end points themselves are an exact sampling of the path
  (:meth:`BlockPath.vertex_samples`, used by kinematic runs).
* **Time base.** One of: ``spindle_speed`` (rev/s; the C axis turns at that constant
  speed, each block takes ``|dC| / (2 pi n)``), ``block_time`` (s per cutting block)
  or the program's own G93 inverse-time feeds. The user's value wins over the
  program's. A program whose G93 feeds give a mean spindle speed below
  :data:`MIN_PROGRAM_RPM` (1021 and 1022: ``F0.001``, 60000 s per 0.5 degree block,
  1.4e-6 rpm) carries no usable time base: that is an error asking for one. A
  two-axis program (no C; DIFFSYS ``.pgm``) needs the spindle speed and the
  traverse: ``block_time``, ``feed_per_rev`` (path length per revolution, m) or the
  program's G94 feeds.
* **Links** (rapids and G94 moves of a C program, see :mod:`~servosurf.toolpath._nc`)
  are not swept. Between two cutting runs the path is interpolated straight from
  the end of one to the start of the next; the link lasts the time of its feed
  moves, and at least ``max(2 x the longest cutting block, 1 ms)`` so that samples
  on either side never bracket a crossing.
* **Rotation sense.** ``rotation = "ccw"``: as C increases the tool moves
  counter-clockwise over the part seen from +z (the tool side), so the tool angle in
  the workpiece frame is ``theta = +C``; ``"cw"``: ``theta = -C``. The sweep kernel
  needs theta strictly increasing in time. When the program turns C the other way
  (C decreasing for ``ccw``, increasing for ``cw``), the path is swept in the mirror
  image of the workpiece frame (y -> -y, theta -> -theta) and the map is mirrored
  back (:meth:`BlockPath.kernel_field`, :meth:`BlockPath.unmirror`). Every cutting
  block must turn C in the same sense; a block that moves X or Z with C standing
  still is refused. Two-axis programs turn at ``theta = 2 pi n t`` in the chosen
  sense.
* **Past the axis.** A block end with X < 0 lies at radius ``|X|`` half a turn away
  (``theta + pi``). A block that crosses X = 0 is split at the axis: the tool
  reaches r = 0, and the angle jumps by pi there (two samples at r = 0 and the same
  time; the kernel's interpolation between them stays on the axis).
* **Reference.** The program's Z is the tool tip (the lowest point of the nose arc)
  or the nose centre; a centre path is converted to the tip: ``z_tip = z - R``
  with R the simulated tool's nose radius.
* **Runs.** Separate cutting runs (e.g. several passes of a WHILE loop) are kept in
  time order; a later run's angle is raised by whole turns so that theta keeps
  increasing (the physical angle is unchanged).
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass
from dataclasses import field as _dc_field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..config import from_mapping, param
from ..errors import ConfigError
from ._nc import NCProgram, read_nc_program
from ._tool import Field, Tool

__all__ = [
    "BlockPath",
    "NCSettings",
    "band_field",
    "nc_spec",
    "nc_spec_from_mapping",
    "apply_overrides",
    "MIN_PROGRAM_RPM",
    "BAND_PITCH",
    "BAND_ROWS",
]

#: A program's own G93 feeds are a usable time base only above this mean spindle
#: speed, in rev/min (the slowest slow-tool-servo spindle speeds are a few rpm).
MIN_PROGRAM_RPM = 1.0
#: Shortest link between two cutting runs, in s (see the module docstring).
MIN_LINK_TIME = 1e-3
#: Pitch of the default band field of an NC run, in m (x and y).
BAND_PITCH = 0.5e-6
#: Rows of the default band field (centred on y = 0).
BAND_ROWS = 5

_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class NCSettings:
    """How to run an NC program: the ``[nc]`` table of a toolpath file.

    Parameters
    ----------
    program : str
        NC program file; relative names resolve against the toolpath file.
    spindle_speed : float, optional
        Spindle speed n, in rev/s: C turns at this constant speed (TOML:
        ``spindle-speed`` or ``spindle-speed-rpm`` in rev/min).
    block_time : float, optional
        Duration of every cutting block, in s.
    feed_per_rev : float, optional
        Two-axis programs only: path length per revolution, in m.
    reference : {"program", "tip", "centre"}, default: "program"
        What the program's Z is: the tool tip (front point) or the nose centre;
        ``"program"`` takes what the program states (DIFFSYS header) and the tip
        when it states nothing.
    rotation : {"ccw", "cw"}, default: "ccw"
        Sense in which the tool moves over the part, seen from +z (the tool side),
        as C increases (two-axis programs: the spindle's sense).
    units : {"mm", "inch"}, default: "mm"
        Units of X and Z until the program sets them (G70/G71, DIFFSYS header).
    format : {"auto", "gcode", "pgm", "csv"}, default: "auto"
        File format (auto: by suffix and content).
    """

    program: str = param("", doc="NC program file (relative to the toolpath file)")
    spindle_speed: float | None = param(None, unit="rev/s", doc="spindle speed",
                                        low=0.0, low_open=True)
    block_time: float | None = param(None, unit="s", doc="time per cutting block",
                                     low=0.0, low_open=True)
    feed_per_rev: float | None = param(None, unit="m",
                                       doc="path length per revolution (two-axis)",
                                       low=0.0, low_open=True)
    reference: Literal["program", "tip", "centre"] = param(
        "program", doc="tool reference point of the program's Z")
    rotation: Literal["ccw", "cw"] = param(
        "ccw", doc="tool motion over the part seen from +z as C increases")
    units: Literal["mm", "inch"] = param("mm", doc="units until the program sets them")
    format: Literal["auto", "gcode", "pgm", "csv"] = param("auto", doc="file format")

    def __post_init__(self) -> None:
        if self.block_time is not None and self.feed_per_rev is not None:
            raise ConfigError("nc: give block-time or feed-per-rev, not both")
        if self.spindle_speed is not None and self.spindle_speed > 20000.0 / 60.0:
            raise ConfigError(
                f"nc.spindle-speed must be in rev/s, got {self.spindle_speed!r} "
                f"({self.spindle_speed * 60:g} rpm): a value in rpm? use "
                "spindle-speed-rpm")
        if self.feed_per_rev is not None and self.feed_per_rev > 1e-3:
            raise ConfigError(
                f"nc.feed-per-rev must be in m, got {self.feed_per_rev!r} m "
                f"({self.feed_per_rev * 1e6:g} um per revolution): a value in mm or "
                "um?")
        if self.block_time is not None and self.block_time > 60.0:
            raise ConfigError(
                f"nc.block-time must be in s per block, got {self.block_time!r} s: "
                "a value in ms?")


def _interp_segments(tq, t, v):
    return np.interp(np.asarray(tq, dtype=float), t, v)


@dataclass(frozen=True, eq=False)
class BlockPath:
    """Cutting blocks of an NC program as a toolpath in time (kernel frame).

    Build it with :meth:`from_program`. The arrays hold the vertices of every
    cutting run (block end points, plus the start point of each run and the splits
    at X = 0), in time order, in the frame the sweep kernel uses (theta strictly
    increasing; mirrored when ``mirrored`` is True).

    Attributes
    ----------
    t : ndarray of shape (n,)
        Vertex times, in s, non-decreasing, from 0.
    theta : ndarray of shape (n,)
        Tool angle in the kernel frame, in rad, strictly increasing.
    r : ndarray of shape (n,)
        Tool-tip radius, in m (>= 0).
    z : ndarray of shape (n,)
        Tool-tip height, in m (the program's Z, a centre path converted).
    run : ndarray of int64, shape (n,)
        Index of the cutting run of each vertex.
    line : ndarray of int64, shape (n,)
        Source line of each vertex (0 for a split at the axis).
    mirrored : bool
        True when theta is the mirror image of the physical tool angle.
    block_duration_max : float
        Longest cutting block, in s.
    spindle_speed : float or None
        Constant spindle speed in rev/s, None when the speed varies.
    time_base : str
        How block times were obtained, for reports.
    reference : {"tip", "centre"}
        Reference point of the program's Z (a centre path is converted).
    rotation : {"ccw", "cw"}
        Sense of the tool over the part as C increases.
    source : str
        The program file.
    nose_radius : float
        Nose radius used for a centre-to-tip conversion, in m.
    """

    t: np.ndarray
    theta: np.ndarray
    r: np.ndarray
    z: np.ndarray
    run: np.ndarray
    line: np.ndarray
    mirrored: bool
    block_duration_max: float
    spindle_speed: float | None
    time_base: str
    reference: Literal["tip", "centre"]
    rotation: Literal["ccw", "cw"]
    source: str = ""
    nose_radius: float = 0.0
    program: NCProgram | None = _dc_field(default=None, repr=False)

    # -- construction ----------------------------------------------------------
    @classmethod
    def from_program(
        cls,
        program: NCProgram,
        *,
        nose_radius: float,
        spindle_speed: float | None = None,
        block_time: float | None = None,
        feed_per_rev: float | None = None,
        reference: Literal["program", "tip", "centre"] = "program",
        rotation: Literal["ccw", "cw"] = "ccw",
    ) -> BlockPath:
        """Interpolate the cutting blocks of ``program`` over time.

        Parameters
        ----------
        program : NCProgram
            The program (:func:`~servosurf.toolpath.read_nc_program`).
        nose_radius : float
            Tool nose radius R, in m (converts a nose-centre path to the tip).
        spindle_speed : float, optional
            Spindle speed, in rev/s.
        block_time : float, optional
            Duration of each cutting block, in s.
        feed_per_rev : float, optional
            Two-axis programs: path length per revolution, in m.
        reference : {"program", "tip", "centre"}, default: "program"
            Reference point of the program's Z (``"program"``: as the file states,
            the tip when it states nothing).
        rotation : {"ccw", "cw"}, default: "ccw"
            Sense of the tool over the part as C increases (see the module
            docstring).

        Returns
        -------
        BlockPath
            The path.

        Raises
        ------
        ConfigError
            Missing or unusable time base (the message says which to give), C
            turning both ways or standing still in a cutting block, a reference
            that contradicts the program's, no cutting block.
        """
        return _build(program, float(nose_radius), spindle_speed, block_time,
                      feed_per_rev, reference, rotation)

    # -- path protocol -----------------------------------------------------------
    @property
    def duration(self) -> float:
        """Time from the first to the last cutting vertex, in s."""
        return float(self.t[-1])

    @property
    def theta0(self) -> float:
        """Tool angle at t = 0 (kernel frame), in rad."""
        return float(self.theta[0])

    @property
    def rev_per_s(self) -> float:
        """Spindle speed in rev/s: the constant one, else the mean over the path."""
        if self.spindle_speed is not None:
            return self.spindle_speed
        if self.duration <= 0:
            return 0.0
        return float((self.theta[-1] - self.theta[0]) / (_TWO_PI * self.duration))

    @property
    def angular_speed(self) -> float:
        """2 pi times :attr:`rev_per_s`, in rad/s."""
        return _TWO_PI * self.rev_per_s

    @property
    def n_revolutions(self) -> float:
        """Turns of the tool angle over the cutting runs."""
        return float((self.theta[-1] - self.theta[0]) / _TWO_PI)

    @property
    def n_runs(self) -> int:
        """Number of cutting runs."""
        return int(self.run[-1]) + 1

    @property
    def r_max(self) -> float:
        """Largest tool-tip radius of the cutting runs, in m."""
        return float(self.r.max())

    @property
    def max_depth(self) -> float:
        """Deepest tool-tip height below z = 0, in m (0 when the path stays above)."""
        return max(0.0, -float(self.z.min()))

    def theta_at(self, t: np.ndarray) -> np.ndarray:
        """Tool angle (kernel frame) at times ``t`` (s), in rad."""
        return _interp_segments(t, self.t, self.theta)

    def radius_at(self, t: np.ndarray) -> np.ndarray:
        """Tool-tip radius at times ``t`` (s), in m."""
        return _interp_segments(t, self.t, self.r)

    def z_at(self, t: np.ndarray) -> np.ndarray:
        """Commanded tool-tip height at times ``t`` (s), in m."""
        return _interp_segments(t, self.t, self.z)

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Path at times ``t`` (s): angle (rad), radius (m), height (m)."""
        return self.theta_at(t), self.radius_at(t), self.z_at(t)

    def time_at_theta(self, theta: np.ndarray) -> np.ndarray:
        """Time (s) at which the tool angle (kernel frame, rad) is ``theta``.

        Clamped to ``[0, duration]`` outside the path's angles.
        """
        return np.interp(np.asarray(theta, dtype=float), self.theta, self.t)

    def cutting_spans(self) -> np.ndarray:
        """Time intervals of the cutting runs, in s, shape (n_runs, 2)."""
        starts = np.flatnonzero(np.diff(self.run, prepend=-1) != 0)
        ends = np.append(starts[1:] - 1, self.t.size - 1)
        return np.column_stack((self.t[starts], self.t[ends]))

    def time_span_for_radius(self, rlo: float,
                             rhi: float) -> tuple[float, float] | None:
        """Time interval from the first to the last cutting moment in [rlo, rhi].

        Parameters
        ----------
        rlo, rhi : float
            Radial range in m.

        Returns
        -------
        tuple of float or None
            ``(t0, t1)`` in s (the hull: the tool may leave and re-enter the range
            in between), or None when no cutting run enters the range.
        """
        t, r, run = self.t, self.r, self.run
        same = run[1:] == run[:-1]
        r0, r1 = r[:-1], r[1:]
        lo = np.minimum(r0, r1)
        hi = np.maximum(r0, r1)
        hit = same & (hi >= rlo) & (lo <= rhi)
        single = (r >= rlo) & (r <= rhi)
        if not hit.any() and not single.any():
            return None
        cand_lo, cand_hi = [], []
        if single.any():
            cand_lo.append(float(t[single].min()))
            cand_hi.append(float(t[single].max()))
        if hit.any():
            i = np.flatnonzero(hit)
            dt = t[i + 1] - t[i]
            dr = r1[i] - r0[i]
            with np.errstate(divide="ignore", invalid="ignore"):
                a_lo = np.where(dr != 0, (rlo - r0[i]) / dr, -np.inf)
                a_hi = np.where(dr != 0, (rhi - r0[i]) / dr, np.inf)
            a0 = np.clip(np.minimum(a_lo, a_hi), 0.0, 1.0)
            a1 = np.clip(np.maximum(a_lo, a_hi), 0.0, 1.0)
            a0 = np.where(dr != 0, a0, 0.0)
            a1 = np.where(dr != 0, a1, 1.0)
            cand_lo.append(float((t[i] + a0 * dt).min()))
            cand_hi.append(float((t[i] + a1 * dt).max()))
        return min(cand_lo), max(cand_hi)

    def _fill(self, starts, stops, fs, t, theta, r, z) -> None:
        """Write samples k in [starts[m], stops[m]) into t, theta, r, z."""
        from ._sample import _ranges_to_index

        k = _ranges_to_index(np.asarray(starts), np.asarray(stops))
        tk = k / float(fs)
        t[:] = tk
        theta[:] = np.interp(tk, self.t, self.theta)
        r[:] = np.interp(tk, self.t, self.r)
        z[:] = np.interp(tk, self.t, self.z)

    # -- kinematic samples and frames --------------------------------------------
    def vertex_samples(self):
        """The path sampled at its vertices: exact for linear block interpolation.

        Returns
        -------
        SampledPath
            ``t`` holds the vertex times (not a uniform grid) and ``fs`` the block
            rate ``1 / block_duration_max``, so that consecutive vertices of a run
            are consecutive samples and the links between runs (longer than 1.5 /
            fs) are gaps. Use it for sweeps only: there is no controller sample
            behind ``index``.
        """
        from ._sample import SampledPath

        return SampledPath(t=self.t, theta=self.theta, r=self.r, z=self.z,
                           fs=1.0 / self.block_duration_max)

    def kernel_field(self, field: Field) -> Field:
        """The field in the kernel frame (mirrored in y when the path is)."""
        if not self.mirrored:
            return field
        import dataclasses

        return dataclasses.replace(field, center_y=-field.center_y)

    def unmirror(self, surface):
        """Map a surface swept on :meth:`kernel_field` back onto the field.

        Parameters
        ----------
        surface : Surface
            Heights on the kernel-frame field, in m.

        Returns
        -------
        Surface
            Heights on the physical field (rows flipped when mirrored).
        """
        if not self.mirrored:
            return surface
        y0 = -(surface.y0 + (surface.shape[0] - 1) * surface.dy)
        return surface.replace(z=np.ascontiguousarray(surface.z[::-1]), y0=y0)

    def feed_per_revolution(self) -> tuple[np.ndarray, np.ndarray]:
        """Radial feed per revolution along the path.

        Returns
        -------
        r : ndarray of shape (m,)
            Radius of the vertex, in m.
        feed : ndarray of shape (m,)
            ``r(theta) - r(theta + 2 pi)`` within the same run, in m (positive
            when the tool moves inward); vertices less than a turn from the end of
            their run are left out.
        """
        rs, fs = [], []
        for j in range(self.n_runs):
            m = self.run == j
            th, r = self.theta[m], self.r[m]
            ok = th + _TWO_PI <= th[-1]
            if not ok.any():
                continue
            rs.append(r[ok])
            fs.append(r[ok] - np.interp(th[ok] + _TWO_PI, th, r))
        if not rs:
            return np.zeros(0), np.zeros(0)
        return np.concatenate(rs), np.concatenate(fs)

    def radial_form(self, radius: np.ndarray) -> np.ndarray:
        """Commanded tip height as a function of radius: the path's form, in m.

        Parameters
        ----------
        radius : ndarray
            Radii at which to evaluate, in m.

        Returns
        -------
        ndarray
            Per cutting run, the tip height interpolated linearly over the run's
            vertices sorted by radius (exact for a spiral, whose radius changes
            monotonically); the lowest over the runs that reach the radius (the
            last cut leaves the lowest surface). The nearest run's end value
            beyond every run's radial range.
        """
        q = np.asarray(radius, dtype=float)
        best = np.full(q.shape, np.inf)
        ends = []
        for j in range(self.n_runs):
            m = self.run == j
            order = np.argsort(self.r[m], kind="stable")
            r, z = self.r[m][order], self.z[m][order]
            inside = (q >= r[0]) & (q <= r[-1])
            best = np.where(inside, np.minimum(best, np.interp(q, r, z)), best)
            ends.append((r[0], z[0], r[-1], z[-1]))
        out = best
        miss = ~np.isfinite(out)
        if miss.any():
            lo = min(ends, key=lambda e: e[0])
            hi = max(ends, key=lambda e: e[2])
            out = np.where(miss, np.where(q < lo[0], lo[1], hi[3]), out)
        return out

    def describe(self) -> dict[str, Any]:
        """JSON-ready description of the path (SI units)."""
        return {
            "source": self.source,
            "time_base": self.time_base,
            "spindle_speed_rev_per_s": self.spindle_speed,
            "mean_spindle_speed_rev_per_s": self.rev_per_s,
            "reference": self.reference,
            "rotation": self.rotation,
            "mirrored_for_sweep": self.mirrored,
            "n_vertices": int(self.t.size),
            "n_runs": self.n_runs,
            "n_revolutions": self.n_revolutions,
            "duration_s": self.duration,
            "r_max_m": self.r_max,
            "block_duration_max_s": self.block_duration_max,
        }


# --------------------------------------------------------------------------------
# building a BlockPath
# --------------------------------------------------------------------------------


def _line_of(program: NCProgram, i: int) -> str:
    return f"{program.source}: line {int(program.line[i])}"


def _resolve_reference(program: NCProgram, reference: str) -> str:
    if reference not in ("program", "tip", "centre"):
        raise ConfigError(f"reference must be 'tip', 'centre' or 'program', got "
                          f"{reference!r}")
    stated = program.reference
    if reference == "program":
        return stated or "tip"
    if stated is not None and stated != reference:
        raise ConfigError(
            f"{program.source}: the program states a {stated} path (header Reference "
            f"Point) but reference {reference!r} was given; drop it or fix the file")
    return reference


def _build(program, R, spindle_speed, block_time, feed_per_rev, reference,
           rotation) -> BlockPath:
    if not isinstance(program, NCProgram):
        raise ConfigError(f"program must be an NCProgram, got {type(program).__name__}")
    if not (math.isfinite(R) and R > 0):
        raise ConfigError(f"nose_radius must be > 0 m, got {R!r}")
    if rotation not in ("ccw", "cw"):
        raise ConfigError(f"rotation must be 'ccw' or 'cw', got {rotation!r}")
    ref = _resolve_reference(program, reference)
    for name, v in (("spindle_speed", spindle_speed), ("block_time", block_time),
                    ("feed_per_rev", feed_per_rev)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ConfigError(f"{name} must be > 0, got {v!r}")
    runs = [ru for ru in program.cutting_runs()]
    if not runs:
        raise ConfigError(f"{program.source}: no cutting blocks (every move is a link: "
                          "G0 rapids and G94 moves without C)")
    two = program.two_axis
    c_all, x_all, z_all = program.c, program.x, program.z
    need = (x_all, z_all) if two else (c_all, x_all, z_all)

    # --- vertices of each run: optional known start point, then block ends ------
    pieces = []
    for i0, i1 in runs:
        idx = list(range(i0, i1))
        for i in idx:
            for arr, nm in zip(need, ("X", "Z") if two else ("C", "X", "Z"),
                               strict=False):
                if not math.isfinite(arr[i]):
                    raise ConfigError(
                        f"{_line_of(program, i)}: cutting block before any {nm} "
                        "position is known (the machine's start position is not in "
                        "the file)")
        start = i0 - 1
        if start >= 0 and all(math.isfinite(a[start]) for a in need):
            idx = [start] + idx
        pieces.append(np.asarray(idx, dtype=np.int64))

    # --- C sense (C programs) -------------------------------------------------
    sense = 1.0
    if not two:
        # an approach that only moves X/Z into the first cutting point belongs to
        # the link: drop a run's start point when the first block does not turn C
        pieces = [idx[1:] if (idx.size > 1 and idx[0] == runs[j][0] - 1
                              and c_all[idx[1]] == c_all[idx[0]]) else idx
                  for j, idx in enumerate(pieces)]
        signs = []
        for idx in pieces:
            dc = np.diff(c_all[idx])
            nz = dc[dc != 0]
            signs.append(np.sign(nz))
            moves = (np.diff(x_all[idx]) != 0) | (np.diff(z_all[idx]) != 0)
            still = (dc == 0) & moves
            if still.any():
                k = idx[1:][np.flatnonzero(still)[0]]
                raise ConfigError(
                    f"{_line_of(program, k)}: cutting block moves X/Z while C stays at "
                    f"{math.degrees(c_all[k]):g} deg; every cutting block must turn "
                    "the spindle (a plunge with the spindle stopped is not supported)")
        s_all = np.concatenate(signs) if signs else np.zeros(0)
        if s_all.size == 0:
            raise ConfigError(f"{program.source}: no cutting block turns C")
        sense = float(s_all[0])
        if np.any(s_all != sense):
            for idx in pieces:
                dc = np.diff(c_all[idx])
                bad = np.flatnonzero(np.sign(dc) == -sense)
                if bad.size:
                    k = idx[1:][bad[0]]
                    raise ConfigError(
                        f"{_line_of(program, k)}: C turns back "
                        f"({math.degrees(dc[bad[0]]):+g} deg); every cutting block "
                        "must turn C in the sense of the first one")
    sigma = 1.0 if rotation == "ccw" else -1.0
    mirrored = (sense * sigma < 0) if not two else (sigma < 0)

    # --- durations --------------------------------------------------------------
    user = [n for n, v in (("spindle speed", spindle_speed), ("block time", block_time),
                           ("feed per revolution", feed_per_rev)) if v is not None]
    if two:
        if spindle_speed is None:
            raise ConfigError(
                f"{program.source}: a two-axis program (no C) turns at a constant "
                "spindle speed that is not in the file: give --spindle-rpm N "
                "(nc.spindle-speed-rpm)")
        if block_time is None and feed_per_rev is None:
            for idx in pieces:
                if not np.all(np.isfinite(program.block_time[idx[1:]])):
                    raise ConfigError(
                        f"{program.source}: the program gives no feed for its cutting "
                        "moves: give --block-time S or nc.feed-per-rev (m per "
                        "revolution)")
            traverse = "the program's G94 feeds"
        elif block_time is not None:
            traverse = f"{block_time:g} s per cutting block (given)"
        else:
            traverse = f"{feed_per_rev:g} m per revolution (given)"
        omega = _TWO_PI * spindle_speed
        time_base = f"spindle {spindle_speed * 60:g} rpm (given), traverse {traverse}"
    else:
        if feed_per_rev is not None:
            raise ConfigError("feed_per_rev applies to two-axis programs only; a C "
                              "program gives the rotation of every block: use "
                              "spindle_speed or block_time")
        if spindle_speed is not None and block_time is not None:
            raise ConfigError("give one time base: spindle_speed or block_time, "
                              "not both")
        omega = None if spindle_speed is None else _TWO_PI * spindle_speed
        if user:
            time_base = (f"spindle {spindle_speed * 60:g} rpm (given)"
                         if spindle_speed is not None else
                         f"{block_time:g} s per cutting block (given)")
        else:
            time_base = _program_time_base(program, pieces)

    durations = []
    for idx in pieces:
        n = idx.size - 1
        if two:
            if block_time is not None:
                d = np.full(n, block_time)
            elif feed_per_rev is not None:
                L = np.hypot(np.diff(x_all[idx]), np.diff(z_all[idx]))
                d = L / (feed_per_rev * spindle_speed)
            else:
                d = program.block_time[idx[1:]]
        else:
            dc = np.abs(np.diff(c_all[idx]))
            if omega is not None:
                d = dc / omega
            elif block_time is not None:
                d = np.full(n, block_time)
            else:
                d = program.block_time[idx[1:]]
            d = np.where(dc == 0, 0.0, d)  # zero-length blocks are dropped below
        durations.append(np.asarray(d, dtype=np.float64))
    dmax = max((float(d.max()) for d in durations if d.size), default=0.0)
    if not dmax > 0:
        raise ConfigError(f"{program.source}: the cutting blocks take no time (no "
                          "motion)")

    # --- vertices in time and angle ---------------------------------------------
    T, TH, RR, ZZ, RUN, LINE = [], [], [], [], [], []
    t_end = None
    th_end = None
    prev_last_block = None
    for j, (idx, d) in enumerate(zip(pieces, durations, strict=True)):
        x = x_all[idx]
        z = z_all[idx] - (R if ref == "centre" else 0.0)
        tt = np.concatenate(([0.0], np.cumsum(d)))
        if two:
            base = tt * omega
        else:
            base = sense * (c_all[idx] - c_all[idx[0]])
        lines = program.line[idx]
        # drop zero-length blocks (C programs: no C, X or Z change)
        if not two:
            keep = np.ones(idx.size, dtype=bool)
            keep[1:] = (np.diff(base) != 0) | (np.diff(x) != 0) | (np.diff(z) != 0)
            x, z, tt, base, lines = x[keep], z[keep], tt[keep], base[keep], lines[keep]
        if x.size < 2:
            continue
        x, z, tt, base, lines, off = _split_axis(x, z, tt, base, lines)
        th = base + math.pi * off
        if t_end is None:
            t0 = 0.0
            th0 = (sense * c_all[idx[0]]) if not two else 0.0
        else:
            gap_blocks = program.block_time[prev_last_block + 1: idx[0] + 1]
            link = float(np.nansum(gap_blocks)) if gap_blocks.size else 0.0
            link = max(link, 2.0 * dmax, MIN_LINK_TIME)
            t0 = t_end + link
            if two:
                th0 = th_end + omega * link
            else:
                th0 = sense * c_all[idx[0]]
                if th0 + th[0] <= th_end:
                    th0 += _TWO_PI * (math.floor((th_end - th0 - th[0]) / _TWO_PI) + 1)
        T.append(t0 + tt)
        TH.append(th0 + th)
        RR.append(np.abs(x))
        ZZ.append(z)
        RUN.append(np.full(x.size, len(RUN), dtype=np.int64))
        LINE.append(lines)
        t_end = float(T[-1][-1])
        th_end = float(TH[-1][-1])
        prev_last_block = int(idx[-1])
    if not T:
        raise ConfigError(f"{program.source}: no cutting run moves the tool")
    theta = np.concatenate(TH)
    bp = BlockPath(
        t=np.concatenate(T), theta=theta, r=np.concatenate(RR), z=np.concatenate(ZZ),
        run=np.concatenate(RUN), line=np.concatenate(LINE), mirrored=bool(mirrored),
        block_duration_max=dmax,
        spindle_speed=spindle_speed,
        time_base=time_base, reference=ref, rotation=rotation,
        source=program.source, nose_radius=R, program=program)
    if not np.all(np.diff(bp.theta) > 0):
        k = int(np.flatnonzero(np.diff(bp.theta) <= 0)[0])
        raise ConfigError(f"{program.source}: line {int(bp.line[k + 1])}: the tool "
                          "angle does not advance (a block that turns C by less than "
                          "it should?)")
    return bp


def _program_time_base(program: NCProgram, pieces) -> str:
    """Check the program's own G93 times; return the description or raise."""
    every = np.concatenate(pieces)
    every = every[program.cutting[every]]
    missing = ~np.isfinite(program.block_time[every])
    if missing.any():
        k = int(every[np.flatnonzero(missing)[0]])
        raise ConfigError(
            f"{_line_of(program, k)}: the program gives no time for its cutting blocks "
            "(no G93 inverse-time feed): give the time base, --spindle-rpm N or "
            "--block-time S (nc.spindle-speed-rpm or nc.block-time)")
    blocks = np.concatenate([idx[1:] if idx.size > 1 else idx for idx in pieces])
    bt = program.block_time[blocks]
    turn = 0.0
    for idx in pieces:
        turn += float(np.abs(np.diff(program.c[idx])).sum())
    total = float(bt.sum())
    rpm = turn / _TWO_PI / total * 60.0 if total > 0 else 0.0
    if rpm < MIN_PROGRAM_RPM:
        per = float(np.median(bt))
        raise ConfigError(
            f"{program.source}: the program's G93 feeds give {per:g} s per cutting "
            "block, "
            f"a mean spindle speed of {rpm:.3g} rpm: no usable time base; give "
            "--spindle-rpm N or --block-time S (nc.spindle-speed-rpm or nc.block-time)")
    return f"program G93 inverse-time feeds (mean spindle {rpm:.4g} rpm)"


def _split_axis(x, z, tt, base, lines):
    """Split blocks at X = 0; return arrays and the half-turn count per vertex."""
    nz = np.flatnonzero(x != 0)
    if nz.size == 0:
        return x, z, tt, base, lines, np.zeros(x.size)
    side = np.sign(x[nz[0]])
    if np.all(np.sign(x[nz]) == side):
        off = np.full(x.size, 0.0 if side > 0 else 1.0)
        return x, z, tt, base, lines, off
    X, Z, Tt, B, L, K = [], [], [], [], [], []
    k = 0.0 if side > 0 else 1.0
    for i in range(x.size):
        if i > 0 and x[i] != 0 and np.sign(x[i]) != side:
            if x[i - 1] != 0:  # crossing inside the block: a vertex at the axis
                a = x[i - 1] / (x[i - 1] - x[i])
                X.append(0.0)
                Z.append(z[i - 1] + a * (z[i] - z[i - 1]))
                Tt.append(tt[i - 1] + a * (tt[i] - tt[i - 1]))
                B.append(base[i - 1] + a * (base[i] - base[i - 1]))
                L.append(0)
                K.append(k)
            # the axis point again, half a turn on
            k += 1.0
            X.append(0.0)
            Z.append(Z[-1])
            Tt.append(Tt[-1])
            B.append(B[-1])
            L.append(0)
            K.append(k)
            side = np.sign(x[i])
        X.append(x[i])
        Z.append(z[i])
        Tt.append(tt[i])
        B.append(base[i])
        L.append(lines[i])
        K.append(k)
    return (np.asarray(X), np.asarray(Z), np.asarray(Tt), np.asarray(B),
            np.asarray(L, dtype=np.int64), np.asarray(K))


# --------------------------------------------------------------------------------
# toolpath specs of kind "nc"
# --------------------------------------------------------------------------------


def band_field(r_max: float, *, pitch: float = BAND_PITCH,
               rows: int = BAND_ROWS) -> Field:
    """A band through the spindle axis across the whole radius of a program.

    Parameters
    ----------
    r_max : float
        Largest radius of the program, in m.
    pitch : float, default: 0.5e-6
        Pixel pitch along x and y, in m (at most 1 um).
    rows : int, default: 5
        Rows along y, centred on y = 0.

    Returns
    -------
    Field
        Columns from -r_max to +r_max (a column on the axis, x = 0), ``rows`` rows
        centred on y = 0: the row through the centre is ``rows // 2``.
    """
    if not (0 < pitch <= 1e-6):
        raise ConfigError(f"band pitch must be in (0, 1e-6] m, got {pitch!r}")
    half = int(math.floor(float(r_max) / pitch + 1e-9))
    return Field(pitch_x=pitch, pitch_y=pitch, nx=2 * half + 1, ny=int(rows),
                 center_x=0.0, center_y=0.0)


_NC_KEYS = ("kind", "description", "nc", "tool", "field")


def _settings_from_table(tab: Mapping[str, Any]) -> NCSettings:
    t = dict(tab)
    if "spindle-speed-rpm" in t:
        if "spindle-speed" in t:
            raise ConfigError("nc: give either 'spindle-speed' (rev/s) or "
                              "'spindle-speed-rpm', not both")
        v = t.pop("spindle-speed-rpm")
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ConfigError(f"nc.spindle-speed-rpm: expected float, got "
                              f"{type(v).__name__}")
        t["spindle-speed"] = float(v) / 60.0
    return from_mapping(NCSettings, t, prefix="nc")


def nc_spec(program: str | Path | NCProgram, *, settings: NCSettings | None = None,
            tool: Tool | None = None, field: Field | None = None,
            description: str = "", **kwargs):
    """A :class:`~servosurf.toolpath.ToolpathSpec` of kind ``"nc"`` for a program.

    Parameters
    ----------
    program : str, Path or NCProgram
        The program file (or an already read program).
    settings : NCSettings, optional
        Time base, reference, rotation, units, format; keyword arguments
        (``spindle_speed``, ``block_time``, ...) override its fields.
    tool : Tool, optional
        The tool. Default: a :class:`Tool` with the program's stated nose radius;
        a program that states none needs one.
    field : Field, optional
        The grid; default :func:`band_field` over the program's radius.
    description : str, default: ""
        Free text.
    **kwargs
        Fields of :class:`NCSettings`.

    Returns
    -------
    ToolpathSpec
        ``kind = "nc"`` with a :class:`BlockPath`.

    Raises
    ------
    ConfigError
        On a bad program, a missing time base or tool radius, or unknown keywords.
    """
    import dataclasses

    from ._paths import ToolpathSpec

    s = settings or NCSettings()
    if kwargs:
        names = {f.name for f in dataclasses.fields(NCSettings)}
        bad = [k for k in kwargs if k not in names]
        if bad:
            sugg = difflib.get_close_matches(bad[0], names, n=1)
            hint = f" Did you mean: {sugg[0]}?" if sugg else ""
            raise TypeError(f"nc_spec() got an unexpected keyword argument "
                            f"{bad[0]!r}.{hint}")
        s = apply_overrides(s, kwargs)
    if isinstance(program, NCProgram):
        prog = program
    else:
        prog = read_nc_program(program, format=None if s.format == "auto" else s.format,
                               units=s.units)
    if tool is None:
        if prog.tool_radius is None:
            raise ConfigError(
                f"{prog.source}: the program states no tool nose radius: give "
                "--tool-radius M (tool.nose-radius in m)")
        tool = Tool(nose_radius=prog.tool_radius)
    path = BlockPath.from_program(
        prog, nose_radius=tool.nose_radius, spindle_speed=s.spindle_speed,
        block_time=s.block_time, feed_per_rev=s.feed_per_rev, reference=s.reference,
        rotation=s.rotation)
    if field is None:
        field = band_field(path.r_max)
    return ToolpathSpec(kind="nc", path=path, tool=tool, field=field,
                        description=description)


_TIME_BASE = ("spindle_speed", "block_time", "feed_per_rev")


def apply_overrides(settings: NCSettings, overrides: Mapping[str, Any]) -> NCSettings:
    """Replace :class:`NCSettings` fields by the given (not None) values.

    A time base among the overrides (``spindle_speed``, ``block_time``,
    ``feed_per_rev``) replaces the settings' whole time base.

    Parameters
    ----------
    settings : NCSettings
        The settings (of a toolpath file).
    overrides : Mapping
        Field names to values; None means "not given".

    Returns
    -------
    NCSettings
        The updated settings.
    """
    import dataclasses

    given = {k: v for k, v in overrides.items() if v is not None}
    if any(k in given for k in _TIME_BASE):
        for k in _TIME_BASE:
            given.setdefault(k, None)
    return dataclasses.replace(settings, **given) if given else settings


def nc_spec_from_mapping(data: Mapping[str, Any], *,
                         base_dir: str | Path | None = None,
                         tool_from_table=None, overrides: Mapping | None = None,
                         nose_radius: float | None = None):
    """Build the spec of a toolpath file with ``kind = "nc"``.

    Parameters
    ----------
    data : Mapping
        The TOML document: ``[nc]`` (:class:`NCSettings`, ``program`` required),
        ``[tool]`` (with an optional ``reference = "tip" | "centre"``), ``[field]``
        (default: the band through the axis).
    base_dir : str or Path, optional
        Directory against which the program file is resolved.
    tool_from_table : callable, optional
        Builds the :class:`Tool` from the ``[tool]`` table (the loader of the
        other kinds, so the aliases are the same).
    overrides : Mapping, optional
        :class:`NCSettings` fields that replace the file's (command-line flags;
        see :func:`apply_overrides`).
    nose_radius : float, optional
        Tool nose radius in m replacing the file's (``--tool-radius``).

    Returns
    -------
    ToolpathSpec
        The validated specification.
    """
    for key in data:
        if key not in _NC_KEYS:
            sugg = difflib.get_close_matches(str(key), _NC_KEYS, n=1)
            hint = f" Did you mean: {sugg[0]}?" if sugg else ""
            raise ConfigError(
                f"unknown key {key!r}.{hint} Allowed keys here: {', '.join(_NC_KEYS)}")
    tab = data.get("nc")
    if not isinstance(tab, Mapping) or "program" not in tab:
        raise ConfigError("kind = 'nc' needs an [nc] table with program = "
                          "'FILE' (the NC program, relative to this file)")
    tool_tab = dict(data.get("tool", {}))
    ref = tool_tab.pop("reference", None)
    tab = dict(tab)
    if ref is not None:
        if "reference" in tab:
            raise ConfigError("give the reference once: tool.reference or "
                              "nc.reference, not both")
        tab["reference"] = ref
    s = apply_overrides(_settings_from_table(tab), overrides or {})
    prog_path = Path(s.program)
    if not prog_path.is_absolute() and base_dir is not None:
        prog_path = Path(base_dir) / prog_path
    prog = read_nc_program(prog_path, format=None if s.format == "auto" else s.format,
                           units=s.units)
    if nose_radius is not None:
        tool_tab.pop("nose_radius", None)
        tool_tab["nose-radius"] = float(nose_radius)
    if not any(k in tool_tab for k in ("nose-radius", "nose_radius", "edge-trace")):
        # (a measured edge trace gives the radius)
        if prog.tool_radius is None:
            raise ConfigError(
                f"{prog.source}: the program states no tool nose radius: give "
                "tool.nose-radius (m) or --tool-radius M")
        tool_tab["nose-radius"] = prog.tool_radius
    tool = (tool_from_table(tool_tab) if tool_from_table is not None
            else from_mapping(Tool, tool_tab, prefix="tool"))
    fld = None
    if "field" in data:
        fld = from_mapping(Field, dict(data["field"]), prefix="field")
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise ConfigError(f"description: expected str, got {type(desc).__name__}")
    return nc_spec(prog, settings=s, tool=tool, field=fld, description=desc)
