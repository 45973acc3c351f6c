"""Machined surface: the lower envelope of the tool arc swept along a sampled path."""

from __future__ import annotations

import math
import warnings
from contextlib import contextmanager
from typing import Literal

import numpy as np

from .._validation import check_no_kwargs
from ..errors import ConfigError
from ..metrology._surface import Surface
from ._sample import SampledPath
from ._tool import Field, Tool, ToolpathWarning

__all__ = ["sweep", "check_clearance", "prepare_path", "PreparedPath"]

_METHODS = ("pruned", "exhaustive")


def check_clearance(path: SampledPath, tool: Tool, *, stacklevel: int = 2) -> float:
    """Warn when the path's slope along the cut exceeds the tool's clearance angle.

    Parameters
    ----------
    path : SampledPath
        The sampled path (with any deviation already added to ``z``).
    tool : Tool
        The tool; its ``clearance_angle`` (rad) is the limit.
    stacklevel : int, default: 2
        Passed to :func:`warnings.warn`.

    Returns
    -------
    float
        The largest slope angle along the cut, in rad (0 for an empty path).

    Warns
    -----
    ToolpathWarning
        When ``atan(max |dz / ds|) > clearance_angle``: the flank rubs the surface.

    Notes
    -----
    Intervals within one nose radius of the spindle axis are skipped: there the
    cutting speed vanishes and any height change exceeds every clearance angle.
    """
    if path.n < 2:
        return 0.0
    slope, k = _max_slope(path, tool.nose_radius)
    return _warn_clearance(path, tool, slope, k, stacklevel + 1)


def _n_chunks(n: int) -> int:
    import numba

    return max(1, min(n // 4096, 4 * numba.get_num_threads()))


def _scan_slope(path: SampledPath, r_skip: float) -> tuple[bool, float, int]:
    """(faulty, largest slope along the cut, its first sample): one parallel pass."""
    from ..kernels._prep import _scan_slope

    nc = _n_chunks(path.n)
    bad, slope, k = _scan_slope(path.t, path.theta, path.r, path.z, path.fs, r_skip,
                                nc, np.empty((nc, 2)))
    return bool(bad), float(slope), int(k)


def _max_slope(path: SampledPath, r_skip: float) -> tuple[float, int]:
    return _scan_slope(path, r_skip)[1:]


def _warn_clearance(path: SampledPath, tool: Tool, slope: float, k: int,
                    stacklevel: int) -> float:
    """Warn when ``atan(slope)`` exceeds the clearance; return that angle (rad).

    ``k`` is the first sample of the steepest interval of ``path`` (-1: none).
    """
    if k < 0:
        return 0.0
    rm = 0.5 * (path.r[k] + path.r[k + 1])
    angle = math.atan(slope)
    if angle > tool.clearance_angle:
        warnings.warn(
            ToolpathWarning(
                f"toolpath slope along the cutting direction reaches "
                f"{math.degrees(angle):.2f} degrees (at t = {path.t[k]:.6g} s, r = "
                f"{rm:.6g} m), above the tool clearance angle of "
                f"{math.degrees(tool.clearance_angle):.2f} degrees: the flank would "
                "rub the cut surface. Lower the surface speed or the amplitude, or use "
                "a tool with more clearance."
            ),
            stacklevel=stacklevel,
        )
    return angle


class PreparedPath:
    """Kernel inputs derived from a sampled path for one field (internal).

    Parameters
    ----------
    path : SampledPath
        The path (after cropping).
    theta_ref : float
        Start angle of bucket 0, in rad.
    """

    def __init__(self, path: SampledPath, theta_ref: float) -> None:
        from ..kernels._sweep import N_STAT, RMID, _bucket_stats

        self.path = path
        self.theta = path.theta
        self.r = path.r
        self.z = path.z
        from ..kernels._prep import _interleave

        # interleaved copy for the crossing evaluations: one cache line per sample pair
        self.pts = np.empty((path.n, 4))
        self.gap = np.empty(path.n, dtype=np.bool_)
        _interleave(path.t, path.theta, path.r, path.z, path.fs, self.pts, self.gap)
        self.theta_ref = float(theta_ref)
        nb = int(math.floor((self.theta[-1] - self.theta_ref) / (2 * math.pi))) + 1
        self.bidx = np.zeros((nb, 4), dtype=np.int64)
        self.bstat = np.zeros((nb, N_STAT), dtype=np.float64)
        _bucket_stats(self.theta, self.r, self.z, self.gap, self.theta_ref, self.bidx,
                      self.bstat)
        self.rmid = np.ascontiguousarray(self.bstat[:, RMID])
        d = np.diff(self.rmid)
        if np.all(d <= 0):
            self.direction = -1
        elif np.all(d >= 0):
            self.direction = 1
        else:
            self.direction = 0
        self.rmin = float(self.r.min())

    @property
    def n_buckets(self) -> int:
        """Number of revolution buckets."""
        return int(self.bidx.shape[0])


def _field_rect(field: Field, rows: tuple[int, int], cols: tuple[int, int]):
    xmin = field.x0 + cols[0] * field.pitch_x
    xmax = field.x0 + (cols[1] - 1) * field.pitch_x
    ymin = field.y0 + rows[0] * field.pitch_y
    ymax = field.y0 + (rows[1] - 1) * field.pitch_y
    return xmin, xmax, ymin, ymax


def _rect_polar(xmin, xmax, ymin, ymax, reach):
    """Radial range and angular window (or None = all angles) of a rectangle."""
    cx = min(max(0.0, xmin), xmax)
    cy = min(max(0.0, ymin), ymax)
    rmin = math.hypot(cx, cy)
    rmax = max(math.hypot(x, y) for x in (xmin, xmax) for y in (ymin, ymax))
    if rmin <= reach or rmin == 0.0:
        return rmin, rmax, None
    centre = math.atan2(0.5 * (ymin + ymax), 0.5 * (xmin + xmax))
    rel = []
    for x in (xmin, xmax):
        for y in (ymin, ymax):
            a = math.atan2(y, x) - centre
            rel.append((a + math.pi) % (2 * math.pi) - math.pi)
    return rmin, rmax, (centre, min(min(rel), 0.0), max(max(rel), 0.0))


#: Paths longer than this (samples) are first crop-tested on one interval in
#: ``_CROP_STRIDE``, spread over the path (``kernels._prep._hit_fraction``).
_CROP_SAMPLE_MIN = 65536
_CROP_STRIDE = 64


def _crop(path: SampledPath, rmin: float, rmax: float, window, reach: float):
    """Keep the intervals that can cut the rectangle (both of their samples).

    The crop changes speed, not results: a path of which more than 80 % would be
    kept is used whole. For long paths a test of one interval in 64, spread over
    the path on a golden-ratio sequence (no aliasing with the samples per
    revolution), decides that first: above 90 % hitting, the full pass is skipped,
    since a path sampled for the field, as ``simulate`` and ``face`` sample it,
    keeps nearly all.
    """
    from ..kernels._prep import _crop_mask_chunked, _hit_fraction

    if window is None:
        centre, lo, hi = 0.0, -math.pi, math.pi
    else:
        centre, lo, hi = window
    # allowances for rounding: 1 nm radially, 1 nrad in angle
    args = (rmin, rmax, reach + 1e-9, window is not None, centre, lo - 1e-9,
            hi + 1e-9)
    if path.n > _CROP_SAMPLE_MIN and _hit_fraction(
            path.theta, path.r, path.n // _CROP_STRIDE, *args) > 0.9:
        return path
    keep = np.empty(path.n, dtype=np.bool_)
    count = _crop_mask_chunked(path.theta, path.r, *args, _n_chunks(path.n), keep)
    if count > 0.8 * path.n:
        return path
    return path.select(keep)


def _raise_path_error(path: SampledPath, code: int) -> None:
    if code == 1:
        raise ConfigError(
            "path.t, path.theta, path.r and path.z must have finite values")
    if code == 2:
        raise ConfigError(
            "path.theta must be strictly increasing (unwrapped angle, rad)")
    if code == 3:
        raise ConfigError(f"path.r must be >= 0 m, got min {path.r.min()!r}")


def prepare_path(path: SampledPath, tool: Tool, field: Field, *,
                 rows: tuple[int, int] | None = None,
                 cols: tuple[int, int] | None = None,
                 crop: bool = True, check: bool = False,
                 stacklevel: int = 2) -> PreparedPath | None:
    """Crop a sampled path to what can cut a (sub-)field and build kernel inputs.

    Parameters
    ----------
    path : SampledPath
        The sampled path.
    tool : Tool
        The tool.
    field : Field
        The grid.
    rows, cols : tuple of int, optional
        Half-open row and column ranges of the part of ``field`` to compute.
    crop : bool, default: True
        Drop the samples that cannot touch the (sub-)field first. Skip it when the
        path was sampled for this field already (it changes speed, not results).
    check : bool, default: False
        Validate the path (finite, strictly increasing angle, r >= 0) and warn when
        the slope along the cut of the cropped path exceeds the clearance angle
        (:func:`check_clearance`). Every pass runs in parallel chunks.
    stacklevel : int, default: 2
        Passed to :func:`warnings.warn` for the clearance warning.

    Returns
    -------
    PreparedPath or None
        None when fewer than two samples can cut the field.

    Raises
    ------
    ConfigError
        With ``check``: on a non-finite or non-monotonic path or a negative radius.
    """
    from ..kernels._notice import compile_notice
    from ..kernels._sweep import _sweep_pruned

    compile_notice(_sweep_pruned, "surface kernel")  # once, before a slow first call
    rows = (0, field.ny) if rows is None else rows
    cols = (0, field.nx) if cols is None else cols
    reach = tool.half_width
    rect = _field_rect(field, rows, cols)
    rmin, rmax, window = _rect_polar(*rect, reach)
    if check:
        if not isinstance(path, SampledPath):
            raise ConfigError(
                f"path must be a SampledPath, got {type(path).__name__}")
        # validity and clearance slope in one pass; the slope is taken again over
        # the cropped path when the crop removes samples
        bad, slope, k = _scan_slope(path, tool.nose_radius)
        if bad:
            from ..kernels._prep import _check_path

            _raise_path_error(
                path, int(_check_path(path.t, path.theta, path.r, path.z)))
    if path.n < 2:
        return None
    p = _crop(path, rmin, rmax, window, reach) if crop else path
    if p.n < 2:
        return None
    if check:
        if p is not path:
            slope, k = _max_slope(p, tool.nose_radius)
        _warn_clearance(p, tool, slope, k, stacklevel + 1)
    centre = 0.0 if window is None else window[0]
    # Bucket boundaries half a turn from the field centre, at or before theta[0].
    ref = centre - math.pi
    theta_ref = p.theta[0] - ((p.theta[0] - ref) % (2 * math.pi))
    if not (theta_ref <= p.theta[0]):  # rounding
        theta_ref = p.theta[0]
    return PreparedPath(p, theta_ref)


def _initial_array(initial, shape, rows, cols, field):
    """(out, fill): the output array and, for a uniform pre-cut height, that height
    in m (``out`` is then left unfilled: the kernel writes it row by row)."""
    if initial is None:
        return np.empty(shape), 0.0
    if isinstance(initial, Surface):
        initial = initial.z
    if np.isscalar(initial):
        v = float(initial)
        if math.isnan(v) or v == -math.inf:
            raise ConfigError(f"initial must be a height in m or +inf, got {v!r}")
        return np.empty(shape), v
    a = np.asarray(initial, dtype=np.float64)
    if a.shape == field.shape and shape != field.shape:
        a = a[rows[0]:rows[1], cols[0]:cols[1]]
    if a.shape != shape:
        raise ConfigError(
            f"initial must have the field's shape {shape} (rows, cols), got {a.shape}"
        )
    if np.any(a == -np.inf):
        raise ConfigError("initial must not contain -inf")
    return np.array(a, dtype=np.float64, order="C", copy=True), None


@contextmanager
def _threads(n_threads: int | None):
    if n_threads is None:
        yield
        return
    import numba

    n = int(n_threads)
    if not 1 <= n <= numba.config.NUMBA_NUM_THREADS:
        raise ConfigError(
            f"n_threads must be in [1, {numba.config.NUMBA_NUM_THREADS}], "
            f"got {n_threads!r}"
        )
    old = numba.get_num_threads()
    numba.set_num_threads(n)
    try:
        yield
    finally:
        numba.set_num_threads(old)


def sweep(path: SampledPath, tool: Tool, field: Field, *,
          initial: float | np.ndarray | Surface | None = None,
          method: Literal["pruned", "exhaustive"] = "pruned",
          n_threads: int | None = None,
          rows: tuple[int, int] | None = None,
          cols: tuple[int, int] | None = None,
          check: bool = True,
          **kwargs) -> Surface:
    """Machined height map: the lower envelope of the tool arc along a sampled path.

    Parameters
    ----------
    path : SampledPath
        Tool path (angle in rad, radius and height in m), whole or windowed.
    tool : Tool
        Round-nose tool: radius R (m), arc half-angle (rad), optional waviness.
    field : Field
        The grid (pitch in m, size, centre).
    initial : float, ndarray of shape (ny, nx), Surface or None, default: None
        Pre-cut height in m. None means a flat face at z = 0. ``np.inf`` means no
        material limit (uncut pixels stay +inf). NaN pixels are not computed and stay
        NaN (outside the workpiece or invalid).
    method : {"pruned", "exhaustive"}, default: "pruned"
        ``"pruned"`` evaluates only the passes that can be lowest; ``"exhaustive"``
        evaluates every pass that reaches below the pre-cut height (the baseline).
        Both give the same result.
    n_threads : int, optional
        Numba threads for this call; default numba's current setting.
    rows, cols : tuple of int, optional
        Half-open row/column ranges: compute only this tile of the field. Pixel
        coordinates are those of the whole field, so tiles reproduce a whole-field run
        bit for bit.
    check : bool, default: True
        Validate the path and warn on clearance violations.

    Returns
    -------
    Surface
        Heights in m (rows = y, columns = x) with ``dx``, ``dy``, ``x0``, ``y0`` of
        the computed tile and the sweep settings in ``metadata["sweep"]``.

    Raises
    ------
    ConfigError
        On a non-monotonic or non-finite path, bad shapes or an unknown method.
    TypeError
        On unknown keyword arguments.

    Warns
    -----
    ToolpathWarning
        When the slope along the cut exceeds the clearance angle
        (:func:`check_clearance`).

    Notes
    -----
    The edge is the circular arc of the seed paper's round diamond tool (section 4.2,
    Table 2) in the radial-axial plane; see :mod:`servosurf.kernels._sweep` for the
    crossing and bound formulas.
    """
    check_no_kwargs(kwargs, name="sweep")
    if method not in _METHODS:
        raise ConfigError(f"method must be one of {_METHODS}, got {method!r}")
    if not isinstance(tool, Tool):
        raise ConfigError(f"tool must be a Tool, got {type(tool).__name__}")
    if not isinstance(field, Field):
        raise ConfigError(f"field must be a Field, got {type(field).__name__}")
    rows = (0, field.ny) if rows is None else (int(rows[0]), int(rows[1]))
    cols = (0, field.nx) if cols is None else (int(cols[0]), int(cols[1]))
    if not (0 <= rows[0] < rows[1] <= field.ny and 0 <= cols[0] < cols[1] <= field.nx):
        raise ConfigError(
            f"rows {rows} and cols {cols} must be non-empty ranges inside the field of "
            f"shape {field.shape}"
        )
    shape = (rows[1] - rows[0], cols[1] - cols[0])
    out, fill = _initial_array(initial, shape, rows, cols, field)
    if not isinstance(path, SampledPath):
        raise ConfigError(f"path must be a SampledPath, got {type(path).__name__}")
    with _threads(n_threads):
        prep = prepare_path(path, tool, field, rows=rows, cols=cols, check=check,
                            stacklevel=3)
    meta = {
        "sweep": {
            "method": method,
            "nose_radius": tool.nose_radius,
            "arc_half_angle": tool.arc_half_angle,
            "n_samples": int(path.n),
            "n_samples_used": 0 if prep is None else int(prep.path.n),
            "fs": path.fs,
            "rows": list(rows),
            "cols": list(cols),
        }
    }
    x0 = field.x0 + cols[0] * field.pitch_x
    y0 = field.y0 + rows[0] * field.pitch_y
    if prep is None:
        if fill is not None:
            out.fill(fill)
        return Surface(out, field.pitch_x, field.pitch_y, meta, x0, y0)
    run_kernel(prep, tool, field, out, method=method, n_threads=n_threads,
               row0=rows[0], col0=cols[0], fill=fill)
    return Surface(out, field.pitch_x, field.pitch_y, meta, x0, y0)


def run_kernel(prep: PreparedPath, tool: Tool, field: Field, out: np.ndarray, *,
               method: str = "pruned", n_threads: int | None = None, row0: int = 0,
               col0: int = 0, fill: float | None = None) -> None:
    """Call the numba kernel in place on ``out`` (no checks; internal).

    Parameters
    ----------
    prep : PreparedPath
        Kernel inputs from :func:`prepare_path`.
    tool : Tool
        The tool.
    field : Field
        The whole grid (origin and pitch).
    out : ndarray of shape (ny, nx)
        Pre-cut heights in m, overwritten with the machined heights (with ``fill``:
        any content, overwritten).
    method : {"pruned", "exhaustive"}, default: "pruned"
        Kernel.
    n_threads : int, optional
        Numba threads.
    row0, col0 : int, default: 0
        Position of ``out`` in the field.
    fill : float, optional
        A uniform pre-cut height in m (or +inf) written into each row of ``out``
        just before it is computed (in cache, in parallel), instead of a separate
        pass over ``out``.
    """
    from ..kernels._sweep import _sweep_exhaustive, _sweep_pruned

    R = tool.nose_radius
    hw = tool.half_width
    s0, ds, wav = tool.waviness_table()
    wav_bound = max(0.0, float(wav.max())) if wav.size else 0.0
    slack = 1e-12 * R
    mirror_rmax = hw - prep.rmin
    with _threads(n_threads):
        if method == "pruned":
            _sweep_pruned(prep.theta, prep.pts, prep.bidx, prep.bstat, prep.rmid,
                          prep.theta_ref, R, hw, wav, s0, 1.0 / ds, wav_bound, slack,
                          mirror_rmax, prep.direction, field.x0, field.pitch_x,
                          col0, field.y0, field.pitch_y, row0, fill is not None,
                          0.0 if fill is None else float(fill), out)
        else:
            if fill is not None:
                out.fill(fill)
            _sweep_exhaustive(prep.theta, prep.pts, prep.bidx,
                              prep.bstat, prep.theta_ref, R, hw, wav, s0, 1.0 / ds,
                              wav_bound, slack, mirror_rmax, field.x0, field.pitch_x,
                              col0, field.y0, field.pitch_y, row0, out)
