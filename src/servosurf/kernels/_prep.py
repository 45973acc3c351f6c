"""Numba kernels: one-pass checks and preparation of a sampled path for the sweep.

Checked wrapper: :func:`servosurf.toolpath.sweep` (via ``prepare_path``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._config import CACHE, FASTMATH

__all__ = ["_check_path", "_max_slope", "_crop_mask", "_interleave"]

TWO_PI = 2.0 * np.pi


@njit(cache=CACHE, fastmath=FASTMATH)
def _check_path(theta, r, z):  # pragma: no cover - numba
    """Validate a sampled path in one pass.

    Parameters
    ----------
    theta, r, z : ndarray of shape (n,)
        Angle (rad), radius (m), height (m).

    Returns
    -------
    int
        0 valid; 1 a non-finite value; 2 theta not strictly increasing; 3 r < 0.
    """
    n = theta.size
    for i in range(n):
        if not (np.isfinite(theta[i]) and np.isfinite(r[i]) and np.isfinite(z[i])):
            return 1
        if i > 0 and not theta[i] > theta[i - 1]:
            return 2
        if r[i] < 0.0:
            return 3
    return 0


@njit(cache=CACHE, fastmath=FASTMATH)
def _max_slope(t, theta, r, z, fs, r_skip):  # pragma: no cover - numba
    """Largest |dz / ds| along the cut over consecutive samples.

    Parameters
    ----------
    t, theta, r, z : ndarray of shape (n,)
        Time (s), angle (rad), radius (m), height (m).
    fs : float
        Sampling rate, in Hz (a time step above 1.5 / fs is a gap, skipped).
    r_skip : float
        Intervals with mid radius below this (m) are skipped.

    Returns
    -------
    slope : float
        Largest slope (dimensionless); 0 when none.
    index : int
        First sample of that interval (-1 when none).
    """
    best = 0.0
    at = -1
    gap = 1.5 / fs
    for i in range(t.size - 1):
        if t[i + 1] - t[i] > gap:
            continue
        rm = 0.5 * (r[i] + r[i + 1])
        if rm < r_skip:
            continue
        ds = rm * (theta[i + 1] - theta[i])
        if ds > 0.0:
            s = abs(z[i + 1] - z[i]) / ds
            if s > best:
                best = s
                at = i
    return best, at


@njit(cache=CACHE, fastmath=FASTMATH)
def _crop_mask(theta, r, rmin, rmax, reach, has_window, centre, lo, hi,
               keep):  # pragma: no cover - numba
    """Mark the samples of every interval that can cut a rectangle.

    Parameters
    ----------
    theta, r : ndarray of shape (n,)
        Angle (rad) and radius (m).
    rmin, rmax : float
        Radial range of the rectangle, in m.
    reach : float
        Arc reach plus a rounding allowance, in m.
    has_window : bool
        False when every angle is needed.
    centre, lo, hi : float
        Angular window ``[centre + lo, centre + hi]``, in rad.
    keep : ndarray of shape (n,), bool
        Output: samples to keep (both ends of every relevant interval).

    Returns
    -------
    int
        Number of samples kept.
    """
    n = theta.size
    for i in range(n):
        keep[i] = False
    for i in range(n - 1):
        r0 = r[i]
        r1 = r[i + 1]
        rl = r0 if r0 < r1 else r1
        rh = r1 if r0 < r1 else r0
        hit = (rl <= rmax + reach and rh >= rmin - reach) or rl <= reach - rmin
        if hit and has_window:
            rel = theta[i] - centre + np.pi
            rel = rel - TWO_PI * np.floor(rel / TWO_PI) - np.pi
            dth = theta[i + 1] - theta[i]
            hit = ((rel <= hi and rel + dth >= lo) or rel - TWO_PI + dth >= lo
                   or dth >= TWO_PI)
        if hit:
            keep[i] = True
            keep[i + 1] = True
    count = 0
    for i in range(n):
        if keep[i]:
            count += 1
    return count


@njit(parallel=True, cache=CACHE, fastmath=FASTMATH)
def _interleave(t, theta, r, z, fs, pts, gap):  # pragma: no cover - numba
    """Interleave the path for the sweep kernels and flag gaps.

    Parameters
    ----------
    t, theta, r, z : ndarray of shape (n,)
        Time (s), angle (rad), radius (m), height (m).
    fs : float
        Sampling rate, in Hz.
    pts : ndarray of shape (n, 4)
        Output: theta, r, z and 1 / (theta[i + 1] - theta[i]) (0 across gaps and at
        the end).
    gap : ndarray of shape (n,), bool
        Output: True where samples i and i + 1 are not consecutive in time.
    """
    n = t.size
    lim = 1.5 / fs
    for i in prange(n):  # each i writes only row i (pages touched on both threads)
        pts[i, 0] = theta[i]
        pts[i, 1] = r[i]
        pts[i, 2] = z[i]
        g = i == n - 1 or t[i + 1] - t[i] > lim
        gap[i] = g and i < n - 1
        pts[i, 3] = 0.0 if g else 1.0 / (theta[i + 1] - theta[i])
