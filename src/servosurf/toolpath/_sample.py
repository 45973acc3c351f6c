"""Sampling a toolpath at the controller rate, whole or only where a field is cut."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import check_no_kwargs, check_positive
from ..errors import ConfigError
from ._paths import FacingToolpath, LensletToolpath, ToolpathSpec
from ._tool import Field, Tool

__all__ = ["SampledPath", "sample", "count_samples", "FS_DEFAULT", "field_reach"]

#: Controller update rate of the seed paper's FTS, in Hz (section 4.1).
FS_DEFAULT = 199.6e3

#: Refuse to allocate more samples than this without an explicit ``max_samples``.
MAX_SAMPLES_DEFAULT = 50_000_000


@dataclass(frozen=True, eq=False)
class SampledPath:
    """A toolpath sampled at a constant rate, possibly only in some time windows.

    Sample k of the full path is taken at ``t = k / fs``. A windowed path keeps a
    subset of those samples; two neighbours whose times differ by more than 1.5 / fs
    are not consecutive (a gap) and no crossing is interpolated between them.

    Parameters
    ----------
    t : ndarray of shape (n,)
        Sample times, in s, increasing.
    theta : ndarray of shape (n,)
        Unwrapped tool angle in the workpiece frame, in rad, strictly increasing.
    r : ndarray of shape (n,)
        Tool-tip radius, in m (>= 0).
    z : ndarray of shape (n,)
        Tool-tip height, in m (up = away from the material; the pre-cut face is at 0).
        Servo, force and vibration deviations are added here (see :meth:`add_z`).
    fs : float
        Sampling rate, in Hz.
    """

    t: np.ndarray
    theta: np.ndarray
    r: np.ndarray
    z: np.ndarray
    fs: float

    def __post_init__(self) -> None:
        n = None
        for name in ("t", "theta", "r", "z"):
            a = np.ascontiguousarray(getattr(self, name), dtype=np.float64)
            if a.ndim != 1:
                raise ConfigError(
                    f"SampledPath.{name} must be 1-dimensional, got shape {a.shape}")
            if n is None:
                n = a.size
            elif a.size != n:
                raise ConfigError(
                    f"SampledPath arrays must have one length, got {name} of {a.size} "
                    f"and t of {n}"
                )
            object.__setattr__(self, name, a)
        object.__setattr__(self, "fs", check_positive(self.fs, name="SampledPath.fs"))

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t.size)

    @property
    def index(self) -> np.ndarray:
        """Global sample numbers ``round(t * fs)``, int64 of shape (n,)."""
        return np.rint(self.t * self.fs).astype(np.int64)

    def gaps(self) -> np.ndarray:
        """True at i when samples i and i + 1 are not consecutive; shape (n,).

        Returns
        -------
        ndarray of bool, shape (n,)
            The last entry is always False.
        """
        g = np.zeros(self.n, dtype=np.bool_)
        if self.n > 1:
            g[:-1] = np.diff(self.t) > 1.5 / self.fs
        return g

    def with_z(self, z: np.ndarray) -> SampledPath:
        """Return a copy with the tool height replaced.

        Parameters
        ----------
        z : ndarray of shape (n,)
            New tool-tip height, in m.

        Returns
        -------
        SampledPath
            A new path sharing t, theta and r.
        """
        return SampledPath(self.t, self.theta, self.r, z, self.fs)

    def add_z(self, dz: np.ndarray) -> SampledPath:
        """Return a copy with a height deviation added (aligned with ``t``).

        Parameters
        ----------
        dz : ndarray of shape (n,)
            Deviation of the tool tip in m (servo error, force deflection,
            vibration), positive away from the material.

        Returns
        -------
        SampledPath
            The path with ``z + dz``.
        """
        dz = np.asarray(dz, dtype=np.float64)
        if dz.shape != self.z.shape:
            raise ConfigError(
                f"deviation must have shape {self.z.shape}, got {dz.shape}")
        return self.with_z(self.z + dz)

    def select(self, mask: np.ndarray) -> SampledPath:
        """Return the samples where ``mask`` is True (creates gaps where it skips).

        Parameters
        ----------
        mask : ndarray of bool, shape (n,)
            Samples to keep.

        Returns
        -------
        SampledPath
            The selected samples.
        """
        m = np.asarray(mask, dtype=bool)
        return SampledPath(self.t[m], self.theta[m], self.r[m], self.z[m], self.fs)

    def slope_along_cut(self) -> np.ndarray:
        """Slope of the tool height along the cutting direction, per interval.

        Returns
        -------
        ndarray of shape (n - 1,)
            ``(z[i+1] - z[i]) / (r_mid * (theta[i+1] - theta[i]))``, dimensionless;
            NaN across gaps and where the tool is on the axis.
        """
        if self.n < 2:
            return np.zeros(0)
        rm = 0.5 * (self.r[1:] + self.r[:-1])
        ds = rm * np.diff(self.theta)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.diff(self.z) / ds
        s[self.gaps()[:-1] | ~(ds > 0)] = np.nan
        return s


def field_reach(tool: Tool, depth: float | None = None, *,
                depth_margin: float = 1e-6) -> float:
    """Radial reach of the edge that matters for a field, in m.

    Parameters
    ----------
    tool : Tool
        The tool.
    depth : float, optional
        Deepest tool-tip position below the highest pre-cut height, in m. None gives
        the full arc half-width R sin(phi_max) (always exact).
    depth_margin : float, default: 1e-6
        Extra depth allowed for deviations added after sampling, in m.

    Returns
    -------
    float
        ``sqrt(2 R D - D**2)`` with D = depth + depth_margin, capped at the arc
        half-width; passes farther than this from a point cannot cut below the
        pre-cut surface there.
    """
    if depth is None:
        return tool.half_width
    return tool.chord_half_width(float(depth) + float(depth_margin))


def _ranges_to_index(starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """Concatenate ``arange(start, stop)`` for each pair (stop exclusive), int64."""
    lengths = np.maximum(stops - starts, 0)
    total = int(lengths.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    keep = lengths > 0
    starts, lengths = starts[keep], lengths[keep]
    before = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    offsets = np.repeat(starts - before, lengths)
    return np.arange(total, dtype=np.int64) + offsets


def _resolve(spec, tool):
    from ._design import DesignToolpath
    from ._trajectory import BlockPath

    if isinstance(spec, ToolpathSpec):
        return spec.path, (spec.tool if tool is None else tool)
    if isinstance(spec, FacingToolpath | LensletToolpath | BlockPath | DesignToolpath):
        return spec, tool
    raise ConfigError(
        f"spec must be a ToolpathSpec, FacingToolpath, LensletToolpath, BlockPath or "
        f"DesignToolpath, got {type(spec).__name__}"
    )


def _intersect(starts, stops, lo, hi):
    """Intersection of two sorted lists of disjoint half-open index ranges."""
    out_s, out_e = [], []
    i = j = 0
    while i < starts.size and j < lo.size:
        a = max(starts[i], lo[j])
        b = min(stops[i], hi[j])
        if b > a:
            out_s.append(a)
            out_e.append(b)
        if stops[i] < hi[j]:
            i += 1
        else:
            j += 1
    return (np.asarray(out_s, dtype=np.int64), np.asarray(out_e, dtype=np.int64))


def _merge(starts, stops):
    """Sorted, disjoint union of half-open index ranges."""
    if starts.size < 2:
        return starts, stops
    order = np.argsort(starts, kind="stable")
    starts, stops = starts[order], stops[order]
    out_s, out_e = [int(starts[0])], [int(stops[0])]
    for a, b in zip(starts[1:].tolist(), stops[1:].tolist(), strict=True):
        if a <= out_e[-1]:
            out_e[-1] = max(out_e[-1], b)
        else:
            out_s.append(a)
            out_e.append(b)
    return np.asarray(out_s, dtype=np.int64), np.asarray(out_e, dtype=np.int64)


def _cutting_ranges(path, fs, starts, stops):
    """Keep only the samples inside the path's cutting spans (paths with links)."""
    starts, stops = _merge(starts, stops)
    spans = path.cutting_spans()
    lo = np.ceil(spans[:, 0] * fs - 1e-9).astype(np.int64)
    hi = np.floor(spans[:, 1] * fs + 1e-9).astype(np.int64) + 1
    return _intersect(starts, stops, lo, hi)


def _window_ranges_varying(path, fs, i0, i1, centre, lo, hi):
    """Revolution windows of a path whose angular speed varies (``time_at_theta``)."""
    two_pi = 2.0 * math.pi
    a_lo = centre + lo
    a_hi = centre + hi
    th_lo, th_hi = (float(v) for v in path.theta_at(np.array([i0 / fs, i1 / fs])))
    k0 = math.floor((th_lo - a_hi) / two_pi)
    k1 = math.ceil((th_hi - a_lo) / two_pi)
    ks = np.arange(k0, k1 + 1, dtype=np.float64)
    starts = np.floor(path.time_at_theta(a_lo + two_pi * ks) * fs).astype(np.int64)
    stops = np.ceil(path.time_at_theta(a_hi + two_pi * ks) * fs).astype(np.int64)
    starts = np.clip(starts - 2, i0, i1 + 1)
    stops = np.clip(stops + 3, i0, i1 + 1)
    keep = stops > starts
    return starts[keep], stops[keep]


def _index_ranges(path, fs, t_window, field, tool, reach):
    """Half-open sample-number ranges ``[starts[k], stops[k])`` to sample."""
    T = path.duration
    n_total = int(math.floor(T * fs * (1 + 1e-15))) + 1
    t0, t1 = 0.0, T
    if t_window is not None:
        a, b = (float(v) for v in t_window)
        if not b >= a:
            raise ConfigError(f"t_window must be (t0, t1) with t1 >= t0 in s, got "
                              f"{t_window!r}")
        t0, t1 = max(t0, a), min(t1, b)
    window = None
    if field is not None:
        if reach is None:
            if tool is None:
                raise ConfigError("sample(field=...) needs a tool (or a reach in m)")
            reach = tool.half_width
        reach = float(reach)
        rmin, rmax = field.radial_range()
        span = path.time_span_for_radius(rmin - reach, rmax + reach)
        if span is None:
            t1 = t0 - 1.0  # nothing
        else:
            t0, t1 = max(t0, span[0]), min(t1, span[1])
        window = field.angular_window(reach)
    empty = np.zeros(0, dtype=np.int64)
    if t1 < t0:
        return empty, empty
    i0 = max(0, math.floor(t0 * fs) - 1)
    i1 = min(n_total - 1, math.ceil(t1 * fs) + 1)
    links = hasattr(path, "cutting_spans")  # NC paths: links are not sampled
    if window is None:
        starts = np.array([i0], dtype=np.int64)
        stops = np.array([i1 + 1], dtype=np.int64)
        return _cutting_ranges(path, fs, starts, stops) if links else (starts, stops)
    centre, lo, hi = window
    if hasattr(path, "time_at_theta"):  # angular speed not constant
        starts, stops = _window_ranges_varying(path, fs, i0, i1, centre, lo, hi)
        return _cutting_ranges(path, fs, starts, stops) if links else (starts, stops)
    w = path.angular_speed
    margin = 2.0 * w / fs
    a_lo = centre + lo - margin
    a_hi = centre + hi + margin
    th_lo = path.theta0 + w * (i0 / fs)
    th_hi = path.theta0 + w * (i1 / fs)
    two_pi = 2.0 * math.pi
    k0 = math.floor((th_lo - a_hi) / two_pi)
    k1 = math.ceil((th_hi - a_lo) / two_pi)
    ks = np.arange(k0, k1 + 1, dtype=np.float64)
    starts = np.floor((a_lo + two_pi * ks - path.theta0) / w * fs).astype(np.int64)
    stops = np.ceil((a_hi + two_pi * ks - path.theta0) / w * fs).astype(np.int64)
    starts = np.clip(starts - 1, i0, i1 + 1)
    stops = np.clip(stops + 2, i0, i1 + 1)
    keep = stops > starts
    return starts[keep], stops[keep]


def count_samples(spec: ToolpathSpec | FacingToolpath | LensletToolpath | Any, *,
                  fs: float = FS_DEFAULT, t_window: tuple[float, float] | None = None,
                  field: Field | None = None, tool: Tool | None = None,
                  reach: float | None = None) -> int:
    """Number of samples :func:`sample` would return (nothing is allocated).

    Parameters
    ----------
    spec, fs, t_window, field, tool, reach
        As for :func:`sample`.

    Returns
    -------
    int
        Sample count (an upper bound when windows overlap).
    """
    path, tool = _resolve(spec, tool)
    fs = check_positive(fs, name="fs")
    starts, stops = _index_ranges(path, fs, t_window, field, tool, reach)
    return int((stops - starts).sum())


def sample(spec: ToolpathSpec | FacingToolpath | LensletToolpath | Any, *,
           fs: float = FS_DEFAULT, t_window: tuple[float, float] | None = None,
           field: Field | None = None, tool: Tool | None = None,
           reach: float | None = None, max_samples: int = MAX_SAMPLES_DEFAULT,
           **kwargs) -> SampledPath:
    """Sample a toolpath at the controller rate.

    Parameters
    ----------
    spec : ToolpathSpec, FacingToolpath, LensletToolpath or BlockPath
        What to sample. A :class:`~servosurf.toolpath.BlockPath` (NC program) is
        sampled only inside its cutting runs (links are left out) and its field
        windows follow its varying angular speed.
    fs : float, default: 199.6e3
        Sampling rate, in Hz (the seed paper's controller rate).
    t_window : tuple of float, optional
        Keep only samples with ``t0 <= t <= t1`` (s), plus one on each side.
    field : Field, optional
        Keep only the samples that can cut this field: the revolutions whose radius
        is within ``reach`` of the field and, in each, the angular window the field
        subtends (two samples of margin on each side). The spindle passes the window
        once per revolution, so a whole-part path stays small.
    tool : Tool, optional
        Tool for the default reach (taken from ``spec`` when it is a ToolpathSpec).
    reach : float, optional
        Radial reach in m; default the arc half-width R sin(phi_max), which keeps
        every sample that can touch the field. :func:`field_reach` gives a tighter,
        depth-based reach.
    max_samples : int, default: 50_000_000
        Refuse larger results (memory guard: 4 arrays of 8 bytes per sample).

    Returns
    -------
    SampledPath
        Samples at ``t = k / fs`` (k integer), possibly with gaps.

    Raises
    ------
    ConfigError
        On bad arguments or when more than ``max_samples`` samples would result.
    TypeError
        On unknown keyword arguments.

    Examples
    --------
    >>> import servosurf.toolpath as tp
    >>> spec = tp.ToolpathSpec(kind="facing", path=tp.FacingToolpath())
    >>> path = tp.sample(spec, field=spec.field)  # only what the field needs
    >>> path.n < 0.02 * tp.count_samples(spec)
    True
    """
    check_no_kwargs(kwargs, name="sample")
    path, tool = _resolve(spec, tool)
    fs = check_positive(fs, name="fs")
    starts, stops = _index_ranges(path, fs, t_window, field, tool, reach)
    n = int((stops - starts).sum())
    if n > max_samples:
        raise ConfigError(
            f"sampling would give {n} samples, more than {max_samples}: use a "
            "smaller field (field.nx, field.ny) or a shorter toolpath (Python: pass "
            "field= or t_window=, or raise max_samples)"
        )
    if starts.size > 1 and np.any(starts[1:] < stops[:-1]):  # overlapping windows
        idx = np.unique(_ranges_to_index(starts, stops))
        starts, stops = idx, idx + 1
    n = int((stops - starts).sum())
    t, theta, r, z = (np.empty(n) for _ in range(4))
    path._fill(np.ascontiguousarray(starts, dtype=np.int64),
               np.ascontiguousarray(stops, dtype=np.int64), float(fs), t, theta, r, z)
    return SampledPath(t=t, theta=theta, r=r, z=z, fs=fs)
