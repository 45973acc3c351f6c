"""Lenslet toolpath and pointwise surface generation (plain numpy).

Geometry from the toolpath TOML (read with :mod:`tomllib`) and the conventions its
documentation states: the FTS command is ``z(t) = (A - d) - A sin(2 pi f t)``; the
spindle turns at ``f / N`` rev/s with ``N = round(2 pi r0 f / v)`` lenslets per ring,
so lenslet centres (deepest points, ``sin = 1``) sit at angles ``2 pi m / N``, one
on the +x axis; ring k is cut during revolution k at ``r0 - k pitch``, the tool
stepping inward with a half-cosine ramp during the second half of the ring's last
period; each ring starts half a turn from the +x axis. The start angle follows:
``theta0 = 2 pi j / N - pi / (2 N)`` with ``j = N // 2``.

Surface: the round-nose edge is a circular arc of radius R in the radial-axial
plane. A point ``(r, theta)`` is touched once per revolution, at the time the tool
passes its angle; the height left there is the lowest of the arcs of all passes,
``z_tool(t) + R - sqrt(R^2 - dr^2) - W(phi) / cos(phi)`` (``dr`` the radial offset
from the tool, ``phi = asin(dr / R)`` the contact angle, ``W`` an outward edge
deviation), and never above the flat pre-cut face at ``z = 0``.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class LensletPath:
    """Lenslet rings and the tool (SI: Hz, m, m/s, rad)."""

    frequency: float
    amplitude: float
    depth: float
    speed: float
    r0: float
    rings: int
    pitch: float
    nose_radius: float
    arc_half_angle: float
    field_center: tuple[float, float]
    field_pitch: tuple[float, float]
    field_shape: tuple[int, int]  # (ny, nx)

    @property
    def n_lenslets(self) -> int:
        """Lenslets per ring N."""
        return max(1, round(2 * math.pi * self.r0 * self.frequency / self.speed))

    @property
    def omega(self) -> float:
        """Spindle angular speed, rad/s."""
        return 2 * math.pi * self.frequency / self.n_lenslets

    @property
    def t_rev(self) -> float:
        """One revolution (one ring), s."""
        return self.n_lenslets / self.frequency

    @property
    def duration(self) -> float:
        """All rings, s."""
        return self.rings * self.t_rev

    @property
    def theta0(self) -> float:
        """Tool angle at t = 0, rad."""
        n = self.n_lenslets
        return 2 * math.pi * (n // 2) / n - math.pi / (2 * n)

    @property
    def cut_fraction(self) -> float:
        """Share of each period spent in the material."""
        a, d = self.amplitude, self.depth
        return 0.5 - math.asin((a - d) / a) / math.pi

    def command(self, t: np.ndarray) -> np.ndarray:
        """Commanded tool height at ``t`` (s), m."""
        t = np.asarray(t, dtype=float)
        return (self.amplitude - self.depth) - self.amplitude * np.sin(
            2 * math.pi * self.frequency * t
        )

    def radius(self, t: np.ndarray) -> np.ndarray:
        """Tool radius at ``t`` (s), m."""
        t = np.asarray(t, dtype=float)
        ring = np.clip(np.floor(t / self.t_rev), 0, self.rings - 1)
        tau = t - ring * self.t_rev
        start = (self.n_lenslets - 0.5) / self.frequency
        u = np.clip((tau - start) * 2 * self.frequency, 0.0, 1.0)
        step = np.where(ring < self.rings - 1, 0.5 - 0.5 * np.cos(math.pi * u), 0.0)
        return self.r0 - self.pitch * (ring + step)

    def ring_radii(self) -> np.ndarray:
        """Ring radii, m."""
        return self.r0 - self.pitch * np.arange(self.rings)

    def pass_times(self, theta: np.ndarray) -> np.ndarray:
        """Times (s) the tool passes the angles ``theta``: shape (rings, n)."""
        first = np.mod(np.asarray(theta, dtype=float) - self.theta0, 2 * math.pi)
        first = first / self.omega
        return first[None, :] + self.t_rev * np.arange(self.rings)[:, None]


def load_lenslet(path: str | Path) -> LensletPath:
    """Read a lenslet toolpath TOML (``toolpaths/lenslet_*.toml``)."""
    with open(path, "rb") as fh:
        d = tomllib.load(fh)
    if d.get("kind") != "lenslet":
        raise ValueError(f"{path}: not a lenslet toolpath")
    le, tool, fld = d["lenslet"], d.get("tool", {}), d.get("field", {})
    if "arc-half-angle-deg" in tool:
        half = math.radians(float(tool["arc-half-angle-deg"]))
    else:
        half = float(tool.get("arc-half-angle", math.radians(60.0)))
    return LensletPath(
        frequency=float(le["frequency"]),
        amplitude=float(le["amplitude"]),
        depth=float(le["depth-of-cut"]),
        speed=float(le["surface-speed"]),
        r0=float(le["ring-radius"]),
        rings=int(le["ring-count"]),
        pitch=float(le["ring-pitch"]),
        nose_radius=float(tool.get("nose-radius", 0.5e-3)),
        arc_half_angle=half,
        field_center=(float(fld.get("center-x", 5e-3)),
                      float(fld.get("center-y", 0.0))),
        field_pitch=(float(fld.get("pitch-x", 0.55e-6)),
                     float(fld.get("pitch-y", 0.55e-6))),
        field_shape=(int(fld.get("ny", 480)), int(fld.get("nx", 640))),
    )


def heights(
    path: LensletPath,
    x: np.ndarray,
    y: np.ndarray,
    tool_z,
    *,
    radius=None,
    waviness=None,
    offset=None,
    top: float = 0.0,
) -> np.ndarray:
    """Machined heights at points ``(x, y)`` (m, spindle axis at the origin).

    Parameters
    ----------
    path : LensletPath
        Path and tool.
    x, y : ndarray of shape (n,)
        Point coordinates, m.
    tool_z : callable
        ``tool_z(t)``: tool-tip height (m) at times ``t`` (s), the loop's output.
    radius : callable, optional
        ``radius(t)``: nose radius (m) at ``t`` (tool wear); default constant.
    waviness : callable, optional
        ``waviness(phi)``: outward edge deviation (m) at contact angle ``phi`` (rad).
    offset : callable, optional
        ``offset(t, theta)``: tool-to-work height change outside the loop (m).
    top : float, default: 0.0
        Height of the pre-cut face, m.

    Returns
    -------
    ndarray of shape (n,)
        Heights in m.
    """
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    rp = np.hypot(x, y)
    th = np.arctan2(y, x)
    t = path.pass_times(th)  # (rings, n)
    z = np.full(rp.size, top)
    for j in range(t.shape[0]):
        tj = t[j]
        R = (np.full(tj.size, path.nose_radius) if radius is None
             else np.asarray(radius(tj), dtype=float))
        dr = rp - path.radius(tj)
        reach = np.abs(dr) <= R * math.sin(path.arc_half_angle)
        if not reach.any():
            continue
        tt, drr, RR = tj[reach], dr[reach], R[reach]
        zt = np.asarray(tool_z(tt), dtype=float)
        if offset is not None:
            zt = zt + offset(tt, th[reach])
        h = zt + RR - np.sqrt(RR * RR - drr * drr)
        if waviness is not None:
            phi = np.arcsin(drr / RR)
            h = h - waviness(phi) / np.cos(phi)
        z[reach] = np.minimum(z[reach], h)
    return z


def field_points(center, pitch, shape):
    """Pixel-centre coordinates of a field (rows = y): ``(x, y, x0, y0)``."""
    ny, nx = shape
    x0 = center[0] - 0.5 * (nx - 1) * pitch[0]
    y0 = center[1] - 0.5 * (ny - 1) * pitch[1]
    xx, yy = np.meshgrid(x0 + pitch[0] * np.arange(nx), y0 + pitch[1] * np.arange(ny))
    return xx.ravel(), yy.ravel(), x0, y0


def ring_points(radius: float, dx: float, angle_start: float = 0.0):
    """Points along a full circle of ``radius`` (m) every ``dx`` (m): ``(x, y)``."""
    n = int(2 * math.pi * radius / dx)
    th = angle_start + dx * np.arange(n) / radius
    return radius * np.cos(th), radius * np.sin(th)
