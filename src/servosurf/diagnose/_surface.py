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
e.g. elastic recovery) act on the result. With a minimum chip thickness (a
``cutting_rules`` hook) the passes are applied in time order instead, each cutting
only where it meets more than ``h_min`` (:func:`ordered_heights`, the rule of the
simulator's ordered sweep).

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
    "SPIRAL_KINDS",
    "spiral_pass_times",
    "feed_per_rev",
    "PointSet",
    "ToolTrajectory",
    "tool_trajectory",
    "trajectory_samples",
    "ordered_heights",
    "surface_heights",
]


#: Toolpath kinds cut by one spiral whose passes are found from the path itself
#: (design surfaces and NC programs): their deviation record is not periodic.
SPIRAL_KINDS = ("surface", "nc")

#: Most passes evaluated on each side of the one whose tip radius is a point's.
MAX_SIDE_PASSES = 40


#: spiral geometry of the last few paths, by identity: (path, tool, result)
_GEOMETRY: list = []


def _spiral_geometry(spec) -> tuple[np.ndarray, np.ndarray, int]:
    """Radius table ``(t, r)`` of a spiral path and the passes per side to check.

    The passes a point can be cut by lie within the tool's contact offset
    ``R sin(slope)`` (the radial slope of the commanded path between revolutions)
    plus one feed of the pass whose tip radius is the point's.
    """
    for path, tool, out in _GEOMETRY:
        if path is spec.path and tool is spec.tool:
            return out
    out = _spiral_geometry_of(spec)
    _GEOMETRY.insert(0, (spec.path, spec.tool, out))
    del _GEOMETRY[4:]
    return out


def _spiral_geometry_of(spec) -> tuple[np.ndarray, np.ndarray, int]:
    path = spec.path
    w = path.angular_speed
    t_rev = 2 * math.pi / w
    dur = float(path.duration)
    tg = np.linspace(0.0, dur, max(int(math.ceil(dur / t_rev * 256)), 2) + 1)
    rg = np.asarray(path.radius_at(tg), dtype=float)
    ta = tg[tg + t_rev <= dur]
    if ta.size < 2:
        return tg, rg, 2
    dr = np.asarray(path.radius_at(ta), float) - np.asarray(
        path.radius_at(ta + t_rev), float
    )
    dz = np.asarray(path.z_at(ta + t_rev), float) - np.asarray(path.z_at(ta), float)
    feed = np.abs(dr)
    moving = feed > 1e-12
    if not moving.any():
        return tg, rg, 2
    f_min = float(np.percentile(feed[moving], 1.0))
    f_max = float(feed[moving].max())
    slope = float(np.max(np.abs(dz[moving]) / feed[moving]))
    offset = spec.tool.nose_radius * slope / math.sqrt(1.0 + slope * slope)
    k = int(math.ceil((offset + f_max) / max(f_min, 1e-12))) + 1
    return tg, rg, min(max(k, 2), MAX_SIDE_PASSES)


def feed_per_rev(spec) -> float:
    """Radial feed per revolution in m: the path's, or for a spiral path whose feed
    varies (:data:`SPIRAL_KINDS`) the median over its revolutions."""
    f = getattr(spec.path, "feed_per_rev", None)
    if f is not None and spec.kind not in SPIRAL_KINDS:
        return float(f)
    path = spec.path
    t_rev = 2 * math.pi / path.angular_speed
    tg = np.linspace(0.0, float(path.duration), 4097)
    ta = tg[tg + t_rev <= path.duration]
    if ta.size == 0:
        return float(f) if f is not None else 0.0
    dr = np.abs(
        np.asarray(path.radius_at(ta), float)
        - np.asarray(path.radius_at(ta + t_rev), float)
    )
    return float(np.median(dr))


def spiral_pass_times(spec, r: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Times (s) the tool of a spiral path passes the angles of points.

    Parameters
    ----------
    spec : ToolpathSpec
        A design-surface or NC toolpath (kind in :data:`SPIRAL_KINDS`) whose tip
        radius is monotonic in time.
    r, theta : ndarray of shape (n,)
        Point radii in m and angles in rad, in the path's (kernel) frame.

    Returns
    -------
    ndarray of shape (n, passes)
        Pass times in s around the revolution whose tip radius is the point's
        (NaN: a pass before the path's start or after its end).
    """
    from ..errors import ConfigError

    path = spec.path
    tg, rg, side = _spiral_geometry(spec)
    d = np.diff(rg)
    if np.all(d <= 1e-15):
        t_r = np.interp(-r, -rg, tg)
    elif np.all(d >= -1e-15):
        t_r = np.interp(r, rg, tg)
    else:
        raise ConfigError(
            f"toolpath {spec.kind!r}: its tip radius goes both in and out; the "
            "diagnosis models maps of a spiral that moves one way"
        )
    two_pi = 2 * math.pi
    th0 = float(path.theta0)
    frac = np.mod(theta - th0, two_pi)
    ks = np.arange(-side, side + 1)
    dur = float(path.duration)
    if hasattr(path, "time_at_theta"):  # NC blocks: angle to time along the path
        th_r = np.asarray(path.theta_at(t_r), dtype=float)
        jc = np.rint((th_r - th0 - frac) / two_pi)
        j = jc[:, None] + ks[None, :]
        th_u = th0 + frac[:, None] + two_pi * j
        t = path.time_at_theta(th_u)
        inside = (th_u >= path.theta[0]) & (th_u <= path.theta[-1])
    else:
        w = path.angular_speed
        t_rev = two_pi / w
        phase = frac / w
        jc = np.rint((t_r - phase) / t_rev)
        t = phase[:, None] + (jc[:, None] + ks[None, :]) * t_rev
        inside = (t >= 0.0) & (t <= dur)
    return np.where(inside, t, np.nan)


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
        elif spec.kind in SPIRAL_KINDS:
            # the kernel's frame (an NC path may run mirrored in y)
            th = -self.theta if getattr(path, "mirrored", False) else self.theta
            t = spiral_pass_times(spec, self.r, th)
        else:
            t_r = (path.r_start - self.r) / (path.feed_per_rev * path.rev_per_s)
            jc = np.rint((t_r - phase) / t_rev)
            ks = np.arange(-2, 3)
            j = jc[:, None] + ks[None, :]
            n_rev = math.floor(path.duration / t_rev)
            j = np.clip(j, 0, n_rev)
            t = phase[:, None] + j * t_rev
        valid = np.isfinite(t)
        t = np.where(valid, t, 0.0)
        self.t = t  # (n, passes) s
        # (n, passes) m; inf: a pass outside the path's time
        self.dr = np.where(valid, self.r[:, None] - path.radius_at(t), np.inf)
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
    period : float or None
        Period of the steady state in s (lenslet: 1/f; facing: one sample); None:
        the record spans every time asked for (spiral paths), no extension.
    """

    def __init__(self, t: np.ndarray, x1: np.ndarray, period: float) -> None:
        self.t = t
        self.x1 = x1
        self.period = period
        self.t_end = float(t[-1])

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Tool height in m at times ``t`` (s)."""
        t = np.asarray(t, dtype=float)
        if self.period is None:  # a record over the whole span: no extension
            return np.interp(t, self.t, self.x1)
        start = self.t_end - self.period
        tt = np.where(t > self.t_end, start + np.mod(t - start, self.period), t)
        return np.interp(tt, self.t, self.x1)


def trajectory_samples(
    case: CaseModel, *, periods: int = 12, radii: tuple[float, float] | None = None
) -> tuple[int, int, float | None]:
    """The loop record the surface model is built from.

    Lenslet and facing paths are periodic after the start-up: ``periods`` lenslet
    periods (0.12 s of facing) from t = 0, extended periodically. A spiral path
    (:data:`SPIRAL_KINDS`) is not: the record is simulate's own deviation record
    (:func:`servosurf.simulation.deviation_samples`), widened to the radii of the
    points (``radii``, m) when they reach outside the toolpath's field.

    Returns
    -------
    tuple
        ``(k0, n, period)``: first controller sample (loop at rest there), sample
        count and the period in s of the extension (None: none).
    """
    spec = case.toolpath
    fs = case.fs
    if spec.kind in SPIRAL_KINDS:
        from ..simulation import deviation_samples

        k0, n = deviation_samples(spec, spec.tool, fs, radii=radii)
        return k0, n, None
    if spec.kind == "lenslet":
        span = periods / spec.path.frequency
        period = 1.0 / spec.path.frequency
    else:
        span = 0.12
        period = 2.0 / fs
    n = int(round(min(span, spec.path.duration) * fs)) + 2
    return 0, n, period


def tool_trajectory(
    case: CaseModel,
    p: Model,
    *,
    periods: int = 12,
    sim: dict | None = None,
    radii: tuple[float, float] | None = None,
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
        A simulation result (``tool`` over the samples of
        :func:`trajectory_samples`) to reuse.
    radii : tuple of float, optional
        Radial range of the points in m (spiral paths, see
        :func:`trajectory_samples`).

    Returns
    -------
    ToolTrajectory
        The tool height over time.
    """
    k0, n, period = trajectory_samples(case, periods=periods, radii=radii)
    fs = case.fs
    if sim is not None and sim["tool"].size >= n:
        x1 = sim["tool"][:n]
    else:
        x1 = case.simulate_path(p, (k0 + np.arange(n)) / fs)["tool"]
    t = (k0 + np.arange(x1.size)) / fs
    return ToolTrajectory(t, x1, period)


def ordered_heights(h: np.ndarray, t: np.ndarray, top: float,
                    h_min: float) -> tuple[np.ndarray, np.ndarray]:
    """Heights left by passes in time order with a minimum chip thickness.

    A point starts at the pre-cut height ``top``; each pass, in the order of its
    time, removes material only where it meets more than ``h_min`` of it (its edge
    lies more than ``h_min`` below the current height); a thinner sliver is
    ploughed and stays (the rule of :class:`servosurf.toolpath.CuttingRules`).
    With ``h_min = 0`` this is the lower envelope capped at ``top``.

    Parameters
    ----------
    h : ndarray of shape (n, passes)
        Edge height of each pass at each point in m (inf: the pass does not
        reach the point).
    t : ndarray of shape (n, passes)
        Time of each pass in s.
    top : float
        Pre-cut height in m.
    h_min : float
        Minimum chip thickness in m (>= 0).

    Returns
    -------
    z : ndarray of shape (n,)
        Heights in m.
    k : ndarray of shape (n,)
        Index of the pass that cut last (-1: no pass cut the point).
    """
    n = h.shape[0]
    tt = np.where(np.isfinite(h), t, np.inf)
    order = np.argsort(tt, axis=1, kind="stable")
    rows = np.arange(n)
    z = np.full(n, float(top))
    k = np.full(n, -1, dtype=np.int64)
    for j in range(h.shape[1]):
        col = order[:, j]
        he = h[rows, col]
        cuts = z - he > h_min
        z = np.where(cuts, he, z)
        k = np.where(cuts, col, k)
    return z, k


def surface_heights(
    case: CaseModel,
    pts: PointSet,
    p: Model,
    traj: ToolTrajectory,
    *,
    noise=None,
    top: float | None = None,
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
    top : float, optional
        Pre-cut height in m (default: the case's, :attr:`CaseModel.top`).
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
    if top is None:
        top = case.top
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
    h_min = case.min_chip_thickness(p)  # 0 without a cutting_rules hook
    if h_min > 0.0:
        z, k = ordered_heights(h, pts.t, top, h_min)
        cut = k >= 0
        hmin = np.min(h, axis=1)
    else:
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
