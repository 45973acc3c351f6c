"""Pointwise surface model: heights left by the tool at arbitrary points.

A map or profile recording is a set of points ``(x, y)`` on the workpiece face (m,
spindle axis at the origin). The surface at a point is the lower envelope of the
round-nose arc over the passes that reach it (the model of
:func:`servosurf.toolpath.sweep`, evaluated at the points):

``z = min(top, min_k [z_tool(t_k) + R' - sqrt(R'^2 - dr_k^2) - W(phi_k) / cos(phi_k)])``

with ``t_k`` the time the tool passes the point's angle, ``dr_k`` its radial offset
from the tool, ``R' = R + dR`` and ``W`` the nose radius change and the edge
deviation of the model's tool terms (their pointwise ``edge`` hooks, ``edge_at``
at the pass times for a tool that changes in time). The tool
height ``z_tool(t) = x1(t) + d_path(t, theta)`` is the deterministic loop
response (periodic after the start-up, extended periodically) plus the model's
outside-the-loop ``path_z`` terms; its surface terms (``surface_heights`` hooks,
e.g. elastic recovery) act on the result.

For lenslet paths each ring passes a point once; for facing the nearest five passes
are evaluated. Written for the diagnosis (no dependency on the surface simulator);
the tests compare it with :func:`servosurf.toolpath.sweep` on a lenslet field.
"""

from __future__ import annotations

import math

import numpy as np

from ._sim import CaseModel
from .effects._base import Model

__all__ = [
    "PointSet",
    "ToolTrajectory",
    "tool_trajectory",
    "surface_heights",
]


class PointSet:
    """Points of a map or profile in the workpiece frame with their passes.

    Parameters
    ----------
    case : CaseModel
        The case (its toolpath must be set).
    x, y : ndarray of shape (n,)
        Point coordinates in m.
    """

    def __init__(self, case: CaseModel, x: np.ndarray, y: np.ndarray) -> None:
        spec = case.toolpath
        path = spec.path
        self.x = np.asarray(x, dtype=float)
        self.y = np.asarray(y, dtype=float)
        self.r = np.hypot(self.x, self.y)
        self.theta = np.arctan2(self.y, self.x)
        w = path.angular_speed
        t_rev = 2 * math.pi / w
        phase = np.mod(self.theta - path.theta0, 2 * math.pi) / w
        if spec.kind == "lenslet":
            ks = np.arange(path.ring_count)
            t = phase[:, None] + ks[None, :] * t_rev
        else:
            t_r = (path.r_start - self.r) / (path.feed_per_rev * path.rev_per_s)
            jc = np.rint((t_r - phase) / t_rev)
            ks = np.arange(-2, 3)
            j = jc[:, None] + ks[None, :]
            n_rev = math.floor(path.duration / t_rev)
            j = np.clip(j, 0, n_rev)
            t = phase[:, None] + j * t_rev
        self.t = t  # (n, passes) s
        self.dr = self.r[:, None] - path.radius_at(t)  # (n, passes) m
        self.theta_pass = path.theta_at(t)  # unwrapped tool angle, rad
        self.z_cmd = path.z_at(t)
        self.half_width = spec.tool.half_width
        self.radius = spec.tool.nose_radius
        self.kind = spec.kind
        # (point, pass) pairs the edge can reach: only those are evaluated
        self.reach = np.abs(self.dr) <= self.half_width
        self.flat = np.flatnonzero(self.reach)
        self.t_r = self.t.ravel()[self.flat]
        self.dr_r = self.dr.ravel()[self.flat]
        self.theta_r = self.theta_pass.ravel()[self.flat]

    @property
    def n(self) -> int:
        """Number of points."""
        return int(self.x.size)


class ToolTrajectory:
    """Deterministic tool height from the loop simulation, extended periodically.

    Parameters
    ----------
    t : ndarray of shape (m,)
        Sample times in s (0, 1/fs, ...).
    x1 : ndarray of shape (m,)
        Tool height in m.
    period : float
        Period of the steady state in s (lenslet: 1/f; facing: one sample).
    """

    def __init__(self, t: np.ndarray, x1: np.ndarray, period: float) -> None:
        self.t = t
        self.x1 = x1
        self.period = period
        self.t_end = float(t[-1])

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Tool height in m at times ``t`` (s)."""
        t = np.asarray(t, dtype=float)
        start = self.t_end - self.period
        tt = np.where(t > self.t_end, start + np.mod(t - start, self.period), t)
        return np.interp(tt, self.t, self.x1)


def tool_trajectory(
    case: CaseModel, p: Model, *, periods: int = 12, sim: dict | None = None
) -> ToolTrajectory:
    """Simulate the cut of the case's toolpath under ``p`` (deterministic part).

    Parameters
    ----------
    case : CaseModel
        Case with a toolpath.
    p : Model
        Effects.
    periods : int, default: 12
        Lenslet periods simulated before the steady state is extended (the loop
        settles to 1e-14 m in six periods).
    sim : dict, optional
        A simulation result (``tool`` and its times from 0) to reuse.

    Returns
    -------
    ToolTrajectory
        The tool height over time.
    """
    spec = case.toolpath
    fs = case.fs
    if spec.kind == "lenslet":
        period = 1.0 / spec.path.frequency
    else:
        period = 0.01
    n = (
        int(
            round(
                min(
                    periods * period if spec.kind == "lenslet" else 0.12,
                    spec.path.duration,
                )
                * fs
            )
        )
        + 2
    )
    if sim is not None and sim["tool"].size >= n:
        x1 = sim["tool"]
    else:
        x1 = case.simulate_path(p, np.arange(n) / fs)["tool"]
    t = np.arange(x1.size) / fs
    if spec.kind != "lenslet":
        period = 2.0 / fs
    return ToolTrajectory(t, x1, period)


def surface_heights(
    case: CaseModel,
    pts: PointSet,
    p: Model,
    traj: ToolTrajectory,
    *,
    noise=None,
    top: float = 0.0,
    return_pass: bool = False,
):
    """Heights in m of the surface at the points under ``p``.

    Parameters
    ----------
    case : CaseModel
        The case.
    pts : PointSet
        Points and passes.
    p : Model
        Effects (tool, path and map terms are used here; loop terms through
        ``traj``).
    traj : ToolTrajectory
        Deterministic tool height.
    noise : callable, optional
        ``noise(t) -> m`` stochastic tool error added to the tool height.
    top : float, default: 0.0
        Pre-cut height in m.
    return_pass : bool, default: False
        Also return the index of the active pass per point (-1 when uncut),
        the lowest tool height before clipping at ``top`` (m, inf when no pass
        reaches) and the height of the runner-up pass above it (m, inf when
        only one pass reaches).

    Returns
    -------
    ndarray of shape (n,)
        Heights in m (``top`` where no pass reaches).
    """
    t = pts.t_r
    dr = pts.dr_r
    z_tool = traj(t)
    zt = z_tool
    if p.hooks("path_z"):
        # radius of the tool at each pass: the point's radius less its offset
        r_tool = np.broadcast_to(pts.r[:, None], pts.t.shape).ravel()[pts.flat] - dr
        dz = case.path_z(p, t, pts.theta_r, r_tool, z_tool)
        zt = z_tool + dz
    if noise is not None:
        zt = zt + noise(t)
    with np.errstate(invalid="ignore"):
        phi = None
        dev = None
        d_r = 0.0
        if p.hooks("tool"):
            phi = np.arcsin(np.clip(dr / pts.radius, -1.0, 1.0))
            d_r, dev = case.edge(p, phi, t)
        R = pts.radius + d_r
        arc = R - np.sqrt(np.maximum(R * R - dr * dr, 0.0))
        if dev is not None:
            arc = arc - dev / np.cos(phi)
    h = np.full(pts.t.shape, np.inf)
    h.ravel()[pts.flat] = zt + arc
    k = np.argmin(h, axis=1)
    hmin = h[np.arange(h.shape[0]), k]
    cut = hmin < top
    z = np.where(cut, hmin, top)
    z = case.surface_heights(p, z, top)
    if return_pass:
        # how far the runner-up pass is above the active one (inf: only one pass)
        if h.shape[1] > 1:
            second = np.partition(h, 1, axis=1)[:, 1]
            gap = second - hmin
        else:
            gap = np.full(hmin.shape, np.inf)
        return z, np.where(cut, k, -1), hmin, gap
    return z
