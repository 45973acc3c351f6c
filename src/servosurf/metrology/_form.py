"""Nominal lenslet shape from the tool path, form error and centre profiles.

Frame used throughout: heights ``z`` point up, out of the workpiece (a cut lowers
``z``); ``x`` is the cutting direction with ``x = v t``; the fast tool servo moves the
tool tip to ``z_tip(t) = -A cos(2 pi f (t - t_c))``, i.e. the paper's
``A sin(2 pi f t)`` plunge with the phase chosen so that the deepest plunge is at
``x_c = v t_c``, measured from the servo's mean position. The uncut top surface is at
``z_top = depth - A``, so the deepest point lies ``depth`` below it, and for
``depth = A / 2`` the tool cuts during one third of each period (seed paper Table 2
and section 5.3).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.optimize

from .._validation import check_array, check_finite, check_nonnegative, check_positive
from ..errors import ConfigError
from ._lenslet import find_deepest_point
from ._surface import Profile, Surface

__all__ = [
    "nominal_lenslet_profile",
    "nominal_lenslet_surface",
    "form_error_profile",
    "lenslet_centre_profile",
]

#: A reference sample belongs to the cut region when it lies more than this
#: fraction of the reference's height range below the uncut top.
CUT_FRACTION: float = 1e-3


def _tip(u: np.ndarray, amp: float, f: float, v: float, periodic: bool) -> np.ndarray:
    """Tool tip height at distance ``u`` (m) from the deepest plunge."""
    tip = -amp * np.cos(2.0 * np.pi * f * u / v)
    if not periodic:
        tip = np.where(np.abs(u) <= v / (2.0 * f), tip, np.inf)
    return tip


def _lenslet_args(
    amplitude: float,
    frequency: float,
    speed: float,
    depth: float,
    tool_radius: float,
    path_amplitude: float | None,
) -> tuple[float, float, float, float, float, float]:
    a = check_positive(amplitude, name="amplitude")
    f = check_positive(frequency, name="frequency")
    v = check_positive(speed, name="speed")
    d = check_positive(depth, name="depth")
    r = check_positive(tool_radius, name="tool_radius")
    ap = (
        a
        if path_amplitude is None
        else check_positive(path_amplitude, name="path_amplitude")
    )
    return a, f, v, d, r, ap


def nominal_lenslet_profile(
    x: np.ndarray,
    *,
    amplitude: float,
    frequency: float,
    speed: float,
    depth: float,
    tool_radius: float,
    centre: float = 0.0,
    cross_offset: float = 0.0,
    path_amplitude: float | None = None,
    periodic: bool = False,
) -> np.ndarray:
    """Return the nominal lenslet profile along the cutting direction.

    Parameters
    ----------
    x : ndarray of shape (n,)
        Positions along the cutting direction, in m (``x = v t``).
    amplitude : float
        Nominal zero-to-peak servo amplitude ``A``, in m. With ``depth`` it fixes the
        uncut top surface at ``depth - amplitude``.
    frequency : float
        Servo frequency ``f``, in Hz (100 Hz in the seed paper).
    speed : float
        Surface speed ``v`` at the cutting point, in m/s.
    depth : float
        Nominal lenslet depth below the uncut top, in m.
    tool_radius : float
        Tool nose radius ``R``, in m.
    centre : float, default: 0.0
        Position ``x_c`` of the deepest plunge, in m.
    cross_offset : float, default: 0.0
        Distance ``dr`` of the profile from the tool's centre plane in the radial
        (cross) direction, in m. 0 is the profile through the lenslet centre.
    path_amplitude : float or None, default: None
        Amplitude the tool actually moves, in m (for example the air-cut amplitude
        5.2 um used as the form reference in the seed paper), while the top surface
        stays where ``amplitude`` put it. ``None`` means ``amplitude``.
    periodic : bool, default: False
        False: one lenslet, the tool path only within half a servo period
        (``v / (2 f)``) of ``centre`` and the uncut top elsewhere. True: the
        servo keeps oscillating, a row of lenslets at the pitch ``v / f``.

    Returns
    -------
    ndarray of shape (n,)
        Heights in m in the servo frame (top surface at ``depth - amplitude``).

    Raises
    ------
    ConfigError
        If a parameter is not positive or ``x`` is not 1-D.

    See Also
    --------
    nominal_lenslet_surface, form_error_profile

    Notes
    -----
    The tool's round nose arc lies in the radial-axial plane, perpendicular to the
    cutting direction, so along the cutting direction the tool acts as a point of
    zero thickness. The surface left at ``(x, dr)`` is therefore

    ``z = min(z_top, z_tip(x) + R - sqrt(R^2 - dr^2))``,
    ``z_tip(x) = -A_path cos(2 pi f (x - x_c) / v)``,

    which on the centre line (``dr = 0``) is simply ``min(z_top, z_tip(x))``: the
    tool radius does not enter. Only the cross direction is shaped by the arc. A
    sphere of radius ``R`` is *not* the lenslet: along the cut the curvature radius
    at the bottom is ``v^2 / (A (2 pi f)^2)`` (about 0.45 mm for the paper's 5 um
    lenslet), not ``R``. Seed paper section 5.3 and Table 2.

    Examples
    --------
    >>> import numpy as np
    >>> from servosurf.metrology import nominal_lenslet_profile
    >>> x = np.linspace(-100e-6, 100e-6, 2001)
    >>> z = nominal_lenslet_profile(x, amplitude=10e-6, frequency=100.0,
    ...     speed=42.4e-3, depth=5e-6, tool_radius=0.5e-3)
    >>> round(float(z.max() - z.min()) / 1e-6, 6)  # lenslet depth in um
    5.0
    """
    x = check_array(x, name="x", ndim=1)
    a, f, v, d, r, ap = _lenslet_args(
        amplitude, frequency, speed, depth, tool_radius, path_amplitude
    )
    centre = check_finite(centre, name="centre")
    dr = check_finite(cross_offset, name="cross_offset")
    top = d - a
    if abs(dr) >= r:
        return np.full(x.shape, top)
    tip = _tip(x - centre, ap, f, v, periodic)
    return np.minimum(top, tip + (r - np.sqrt(r * r - dr * dr)))


def nominal_lenslet_surface(
    x: np.ndarray,
    y: np.ndarray,
    *,
    amplitude: float,
    frequency: float,
    speed: float,
    depth: float,
    tool_radius: float,
    centre: tuple[float, float] = (0.0, 0.0),
    path_amplitude: float | None = None,
    periodic: bool = False,
) -> np.ndarray:
    """Return the nominal height map of one lenslet (cutting direction along x).

    Parameters
    ----------
    x : ndarray of shape (nx,)
        Column positions (cutting direction), in m.
    y : ndarray of shape (ny,)
        Row positions (radial direction), in m.
    amplitude, frequency, speed, depth, tool_radius, path_amplitude, periodic
        As in :func:`nominal_lenslet_profile` (m, Hz, m/s, m, m, m, bool).
    centre : tuple of float, default: (0.0, 0.0)
        ``(x_c, y_c)`` of the deepest point, in m.

    Returns
    -------
    ndarray of shape (ny, nx)
        Heights in m, servo frame (top at ``depth - amplitude``).

    Raises
    ------
    ConfigError
        If a parameter is not positive.

    Notes
    -----
    ``z(x, y) = min(z_top, z_tip(x) + R - sqrt(R^2 - (y - y_c)^2))``: the point-like
    tool along the cut and the nose arc across it (see
    :func:`nominal_lenslet_profile`).
    """
    x = check_array(x, name="x", ndim=1)
    y = check_array(y, name="y", ndim=1)
    a, f, v, d, r, ap = _lenslet_args(
        amplitude, frequency, speed, depth, tool_radius, path_amplitude
    )
    xc = check_finite(centre[0], name="centre[0]")
    yc = check_finite(centre[1], name="centre[1]")
    top = d - a
    tip = _tip(x - xc, ap, f, v, periodic)
    dr2 = (y - yc) ** 2
    arc = np.where(dr2 < r * r, r - np.sqrt(np.clip(r * r - dr2, 0.0, None)), np.inf)
    return np.minimum(top, tip[None, :] + arc[:, None])


def _deepest_x(x: np.ndarray, z: np.ndarray) -> float:
    """Sub-sample x of the minimum of z (parabola through 3 samples)."""
    k = int(np.nanargmin(z))
    if 0 < k < z.size - 1 and np.all(np.isfinite(z[k - 1 : k + 2])):
        a, b, c = z[k - 1], z[k], z[k + 1]
        den = a - 2.0 * b + c
        if den > 0:
            delta = float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))
            return float(x[k] + delta * (x[k + 1] - x[k - 1]) / 2.0)
    return float(x[k])


def form_error_profile(
    x: np.ndarray,
    z_measured: np.ndarray,
    z_nominal: np.ndarray | Callable[[np.ndarray, float | None], np.ndarray],
    *,
    reference_amplitude: float | None = None,
    max_shift: float = 0.0,
    cut_only: bool = True,
    cutting_direction: int = 1,
) -> dict[str, Any]:
    """Return the form error of a measured lenslet profile against its nominal.

    Parameters
    ----------
    x : ndarray of shape (n,)
        Positions along the cutting direction, in m, increasing.
    z_measured : ndarray of shape (n,)
        Measured heights in m (NaN = invalid), e.g. from
        :func:`lenslet_centre_profile`.
    z_nominal : ndarray of shape (n,) or callable
        Nominal heights in m on ``x``, or a callable ``z_nominal(x, amplitude)``
        returning them for a tool-path amplitude in m (``None``: nominal), for
        example ``lambda x, a: nominal_lenslet_profile(x, amplitude=5e-6, ...,
        path_amplitude=a)``.
    reference_amplitude : float or None, default: None
        Tool-path amplitude of the form reference, in m. The seed paper uses the
        air-cut amplitude (5.2 um for a nominal 5 um, because of the closed loop's
        overshoot at 100 Hz). Requires a callable ``z_nominal``.
    max_shift : float, default: 0.0
        Largest lateral shift of the reference tried in the alignment, in m
        (0: piston only).
    cut_only : bool, default: True
        Evaluate only where the reference lies below its uncut top (the lenslet);
        elsewhere the error is NaN.
    cutting_direction : {1, -1}, default: 1
        Direction the tool travels along ``x``: +1 when it moves towards +x.

    Returns
    -------
    dict
        ``error`` (ndarray (n,), m): measured minus aligned reference;
        ``reference`` (ndarray (n,), m): the aligned reference;
        ``max_abs_error_m`` (m); ``max_error_m`` (m, signed error at that point);
        ``max_error_x_m`` (m): its position; ``x_deepest_m`` (m): deepest point of
        the aligned reference; ``max_error_position_m`` (m): position of the
        maximum error relative to the deepest point, positive when it *lags*
        (comes later in the cut); ``rms_error_m``, ``pv_error_m`` (m);
        ``piston_m`` (m, added to the reference); ``shift_m`` (m, reference shifted
        towards +x); ``reference_amplitude_m`` (m or None).

    Raises
    ------
    ConfigError
        On shape mismatch, no valid overlap, or ``reference_amplitude`` given with
        an array ``z_nominal``.

    See Also
    --------
    nominal_lenslet_profile, lenslet_centre_profile

    Notes
    -----
    Alignment: the piston is the mean of ``z_measured - reference`` over the
    evaluated samples (least squares); with ``max_shift > 0`` the shift minimising
    the RMS residual is found by a bounded scalar search, the reference being
    re-evaluated (callable) or linearly interpolated (array) at ``x - shift``.
    Seed paper section 5.3 (Fig. 18): the maximum form error (200 nm) lags the
    maximum depth of cut.
    """
    x = check_array(x, name="x", ndim=1, min_size=3, finite=True)
    zm = check_array(z_measured, name="z_measured", ndim=1)
    if zm.shape != x.shape:
        raise ConfigError(
            f"z_measured must have the shape of x {x.shape}, got {zm.shape}"
        )
    if np.any(np.diff(x) <= 0):
        raise ConfigError("x must be strictly increasing")
    if cutting_direction not in (1, -1):
        raise ConfigError(
            f"cutting_direction must be 1 or -1, got {cutting_direction!r}"
        )
    max_shift = check_nonnegative(max_shift, name="max_shift")
    if reference_amplitude is not None:
        reference_amplitude = check_positive(
            reference_amplitude, name="reference_amplitude"
        )

    if callable(z_nominal):

        def ref_at(s: float) -> np.ndarray:
            out = check_array(
                z_nominal(x - s, reference_amplitude), name="z_nominal(x, amplitude)"
            )
            if out.shape != x.shape:
                raise ConfigError(
                    f"z_nominal(x, amplitude) must return shape {x.shape}, "
                    f"got {out.shape}"
                )
            return out

    else:
        if reference_amplitude is not None:
            raise ConfigError(
                "reference_amplitude needs z_nominal as a callable z_nominal(x, "
                "amplitude), e.g. functools.partial of nominal_lenslet_profile; got an "
                "array"
            )
        zn = check_array(z_nominal, name="z_nominal", ndim=1)
        if zn.shape != x.shape:
            raise ConfigError(
                f"z_nominal must have the shape of x {x.shape}, got {zn.shape}"
            )

        def ref_at(s: float) -> np.ndarray:
            if s == 0.0:
                return zn
            return np.interp(x - s, x, zn, left=np.nan, right=np.nan)

    def region(ref: np.ndarray) -> np.ndarray:
        ok = np.isfinite(ref) & np.isfinite(zm)
        if cut_only and ok.any():
            top, low = np.nanmax(ref), np.nanmin(ref)
            ok &= ref < top - CUT_FRACTION * (top - low)
            if not ok.any():  # no flat top: the whole profile is cut
                ok = np.isfinite(ref) & np.isfinite(zm)
        return ok

    ref0 = ref_at(0.0)
    mask0 = region(ref0)
    if mask0.sum() < 3:
        raise ConfigError("fewer than 3 valid samples to compare with the reference")

    def cost(s: float) -> float:
        ref = ref_at(s)
        m = mask0 & np.isfinite(ref)
        if m.sum() < 3:
            return np.inf
        res = zm[m] - ref[m]
        return float(np.mean((res - res.mean()) ** 2))

    shift = 0.0
    if max_shift > 0:
        opt = scipy.optimize.minimize_scalar(
            cost,
            bounds=(-max_shift, max_shift),
            method="bounded",
            options={"xatol": 1e-3 * float(np.median(np.diff(x)))},
        )
        shift = float(opt.x) if cost(float(opt.x)) < cost(0.0) else 0.0
    ref = ref_at(shift)
    mask = region(ref)
    if mask.sum() < 3:
        raise ConfigError("fewer than 3 valid samples to compare with the reference")
    piston = float(np.mean(zm[mask] - ref[mask]))
    aligned = ref + piston
    err = np.full(x.shape, np.nan)
    err[mask] = zm[mask] - aligned[mask]
    k = int(np.nanargmax(np.abs(err)))
    x_deep = _deepest_x(x, aligned)
    e = err[mask]
    return {
        "error": err,
        "reference": aligned,
        "max_abs_error_m": float(abs(err[k])),
        "max_error_m": float(err[k]),
        "max_error_x_m": float(x[k]),
        "x_deepest_m": x_deep,
        "max_error_position_m": float((x[k] - x_deep) * cutting_direction),
        "rms_error_m": float(np.sqrt(np.mean(e**2))),
        "pv_error_m": float(e.max() - e.min()),
        "piston_m": piston,
        "shift_m": shift,
        "reference_amplitude_m": reference_amplitude,
    }


def lenslet_centre_profile(
    surface: Surface,
    *,
    direction: str = "x",
    smooth: float = 1.0,
    window: int = 8,
) -> Profile:
    """Extract the profile through a lenslet's deepest point (its centre).

    Parameters
    ----------
    surface : Surface
        Height map in m holding one lenslet (crop or segment first; remove tilt).
    direction : {"x", "y"}, default: "x"
        ``"x"``: the row through the centre, along the cutting direction;
        ``"y"``: the column (radial direction).
    smooth : float, default: 1.0
        Smoothing, in pixels, used only to locate the deepest pixel
        (see :func:`find_deepest_point`).
    window : int, default: 8
        Half-size, in pixels, of the paraboloid fit window that refines the centre
        (see :func:`find_deepest_point`).

    Returns
    -------
    Profile
        Heights in m at the pixel pitch (``dx`` for "x", ``dy`` for "y"; 1.0 per
        pixel when uncalibrated), starting at ``x0`` (or ``y0``). The row (column)
        is linearly interpolated between the two rows (columns) around the
        sub-pixel centre. ``metadata["lenslet_centre"]`` holds ``x_m``, ``y_m``
        (sub-pixel centre, m), ``row``, ``col`` (fractional pixel indices) and
        ``direction``.

    Raises
    ------
    ConfigError
        If ``direction`` is not "x" or "y", or the map has no valid pixels.

    See Also
    --------
    find_deepest_point, form_error_profile
    """
    if direction not in ("x", "y"):
        raise ConfigError(f"direction must be 'x' or 'y', got {direction!r}")
    if not isinstance(surface, Surface):
        raise ConfigError(f"surface must be a Surface, got {type(surface).__name__}")
    fi, fj = find_deepest_point(surface, smooth=smooth, window=window)
    dx = surface.dx if surface.dx is not None else 1.0
    dy = surface.dy if surface.dy is not None else 1.0
    z = surface.z if direction == "x" else surface.z.T
    f = fi if direction == "x" else fj
    n = z.shape[0]
    i = min(int(np.floor(f)), n - 1)
    t = f - i
    if t > 1e-9 and i + 1 < n:
        line = (1.0 - t) * z[i] + t * z[i + 1]
    else:
        line = z[i].copy()
    meta = dict(surface.metadata)
    meta["lenslet_centre"] = {
        "x_m": surface.x0 + fj * dx,
        "y_m": surface.y0 + fi * dy,
        "row": fi,
        "col": fj,
        "direction": direction,
    }
    if direction == "x":
        return Profile(line, dx, meta, surface.x0)
    return Profile(line, dy, meta, surface.y0)
