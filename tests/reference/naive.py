"""Obvious loop-and-numpy versions of servosurf's kernels (stumpy ``tests/naive.py``).

Slow on purpose: every grid point loops over the revolutions that could touch it and
interpolates the path with :func:`numpy.interp`. Units are SI (m, rad).
"""

from __future__ import annotations

import numpy as np

__all__ = ["sweep", "ordered_sweep", "arc_height", "crop_mask", "max_slope",
           "bucket_ranges"]


def arc_height(zc, dr, radius, wav=None):
    """Height of a planar circular arc over radial offset ``dr``, in m.

    Parameters
    ----------
    zc : ndarray
        Tool-tip height, in m.
    dr : ndarray
        Radial offset of the point from the tool tip, in m.
    radius : float
        Nose radius, in m.
    wav : tuple (s0, ds, table), optional
        Waviness correction in m tabulated on s = dr / radius (uniform grid).

    Returns
    -------
    ndarray
        ``zc + R - sqrt(R**2 - dr**2) - c(dr / R)``, in m.
    """
    h = zc + radius - np.sqrt(radius**2 - dr**2)
    if wav is not None and wav[2].size > 1:
        s0, ds, table = wav
        grid = s0 + ds * np.arange(table.size)
        h = h - np.interp(dr / radius, grid, table)
    return h


def sweep(t, theta, r, z, fs, x, y, radius, half_width, initial, wav=None):
    """Lower envelope of the planar tool arc swept along a sampled path.

    Parameters
    ----------
    t, theta, r, z : ndarray of shape (n,)
        Sample times (s), unwrapped tool angle (rad), tool radius (m), height (m).
    fs : float
        Sampling rate, in Hz; neighbours more than 1.5 / fs apart are a gap.
    x : ndarray of shape (nx,)
        Column positions, in m.
    y : ndarray of shape (ny,)
        Row positions, in m.
    radius : float
        Nose radius R, in m.
    half_width : float
        Arc half-width, in m.
    initial : ndarray of shape (ny, nx)
        Pre-cut height, in m (NaN stays NaN).
    wav : tuple, optional
        Waviness table (s0, ds, table) as from ``Tool.waviness_table()``.

    Returns
    -------
    ndarray of shape (ny, nx)
        Machined height, in m.
    """
    n = theta.size
    gap = np.zeros(n, dtype=bool)
    gap[:-1] = np.diff(t) > 1.5 / fs
    out = np.array(initial, dtype=float, copy=True)
    for i, yy in enumerate(y):
        for j, xx in enumerate(x):
            if np.isnan(out[i, j]) or n < 2:
                continue
            rp = np.hypot(xx, yy)
            ang = np.arctan2(yy, xx)
            best = out[i, j]
            # direct crossing, and the part of the arc reaching across the axis
            for phi, rq in ((ang, rp), (ang + np.pi, -rp)):
                k_lo = int(np.ceil((theta[0] - phi) / (2 * np.pi)))
                k_hi = int(np.floor((theta[-1] - phi) / (2 * np.pi)))
                for k in range(k_lo, k_hi + 1):  # one crossing per revolution
                    target = phi + 2 * np.pi * k
                    if target < theta[0] or target > theta[-1]:
                        continue
                    m = min(int(np.searchsorted(theta, target, side="right")) - 1,
                            n - 2)
                    if gap[m]:
                        continue
                    rc = np.interp(target, theta, r)
                    dr = rq - rc
                    if abs(dr) > half_width:
                        continue
                    zc = np.interp(target, theta, z)
                    h = float(arc_height(np.array([zc]), np.array([dr]), radius,
                                         wav)[0])
                    best = min(best, h)
            out[i, j] = best
    return out


def ordered_sweep(t, theta, r, z, fs, x, y, radius, half_width, initial, rules,
                  wav=None):
    """The swept arc applied pass by pass in time order with material rules.

    Parameters
    ----------
    t, theta, r, z, fs, x, y, radius, half_width, initial, wav
        As for :func:`sweep`.
    rules : sequence of 5 float
        ``(h_min, a, b, d0, h_d)`` in m: minimum chip thickness, side-flow ridge
        height and half-width, recovery at zero thickness and its decay thickness.

    Returns
    -------
    ndarray of shape (ny, nx)
        Machined height, in m.

    Notes
    -----
    Every crossing of a point (direct, and across the axis) is listed with its
    angle, sorted (the angle grows with time) and applied in that order: with
    ``h = s - z_e``, a cut (``h > h_min``) sets ``s = z_e + min(h, d0 exp(-h/h_d))``
    and stores the edge slope ``sign (q - r_c) / R`` of the pass; otherwise, at a
    distance ``d = (h_min - h) / |slope - stored slope| < b`` the ridge
    ``a (1 - d / b)`` is added.
    """
    h_min, a, b, d0, hd = (float(v) for v in rules)
    n = theta.size
    gap = np.zeros(n, dtype=bool)
    gap[:-1] = np.diff(t) > 1.5 / fs
    out = np.array(initial, dtype=float, copy=True)
    for i, yy in enumerate(y):
        for j, xx in enumerate(x):
            s = out[i, j]
            if np.isnan(s) or n < 2:
                continue
            rp = np.hypot(xx, yy)
            ang = np.arctan2(yy, xx)
            events = []  # (angle, signed query radius, sign of the slope)
            for phi, rq, sign in ((ang, rp, 1.0), (ang + np.pi, -rp, -1.0)):
                k_lo = int(np.ceil((theta[0] - phi) / (2 * np.pi)))
                k_hi = int(np.floor((theta[-1] - phi) / (2 * np.pi)))
                for k in range(k_lo, k_hi + 1):
                    events.append((phi + 2 * np.pi * k, rq, sign))
            events.sort()
            slope_s = 0.0
            for target, rq, sign in events:
                if target < theta[0] or target > theta[-1]:
                    continue
                m = min(int(np.searchsorted(theta, target, side="right")) - 1, n - 2)
                if gap[m]:
                    continue
                f = (target - theta[m]) / (theta[m + 1] - theta[m])
                f = min(max(f, 0.0), 1.0)
                rc = r[m] + f * (r[m + 1] - r[m])
                dr = rq - rc
                if abs(dr) > half_width:
                    continue
                zc = z[m] + f * (z[m + 1] - z[m])
                ze = float(arc_height(np.array([zc]), np.array([dr]), radius, wav)[0])
                h = s - ze
                slope = sign * dr / radius
                if h > h_min:
                    rec = min(h, d0 * np.exp(-h / hd)) if (d0 > 0 and hd > 0) else 0.0
                    s = ze + rec
                    slope_s = slope
                elif a > 0 and b > 0 and abs(slope - slope_s) > 0:
                    d = (h_min - h) / abs(slope - slope_s)
                    if d < b:
                        s = s + a * (1.0 - d / b)
            out[i, j] = s
    return out


def crop_mask(theta, r, rmin, rmax, reach, window=None):
    """Samples of every interval that can cut the rectangle [rmin, rmax] x window.

    An interval (i, i + 1) hits when its radial range comes within ``reach`` (m) of
    [rmin, rmax] (or reaches across the axis) and, with ``window = (centre, lo,
    hi)`` in rad, its angular span meets [centre + lo, centre + hi] modulo 2 pi.
    Both samples of a hitting interval are kept. Returns (mask, count).
    """
    rl = np.minimum(r[:-1], r[1:])
    rh = np.maximum(r[:-1], r[1:])
    hit = ((rl <= rmax + reach) & (rh >= rmin - reach)) | (rl <= reach - rmin)
    if window is not None:
        centre, lo, hi = window
        rel = np.mod(theta[:-1] - centre + np.pi, 2 * np.pi) - np.pi
        dth = np.diff(theta)
        ang = ((rel <= hi) & (rel + dth >= lo)) | (rel - 2 * np.pi + dth >= lo) | (
            dth >= 2 * np.pi)
        hit &= ang
    keep = np.zeros(theta.size, dtype=bool)
    keep[:-1] |= hit
    keep[1:] |= hit
    return keep, int(keep.sum())


def max_slope(t, theta, r, z, fs, r_skip):
    """Largest |dz / ds| over consecutive samples (time step <= 1.5 / fs) whose mid
    radius is at least ``r_skip`` (m); returns (slope, first interval index or -1)."""
    rm = 0.5 * (r[:-1] + r[1:])
    ds = rm * np.diff(theta)
    ok = (np.diff(t) <= 1.5 / fs) & (rm >= r_skip) & (ds > 0)
    s = np.zeros(rm.size)
    s[ok] = np.abs(np.diff(z)[ok]) / ds[ok]
    if s.size == 0 or s.max() <= 0.0:
        return 0.0, -1
    return float(s.max()), int(np.argmax(s))


def bucket_ranges(theta, theta_ref, n_buckets):
    """For bucket j = [theta_ref + 2 pi j, theta_ref + 2 pi (j + 1)): the first
    sample at or after its start and the first at or after its end (rad)."""
    j = np.arange(n_buckets)
    start = theta_ref + 2 * np.pi * j
    end = theta_ref + 2 * np.pi * (j + 1)
    return np.searchsorted(theta, start, "left"), np.searchsorted(theta, end, "left")
