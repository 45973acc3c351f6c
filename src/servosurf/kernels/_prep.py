"""Numba kernels: one-pass checks and preparation of a sampled path for the sweep.

Checked wrapper: :func:`servosurf.toolpath.sweep` (via ``prepare_path``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._config import CACHE, FASTMATH

__all__ = [
    "_check_path",
    "_scan_slope",
    "_crop_mask_chunked",
    "_hit_fraction",
    "_interleave",
]

TWO_PI = 2.0 * np.pi


@njit(cache=CACHE, fastmath=FASTMATH)
def _check_path(t, theta, r, z):  # pragma: no cover - numba
    """Validate a sampled path in one pass.

    Parameters
    ----------
    t, theta, r, z : ndarray of shape (n,)
        Time (s), angle (rad), radius (m), height (m).

    Returns
    -------
    int
        0 valid; 1 a non-finite value; 2 theta not strictly increasing; 3 r < 0.
    """
    n = theta.size
    for i in range(n):
        if not (np.isfinite(t[i]) and np.isfinite(theta[i]) and np.isfinite(r[i])
                and np.isfinite(z[i])):
            return 1
        if i > 0 and not theta[i] > theta[i - 1]:
            return 2
        if r[i] < 0.0:
            return 3
    return 0


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



@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _interval_slope(t, theta, r, z, i, gap, r_skip):  # pragma: no cover - numba
    """|dz / ds| over interval (i, i + 1), 0 across a gap, near the axis or at ds <= 0.

    ``gap`` is the largest time step of consecutive samples (s), ``r_skip`` the
    smallest mid radius considered (m).
    """
    rm = 0.5 * (r[i] + r[i + 1])
    ds = rm * (theta[i + 1] - theta[i])
    ok = (t[i + 1] - t[i] <= gap) & (rm >= r_skip) & (ds > 0.0)
    sl = abs(z[i + 1] - z[i]) / (ds if ok else 1.0)
    return sl if ok else 0.0


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _chunk_faulty(t, theta, r, z):  # pragma: no cover - numba
    """Whether a sample of these slices is non-finite or at r < 0, or theta does not
    strictly increase along them."""
    bad = False
    for i in range(theta.size):
        fin = (np.isfinite(t[i]) & np.isfinite(theta[i]) & np.isfinite(r[i])
               & np.isfinite(z[i]))
        bad |= (not fin) | (r[i] < 0.0)
    for i in range(1, theta.size):
        bad |= theta[i] <= theta[i - 1]
    return bad


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _chunk_max_slope(t, theta, r, z, gap, r_skip):  # pragma: no cover - numba
    """Largest :func:`_interval_slope` over the intervals of these slices."""
    best = 0.0
    for i in range(t.size - 1):
        best = max(best, _interval_slope(t, theta, r, z, i, gap, r_skip))
    return best


@njit(parallel=True, cache=CACHE, fastmath=FASTMATH)
def _scan_slope(t, theta, r, z, fs, r_skip, n_chunks,
                res):  # pragma: no cover - numba
    """Fault flag and largest |dz / ds| along the cut, in one parallel pass.

    Parameters
    ----------
    t, theta, r, z : ndarray of shape (n,)
        Time (s), angle (rad), radius (m), height (m).
    fs : float
        Sampling rate, in Hz (a time step above 1.5 / fs is a gap, skipped).
    r_skip : float
        Intervals with mid radius below this (m) are skipped.
    n_chunks : int
        Number of chunks.
    res : ndarray of shape (n_chunks, 2)
        Work space: per chunk the fault flag and the largest slope.

    Returns
    -------
    faulty : bool
        True when a sample (t included) is non-finite, theta is not strictly
        increasing or r < 0 (:func:`_check_path` tells which); the slope is then
        meaningless.
    slope : float
        Largest slope (dimensionless); 0 when none.
    index : int
        First sample of the first interval with that slope (-1 when none).

    Notes
    -----
    The fault flags are OR-ed and the slopes max-reduced without branches, so the
    loops vectorise (the ``nnan``/``ninf`` fast-math flags are off, so
    ``isfinite`` is exact); the index is found afterwards in the one chunk that
    holds the maximum.
    """
    n = t.size
    m = n - 1
    step = (n + n_chunks - 1) // n_chunks
    gap = 1.5 / fs
    for c in prange(n_chunks):
        s0 = c * step
        s1 = min(n, s0 + step)
        # slices from the previous sample (for the increasing check) and to the
        # next one (intervals): indices from 0, so the loops vectorise
        p0 = max(s0, 1) - 1
        bad = _chunk_faulty(t[p0:s1], theta[p0:s1], r[p0:s1], z[p0:s1])
        e = min(m, s1) + 1
        best = _chunk_max_slope(t[s0:e], theta[s0:e], r[s0:e], z[s0:e], gap, r_skip)
        res[c, 0] = bad
        res[c, 1] = best
    bad = False
    best = 0.0
    chunk = -1
    for c in range(n_chunks):
        bad |= res[c, 0] != 0.0
        if res[c, 1] > best:
            best = res[c, 1]
            chunk = c
    at = -1
    if chunk >= 0:  # first interval of the first chunk that holds the maximum
        at = chunk * step  # (the rescan recomputes the same values, so it finds it)
        for i in range(chunk * step, min(m, (chunk + 1) * step)):
            if _interval_slope(t, theta, r, z, i, gap, r_skip) == best:
                at = i
                break
    return bad, best, at


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _interval_hits(theta, r, i, rmin, rmax, reach, has_window, centre, lo,
                   hi):  # pragma: no cover - numba
    """Whether interval (i, i + 1) can cut the rectangle (crop mask)."""
    r0 = r[i]
    r1 = r[i + 1]
    rl = min(r0, r1)
    rh = max(r0, r1)
    hit = ((rl <= rmax + reach) & (rh >= rmin - reach)) | (rl <= reach - rmin)
    # angular test evaluated for every interval and combined without branches
    rel = theta[i] - centre + np.pi
    rel = rel - TWO_PI * np.floor(rel * (1.0 / TWO_PI)) - np.pi
    dth = theta[i + 1] - theta[i]
    ang = (((rel <= hi) & (rel + dth >= lo)) | (rel - TWO_PI + dth >= lo)
           | (dth >= TWO_PI))
    return hit & (ang | (not has_window))


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _chunk_keep(theta, r, rmin, rmax, reach, has_window, centre, lo, hi, first,
                keep):  # pragma: no cover - numba
    """Keep marks of one chunk; returns how many are set.

    ``theta``/``r`` start one sample before the chunk when ``first`` is 1 (0 for the
    path's first chunk) and end one sample after it unless it holds the last sample.
    Sample k of the chunk is kept when the interval before or after it hits.
    """
    m = theta.size - 1  # intervals in the slices
    count = 0
    for k in range(keep.size):
        j = k + first  # sample index in the slices
        after = False
        if j < m:
            after = _interval_hits(theta, r, j, rmin, rmax, reach, has_window, centre,
                                   lo, hi)
        before = False
        if j >= 1:
            before = _interval_hits(theta, r, j - 1, rmin, rmax, reach, has_window,
                                    centre, lo, hi)
        keep[k] = after | before
        count += after | before
    return count


@njit(parallel=True, cache=CACHE, fastmath=FASTMATH)
def _crop_mask_chunked(theta, r, rmin, rmax, reach, has_window, centre, lo, hi,
                       n_chunks, keep):  # pragma: no cover - numba
    """Mark the samples of every interval that can cut a rectangle, in parallel chunks.

    Each chunk writes only its own samples: sample i is kept when interval i - 1 or
    interval i can cut the rectangle (the chunk re-evaluates the interval before
    its first sample). The interval test has no branches, so the loop vectorises.

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
    n_chunks : int
        Number of chunks.
    keep : ndarray of shape (n,), bool
        Output: samples to keep (both ends of every relevant interval).

    Returns
    -------
    int
        Number of samples kept.
    """
    n = theta.size
    step = (n + n_chunks - 1) // n_chunks
    counts = np.zeros(n_chunks, dtype=np.int64)
    for c in prange(n_chunks):
        s = c * step
        e = min(n, s + step)
        if s >= e:
            continue
        # slices from the interval before the chunk: indices from 0, so the
        # branch-free loop vectorises; hit[i] is interval s - 1 + i
        p0 = max(s, 1) - 1
        q = min(e, n - 1) + 1
        counts[c] = _chunk_keep(theta[p0:q], r[p0:q], rmin, rmax, reach, has_window,
                                centre, lo, hi, s - p0, keep[s:e])
    return counts.sum()


#: Golden-ratio conjugate: the sample positions of :func:`_hit_fraction` form a
#: Weyl sequence, which no periodic structure of the path (samples per revolution)
#: can alias with.
_GOLDEN = 0.6180339887498949


@njit(cache=CACHE, fastmath=FASTMATH)
def _hit_fraction(theta, r, n_tests, rmin, rmax, reach, has_window, centre, lo,
                  hi):  # pragma: no cover - numba
    """Fraction of ``n_tests`` well-spread intervals that can cut the rectangle.

    Parameters
    ----------
    theta, r : ndarray of shape (n,)
        Angle (rad) and radius (m); n >= 2.
    n_tests : int
        Intervals tested, at positions ``floor(frac(k g) (n - 1))`` for
        k = 0 .. n_tests - 1 with g the golden-ratio conjugate (a low-discrepancy
        sequence: even cover of the path, no alignment with a periodic sampling).
    rmin, rmax, reach, has_window, centre, lo, hi
        As for :func:`_crop_mask_chunked` (m, rad).

    Returns
    -------
    float
        Share of the tested intervals that hit, in [0, 1].
    """
    m = theta.size - 1
    hits = 0
    u = 0.0
    for _ in range(n_tests):
        i = min(int(u * m), m - 1)
        hits += _interval_hits(theta, r, i, rmin, rmax, reach, has_window, centre, lo,
                               hi)
        u += _GOLDEN
        if u >= 1.0:
            u -= 1.0
    return hits / n_tests
