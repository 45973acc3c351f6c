"""Obvious loop-and-numpy versions of servosurf's kernels (stumpy ``tests/naive.py``).

Slow on purpose: every grid point loops over the revolutions that could touch it and
interpolates the path with :func:`numpy.interp`. Units are SI (m, rad).
"""

from __future__ import annotations

import numpy as np

__all__ = ["sweep", "arc_height"]


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
