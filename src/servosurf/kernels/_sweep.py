"""Numba kernels: lower envelope of a planar round-nose arc swept along a sampled path.

Geometry (all SI: m, rad)
-------------------------
The tool's cutting edge is a circular arc of radius ``radius`` (R) lying in the
radial-axial plane through the spindle axis and the tool. At time t the tool tip (the
lowest point of the arc) sits at radius r(t) and height z(t); the tool's angular
position in the workpiece frame is the unwrapped spindle angle Theta(t). A workpiece
point at polar position (r_p, theta_p) is touched when Theta(t) = theta_p + 2 pi k,
and then the edge height over it is

    h = z(t*) + R - sqrt(R**2 - (r_p - r(t*))**2) - c((r_p - r(t*)) / R)

for |r_p - r(t*)| <= ``half_width`` (= R sin(phi_max)); c is the optional tabulated
edge-waviness correction (below). The part of the arc that reaches across the spindle
axis touches the point when Theta(t) = theta_p + pi + 2 pi k with the signed radial
offset -r_p - r(t*) (the "mirror" family, only near the axis). The machined height is
the minimum over every crossing and the initial (pre-cut) height. t* is found by
linear interpolation between the two samples that bracket the target angle; sample
pairs flagged in ``gap`` (not consecutive in time) never bracket a crossing.

Buckets
-------
Targets theta_p + 2 pi j fall in "bucket" j = [theta_ref + 2 pi j, theta_ref + 2 pi
(j + 1)). ``_bucket_stats`` stores for every bucket the sample range that can bracket
its targets and bounds on r and z over that range, plus prefix and suffix hulls. One
crossing per point and bucket exists at most. A bucket whose bound
``z_lo + dr_min**2 / (2 R) - max(c)`` is not below the current height cannot lower it
(R - sqrt(R**2 - d**2) >= d**2 / (2 R)); this is what the pruned kernel uses.

Kernel layout follows stumpy's: private ``_name`` kernels take contiguous float64 or
int64 arrays and a preallocated ``out``; the checked public wrapper is
:func:`servosurf.toolpath.sweep`. Only the outermost kernels are ``parallel=True``;
each thread writes only its own rows of ``out``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._config import CACHE, FASTMATH

__all__ = [
    "N_STAT",
    "RLO",
    "RHI",
    "ZLO",
    "PRE_RLO",
    "PRE_RHI",
    "PRE_ZLO",
    "SUF_RLO",
    "SUF_RHI",
    "SUF_ZLO",
    "RMID",
    "TH_LO",
    "TH_HI",
    "TH_FIRST",
    "GSCALE",
    "ANCHOR",
    "T_SERIES",
    "_bucket_stats",
    "_crossing",
    "_row_polar",
    "_sweep_exhaustive",
    "_sweep_pruned",
    "_walk_pruned",
]

TWO_PI = 2.0 * np.pi

# Columns of the (n_buckets, N_STAT) bucket statistics array.
RLO, RHI, ZLO = 0, 1, 2
PRE_RLO, PRE_RHI, PRE_ZLO = 3, 4, 5
SUF_RLO, SUF_RHI, SUF_ZLO = 6, 7, 8
RMID = 9
TH_LO, TH_HI, TH_FIRST, GSCALE = 10, 11, 12, 13
N_STAT = 16


# The helpers below read the path and bucket arrays through flat row-major views
# (``pts.reshape(-1)`` etc., made once per kernel call) with unsigned indices: numba
# then neither multiplies by a run-time row stride nor emits its negative-index
# wraparound, which took 12 % of the facing kernel's CPU time on one thread
# (2026-11-24, fifth session; the indices here are never negative).
@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _pt(pts, i, k):  # pragma: no cover - numba
    """``pts[i, k]`` of the flat view of the (n, 4) interleaved path."""
    return pts[np.uint64(4 * i + k)]


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _bs(bstat, j, k):  # pragma: no cover - numba
    """``bstat[j, k]`` of the flat view of the (n_buckets, N_STAT) statistics."""
    return bstat[np.uint64(N_STAT * j + k)]


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _bi(bidx, j, k):  # pragma: no cover - numba
    """``bidx[j, k]`` of the flat view of the (n_buckets, 4) bucket ranges."""
    return bidx[np.uint64(4 * j + k)]


@njit(parallel=True, cache=CACHE, fastmath=FASTMATH)
def _bucket_stats(theta, r, z, gap, theta_ref, bidx, bstat):  # pragma: no cover - numba
    """Fill the per-revolution bucket index ranges and bounds.

    Parameters
    ----------
    theta : ndarray of shape (n,)
        Unwrapped tool angle in the workpiece frame, strictly increasing, in rad.
    r : ndarray of shape (n,)
        Tool-tip radius, in m.
    z : ndarray of shape (n,)
        Tool-tip height, in m.
    gap : ndarray of shape (n,), bool
        True where samples i and i + 1 are not consecutive in time.
    theta_ref : float
        Start angle of bucket 0, in rad; ``theta[0] - 2 pi < theta_ref <= theta[0]``.
    bidx : ndarray of shape (n_buckets, 4), int64
        Output: ``[lo, hi, first, last]``: the sample range whose intervals can
        bracket a target of bucket j (``theta[lo] <= target < theta[hi]`` for
        interior targets) and the first and last sample inside the bucket.
    bstat : ndarray of shape (n_buckets, N_STAT)
        Output: r and z bounds over ``lo..hi`` (m), prefix and suffix hulls, the
        mid radius ``RMID`` (m), ``theta[lo]``, ``theta[hi]``, ``theta[first]`` (rad)
        and the samples per rad ``GSCALE`` of the bucket (for the search guess).

    Notes
    -----
    ``n_buckets = floor((theta[-1] - theta_ref) / (2 pi)) + 1`` so that every sample
    belongs to a bucket. The bounds include the samples just outside the bucket, so
    any interpolated crossing of the bucket lies inside them. Buckets are filled in
    parallel (their sample ranges found by binary search); the prefix and suffix
    hulls follow serially.
    """
    n = theta.size
    nb = bidx.shape[0]
    for j in prange(nb):  # each bucket writes only its own rows
        start = theta_ref + TWO_PI * j
        end = theta_ref + TWO_PI * (j + 1)
        # i: first sample with theta >= start; k: first with theta >= end (or n)
        i = np.searchsorted(theta, start, side="left")
        k = np.searchsorted(theta, end, side="left")
        lo = i - 1 if i > 0 else 0
        hi = k if k < n else n - 1
        bidx[j, 0] = lo
        bidx[j, 1] = hi
        # Samples inside the bucket, for the interpolation guess of the search.
        bidx[j, 2] = i if i < k else lo
        bidx[j, 3] = k - 1 if i < k else hi
        # Bounds: a neighbour across a gap never brackets a crossing of this bucket.
        slo = lo + 1 if (gap[lo] and lo < i) else lo
        shi = hi - 1 if (gap[hi - 1] and hi > k - 1 and hi - 1 >= slo) else hi
        rlo = np.inf
        rhi = -np.inf
        zlo = np.inf
        for m in range(slo, shi + 1):
            if r[m] < rlo:
                rlo = r[m]
            if r[m] > rhi:
                rhi = r[m]
            if z[m] < zlo:
                zlo = z[m]
        bstat[j, RLO] = rlo
        bstat[j, RHI] = rhi
        bstat[j, ZLO] = zlo
        bstat[j, RMID] = 0.5 * (rlo + rhi)
        bstat[j, TH_LO] = theta[lo]
        bstat[j, TH_HI] = theta[hi]
        f0 = bidx[j, 2]
        f1 = bidx[j, 3]
        bstat[j, TH_FIRST] = theta[f0]
        bstat[j, GSCALE] = (f1 - f0) / (theta[f1] - theta[f0]) if f1 > f0 else 0.0
    rlo = np.inf
    rhi = -np.inf
    zlo = np.inf
    for j in range(nb):
        rlo = min(rlo, bstat[j, RLO])
        rhi = max(rhi, bstat[j, RHI])
        zlo = min(zlo, bstat[j, ZLO])
        bstat[j, PRE_RLO] = rlo
        bstat[j, PRE_RHI] = rhi
        bstat[j, PRE_ZLO] = zlo
    rlo = np.inf
    rhi = -np.inf
    zlo = np.inf
    for j in range(nb - 1, -1, -1):
        rlo = min(rlo, bstat[j, RLO])
        rhi = max(rhi, bstat[j, RHI])
        zlo = min(zlo, bstat[j, ZLO])
        bstat[j, SUF_RLO] = rlo
        bstat[j, SUF_RHI] = rhi
        bstat[j, SUF_ZLO] = zlo


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _bisect(theta, target, lo, hi):  # pragma: no cover - numba
    """Return i in [lo, hi - 1] with ``theta[i] <= target < theta[i + 1]``.

    Parameters
    ----------
    theta : ndarray of shape (n,)
        Strictly increasing angles, in rad.
    target : float
        Angle to bracket, in rad; requires ``theta[lo] <= target`` and
        (``target < theta[hi]`` or ``hi == n - 1``).
    lo, hi : int
        Search range (sample indices).

    Returns
    -------
    int
        Index of the bracketing interval's first sample.
    """
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if theta[np.uint64(mid)] <= target:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _height_at(i, target, rq, pts, radius, half_width, wav, wav_s0,
               wav_inv_ds):  # pragma: no cover - numba
    """Edge height over the query point for the crossing in interval i, in m.

    Parameters
    ----------
    i : int
        First sample of the bracketing interval.
    target : float
        Crossing angle, in rad.
    rq : float
        Signed radius of the query point in the arc's plane, in m.
    pts : ndarray of shape (4 n,)
        Flat view of the (n, 4) interleaved path: theta (rad), r (m), z (m) and
        ``1 / (theta[i + 1] - theta[i])`` (1/rad), which is 0.0 when samples i and
        i + 1 are not consecutive in time (a gap) and for the last sample.
    radius : float
        Nose radius R, in m.
    half_width : float
        Arc half-width R sin(phi_max), in m.
    wav : ndarray of shape (m,)
        Waviness correction c(s) in m on a uniform grid of s = dr / R (size < 2: none).
    wav_s0, wav_inv_ds : float
        First grid value of s and the inverse grid step.

    Returns
    -------
    float
        Height in m, ``+inf`` when the interval is a gap or the point is beyond the arc.

    Notes
    -----
    h = z + R - sqrt(R**2 - dr**2) - c(dr / R): the round-nose edge of the seed
    paper's tool (Table 2, R = 0.5 mm) as a circular arc in the radial-axial plane,
    not a sphere (a sphere misses the lenslet envelope by micrometres because the
    lenslet curvature along the cut is close to R; PAPER_NOTES.md).
    """
    inv_dt = _pt(pts, i, 3)
    if inv_dt == 0.0:
        return np.inf
    a = (target - _pt(pts, i, 0)) * inv_dt
    if a < 0.0:
        a = 0.0
    elif a > 1.0:
        a = 1.0
    r0 = _pt(pts, i, 1)
    rc = r0 + a * (_pt(pts, i + 1, 1) - r0)
    dr = rq - rc
    if abs(dr) > half_width:
        return np.inf
    z0 = _pt(pts, i, 2)
    zc = z0 + a * (_pt(pts, i + 1, 2) - z0)
    h = zc + (radius - np.sqrt(radius * radius - dr * dr))
    if wav.size > 1:
        u = (dr / radius - wav_s0) * wav_inv_ds
        k = int(u)
        if k < 0:
            k = 0
        elif k > wav.size - 2:
            k = wav.size - 2
        f = u - k
        h -= wav[k] + f * (wav[k + 1] - wav[k])
    return h


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _locate_guided(theta, pts, target, j, bidx, bstat):  # pragma: no cover - numba
    """Same result as :func:`_bisect` over the whole path, searched from a guess.

    Parameters
    ----------
    theta : ndarray of shape (n,)
        Strictly increasing angles, in rad.
    pts : ndarray of shape (4 n,)
        Flat view of the (n, 4) interleaved path (theta in column 0).
    target : float
        Angle to bracket, in rad, with ``theta[0] <= target <= theta[-1]``.
    j : int
        Bucket of the target.
    bidx, bstat : ndarray
        Flat views of the bucket ranges and statistics from :func:`_bucket_stats`.

    Returns
    -------
    int
        Index i with ``theta[i] <= target < theta[i + 1]`` (``n - 2`` at the end).
    """
    n = theta.size
    if target < _bs(bstat, j, TH_LO) or target >= _bs(bstat, j, TH_HI):
        return _bisect(theta, target, 0, n - 1)
    lo = _bi(bidx, j, 0)
    hi = _bi(bidx, j, 1)
    # Interpolation guess from the samples inside the bucket; uniform sampling lands
    # within one step.
    g = _bi(bidx, j, 2) + int((target - _bs(bstat, j, TH_FIRST))
                              * _bs(bstat, j, GSCALE))
    if g < lo:
        g = lo
    elif g > hi - 1:
        g = hi - 1
    for _ in range(4):
        if _pt(pts, g, 0) > target:
            g -= 1
        elif _pt(pts, g + 1, 0) <= target:
            g += 1
        else:
            return g
    return _bisect(theta, target, lo, hi)


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _envelope_exhaustive(phi, rq, h0, theta, pts, bidx, bstat, theta_ref, radius,
                         half_width, wav, wav_s0, wav_inv_ds, wav_bound,
                         slack):  # pragma: no cover - numba
    """Minimum height over every revolution that can cut below ``h0``, in m.

    Parameters
    ----------
    phi : float
        Angle of the query point (theta_p, or theta_p + pi for the mirror family), rad.
    rq : float
        Signed query radius (r_p, or -r_p for the mirror family), in m.
    h0 : float
        Pre-cut height at the point, in m.
    theta : ndarray of shape (n,)
        Path angle, in rad (contiguous, for binary searches).
    pts, radius, half_width, wav, wav_s0, wav_inv_ds : see :func:`_height_at`.
    bidx, bstat, theta_ref : see :func:`_bucket_stats` (flat views of the arrays).
    wav_bound : float
        Upper bound of the waviness correction, in m (0 without waviness).
    slack : float
        Rounding allowance subtracted from every bound, in m.

    Returns
    -------
    float
        The lowest height, in m.

    Notes
    -----
    Every bucket whose radius range lies within the arc reach and whose bound is below
    the pre-cut height is evaluated, each crossing located by a binary search over the
    whole path. No ordering and no early exit: the baseline for the pruned kernel.
    """
    n = theta.size
    nb = bidx.size // 4
    # Absolute revolution number of bucket 0's crossing: targets phi + 2 pi (m0 + j)
    # do not depend on theta_ref, so tiles reproduce whole-field runs bit for bit.
    m0 = np.ceil((theta_ref - phi) / TWO_PI)
    inv2r = 0.5 / radius
    t_first = theta[0]
    t_last = theta[n - 1]
    best = h0
    for j in range(nb):
        d = max(_bs(bstat, j, RLO) - rq, rq - _bs(bstat, j, RHI), 0.0)
        if d > half_width:
            continue
        if _bs(bstat, j, ZLO) + d * d * inv2r - wav_bound - slack >= h0:
            continue
        target = phi + TWO_PI * (m0 + j)
        if target < t_first or target > t_last:
            continue
        i = _bisect(theta, target, 0, n - 1)
        h = _height_at(i, target, rq, pts, radius, half_width, wav, wav_s0,
                       wav_inv_ds)
        if h < best:
            best = h
    return best


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _start_bucket(rq, rmid, direction, hint):  # pragma: no cover - numba
    """Bucket whose mid radius is nearest to ``rq``, walking from ``hint``.

    Parameters
    ----------
    rq : float
        Query radius, in m.
    rmid : ndarray of shape (n_buckets,)
        Mid radius of every bucket (column ``RMID`` of the bucket statistics,
        contiguous), in m.
    direction : int
        +1 / -1 when bucket mid radii increase / decrease, 0 when not monotone.
    hint : int
        Starting bucket (the previous point's), or -1 for a binary search.

    Returns
    -------
    int
        Start bucket (any bucket is correct; a near one prunes best).
    """
    nb = rmid.size
    if direction == 0:
        return 0
    j = hint
    if j < 0:
        lo = 0
        hi = nb
        while lo < hi:  # first bucket on the far side of rq
            mid = (lo + hi) >> 1
            v = rmid[mid]
            if (direction < 0 and v > rq) or (direction > 0 and v < rq):
                lo = mid + 1
            else:
                hi = mid
        j = lo if lo < nb else nb - 1
    while j + 1 < nb and abs(rmid[j + 1] - rq) < abs(rmid[j] - rq):
        j += 1
    while j > 0 and abs(rmid[j - 1] - rq) < abs(rmid[j] - rq):
        j -= 1
    return j


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _crossing(j, phi, m0, rq, theta, pts, bidx, bstat, radius, half_width, wav,
              wav_s0, wav_inv_ds):  # pragma: no cover - numba
    """Edge height over the query point at its crossing of bucket ``j``, in m.

    Parameters
    ----------
    j : int
        Bucket.
    phi, rq : float
        Query angle (rad) and signed query radius (m).
    m0 : float
        Revolution number of bucket 0's crossing, ``ceil((theta_ref - phi) / 2 pi)``.
    theta, pts, bidx, bstat, radius, half_width, wav, wav_s0, wav_inv_ds
        See :func:`_envelope_exhaustive`.

    Returns
    -------
    float
        Height in m; ``+inf`` when the crossing lies outside the path, in a gap or
        beyond the arc's reach.
    """
    target = phi + TWO_PI * (m0 + j)
    # common case first: inside the bucket's sample range, hence inside the path
    if not (target >= _bs(bstat, j, TH_LO) and target < _bs(bstat, j, TH_HI)):
        if target < theta[0] or target > theta[theta.size - 1]:
            return np.inf
    i = _locate_guided(theta, pts, target, j, bidx, bstat)
    return _height_at(i, target, rq, pts, radius, half_width, wav, wav_s0, wav_inv_ds)


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _walk_pruned(phi, m0, rq, best, j0, theta, pts, bidx, bstat, radius, half_width,
                 wav, wav_s0, wav_inv_ds, wav_bound, slack):  # pragma: no cover - numba
    """Lower ``best`` by the crossings of the buckets on both sides of ``j0``, in m.

    Parameters
    ----------
    phi, m0, rq : float
        Query angle (rad), revolution number of bucket 0 (see :func:`_crossing`) and
        signed query radius (m).
    best : float
        Running minimum, in m: the pre-cut height lowered by bucket ``j0``'s crossing.
    j0 : int
        Start bucket (nearest radius), already evaluated.
    theta, pts, bidx, bstat, radius, half_width, wav, wav_s0, wav_inv_ds,
    wav_bound, slack : see :func:`_envelope_exhaustive`.

    Returns
    -------
    float
        The lowest height, in m; with ``j0`` evaluated first, equal to
        :func:`_envelope_exhaustive`'s.

    Notes
    -----
    Walks from ``j0 + 1`` upwards and from ``j0 - 1`` downwards. Before each bucket,
    the bound over *all* remaining buckets in that direction (suffix or prefix hull of
    r, minimum of z) is compared with the running minimum; when it is not lower the
    walk stops. A bucket is evaluated only if its own bound is lower. Bounds never
    exceed the true heights (by more than ``slack``, far above the rounding), so the
    skipped crossings cannot change the minimum, and evaluating ``j0`` whatever its
    bound adds only a crossing that cannot be below a bound it does not beat: the
    result is the exhaustive kernel's, crossing for crossing.
    """
    nb = bidx.size // 4
    inv2r = 0.5 / radius
    j = j0 + 1
    while j < nb:
        d = max(_bs(bstat, j, SUF_RLO) - rq, rq - _bs(bstat, j, SUF_RHI), 0.0)
        if d > half_width:
            break
        if _bs(bstat, j, SUF_ZLO) + d * d * inv2r - wav_bound - slack >= best:
            break
        d = max(_bs(bstat, j, RLO) - rq, rq - _bs(bstat, j, RHI), 0.0)
        if (d <= half_width
                and _bs(bstat, j, ZLO) + d * d * inv2r - wav_bound - slack < best):
            h = _crossing(j, phi, m0, rq, theta, pts, bidx, bstat, radius, half_width,
                          wav, wav_s0, wav_inv_ds)
            if h < best:
                best = h
        j += 1
    j = j0 - 1
    while j >= 0:
        d = max(_bs(bstat, j, PRE_RLO) - rq, rq - _bs(bstat, j, PRE_RHI), 0.0)
        if d > half_width:
            break
        if _bs(bstat, j, PRE_ZLO) + d * d * inv2r - wav_bound - slack >= best:
            break
        d = max(_bs(bstat, j, RLO) - rq, rq - _bs(bstat, j, RHI), 0.0)
        if (d <= half_width
                and _bs(bstat, j, ZLO) + d * d * inv2r - wav_bound - slack < best):
            h = _crossing(j, phi, m0, rq, theta, pts, bidx, bstat, radius, half_width,
                          wav, wav_s0, wav_inv_ds)
            if h < best:
                best = h
        j -= 1
    return best


#: Columns between exact ``arctan2`` anchors of :func:`_row_polar` (absolute column
#: numbers, so tiles reproduce whole-field angles bit for bit).
ANCHOR = 32
#: Largest tangent of the angle from the anchor for which the series is used.
T_SERIES = 0.02


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _row_polar(y, x0, dx, col0, rps, phis):  # pragma: no cover - numba
    """Polar coordinates of one grid row.

    Parameters
    ----------
    y : float
        Row ordinate, in m.
    x0, dx : float
        Grid origin and pitch along x, in m.
    col0 : int
        Absolute column of ``rps[0]`` in the whole grid.
    rps, phis : ndarray of shape (nx,)
        Output: radius (m) and angle ``arctan2(y, x)`` (rad) of every column.

    Notes
    -----
    ``arctan2`` is evaluated exactly at anchor columns (every :data:`ANCHOR` absolute
    columns); in between, phi = phi_a + atan(t) with
    t = tan(phi - phi_a) = y (x_a - x) / (x_a x + y**2) and the Taylor series of atan
    to t**9 (truncation below t**11 / 11 = 2e-20 rad for |t| <= :data:`T_SERIES`).
    Points with a larger |t| (near the spindle axis) get the exact ``arctan2``. The
    angles agree with ``numpy.arctan2`` to a few ulp, and depend only on the absolute
    column, so any tiling gives the same bits.
    """
    nx = rps.size
    yy = y * y
    for col in range(nx):  # branch-free: vectorises
        x = x0 + (col0 + col) * dx
        rps[col] = np.sqrt(x * x + yy)
    a = col0 - col0 % ANCHOR  # anchor column of the first point
    while a < col0 + nx:
        xa = x0 + a * dx
        pa = np.arctan2(y, xa)
        c_lo = max(a, col0) - col0
        c_hi = min(a + ANCHOR, col0 + nx) - col0
        fallback = False
        for col in range(c_lo, c_hi):  # branch-free: vectorises
            x = x0 + (col0 + col) * dx
            den = xa * x + yy
            num = y * (xa - x)
            t = num / (den if den != 0.0 else 1.0)  # den == 0: fallback below
            t2 = t * t
            phis[col] = pa + t * (1.0 - t2 * (1.0 / 3.0 - t2 * (
                0.2 - t2 * (1.0 / 7.0 - t2 * (1.0 / 9.0)))))
            fallback |= not (den > 0.0 and abs(num) <= T_SERIES * den)
        if fallback:  # near the spindle axis: exact arctan2 where the series is off
            for col in range(c_lo, c_hi):
                x = x0 + (col0 + col) * dx
                den = xa * x + yy
                num = y * (xa - x)
                if not (den > 0.0 and abs(num) <= T_SERIES * den):
                    phis[col] = np.arctan2(y, x)
        a += ANCHOR


@njit(parallel=True, nogil=True, cache=CACHE, fastmath=FASTMATH)
def _sweep_exhaustive(theta, pts, bidx, bstat, theta_ref, radius, half_width,
                      wav, wav_s0, wav_inv_ds, wav_bound, slack, mirror_rmax, x0, dx,
                      col0, y0, dy, row0, out):  # pragma: no cover - numba
    """Lower envelope of the swept arc on a grid, every reaching revolution evaluated.

    Parameters
    ----------
    theta : ndarray of shape (n,)
        Unwrapped tool angle in the workpiece frame, rad, strictly increasing.
    pts : ndarray of shape (n, 4)
        The same path interleaved: theta (rad), tool-tip radius r (m), tool-tip
        height z (m, up = away from the work) and the inverse angle step to the next
        sample (1/rad; 0.0 across gaps, where samples are not consecutive in time).
    bidx, bstat : ndarray
        Bucket ranges and bounds from :func:`_bucket_stats`.
    theta_ref : float
        Start angle of bucket 0, in rad.
    radius : float
        Nose radius R, in m.
    half_width : float
        Arc half-width R sin(phi_max), in m.
    wav : ndarray of shape (m,)
        Edge-waviness correction in m on a uniform grid of s = dr / R (size < 2: none).
    wav_s0, wav_inv_ds : float
        First s of the waviness grid and inverse grid step (1).
    wav_bound : float
        max(0, max(wav)), in m.
    slack : float
        Rounding allowance of the bounds, in m.
    mirror_rmax : float
        Points with r_p <= mirror_rmax also meet the arc across the axis, in m.
    x0, dx, y0, dy : float
        Grid origin and pitch, in m: pixel (i, j) of ``out`` is at
        x = x0 + (col0 + j) dx, y = y0 + (row0 + i) dy.
    col0, row0 : int
        Offsets of ``out`` in a larger grid (tiles reproduce the whole grid's
        coordinates bit for bit).
    out : ndarray of shape (ny, nx)
        In: pre-cut heights in m (NaN = no workpiece, stays NaN; +inf = no material
        limit). Out: machined heights in m.

    Notes
    -----
    Implements the planar-arc envelope of the seed paper's lenslet cutting (section 4.2,
    Table 2: round diamond tool, R = 0.5 mm) for arbitrary sampled paths.
    """
    # flat views for the helpers' unsigned indexing (see _pt)
    pts = pts.reshape(pts.size)
    bidx = bidx.reshape(bidx.size)
    bstat = bstat.reshape(bstat.size)
    ny, nx = out.shape
    for row in prange(ny):
        y = y0 + (row0 + row) * dy
        rps = np.empty(nx)
        phis = np.empty(nx)
        _row_polar(y, x0, dx, col0, rps, phis)
        for col in range(nx):
            h0 = out[row, col]
            if np.isnan(h0):
                continue
            rp = rps[col]
            phi = phis[col]
            best = _envelope_exhaustive(phi, rp, h0, theta, pts, bidx, bstat,
                                        theta_ref, radius, half_width, wav, wav_s0,
                                        wav_inv_ds, wav_bound, slack)
            if rp <= mirror_rmax:
                hm = _envelope_exhaustive(phi + np.pi, -rp, h0, theta, pts, bidx,
                                          bstat, theta_ref, radius, half_width, wav,
                                          wav_s0, wav_inv_ds, wav_bound, slack)
                if hm < best:
                    best = hm
            out[row, col] = best


@njit(parallel=True, nogil=True, cache=CACHE, fastmath=FASTMATH)
def _sweep_pruned(theta, pts, bidx, bstat, rmid, theta_ref, radius, half_width, wav,
                  wav_s0, wav_inv_ds, wav_bound, slack, mirror_rmax, direction, x0, dx,
                  col0, y0, dy, row0, has_fill, fill, out):  # pragma: no cover - numba
    """Lower envelope of the swept arc on a grid, pruned by per-revolution bounds.

    Parameters
    ----------
    theta, pts, bidx, bstat, theta_ref, radius, half_width, wav, wav_s0,
    wav_inv_ds, wav_bound, slack, mirror_rmax, x0, dx, col0, y0, dy, row0, out
        As for :func:`_sweep_exhaustive` (``out`` is only written when
        ``has_fill``).
    rmid : ndarray of shape (n_buckets,)
        Contiguous copy of the bucket mid radii ``bstat[:, RMID]``, in m.
    direction : int
        +1 / -1 when bucket mid radii increase / decrease with the bucket index, 0
        otherwise (still exact, but without ordering the walk prunes less).
    has_fill : bool
        Write ``fill`` into each row of ``out`` before computing it (a uniform
        pre-cut height), instead of reading the pre-cut heights from ``out``.
    fill : float
        That height, in m (+inf: no material limit).

    Notes
    -----
    Same result as :func:`_sweep_exhaustive` (the tests check bit equality). For
    facing at feed f, only the passes within a few f of r_p are evaluated, instead of
    the 2 sqrt(2 R d) / f passes that reach the point at depth of cut d (about 70 at
    2 um/rev, 5 um depth, R = 0.5 mm; seed paper Table 2).

    Each row runs in four stages (polar coordinates, start buckets, the start
    bucket's crossing, the bounded walk) so that the first three are loops without
    data-dependent branches between points, which the CPU overlaps; the angles come
    from :func:`_row_polar` (exact ``arctan2`` every :data:`ANCHOR` columns and a
    series in between), shared with :func:`_sweep_exhaustive`.
    """
    # flat views for the helpers' unsigned indexing (see _pt)
    pts = pts.reshape(pts.size)
    bidx = bidx.reshape(bidx.size)
    bstat = bstat.reshape(bstat.size)
    ny, nx = out.shape
    for row in prange(ny):
        y = y0 + (row0 + row) * dy
        rps = np.empty(nx)
        phis = np.empty(nx)
        m0s = np.empty(nx)
        j0s = np.empty(nx, dtype=np.int64)
        if has_fill:  # uniform pre-cut height: written here, in cache
            for col in range(nx):
                out[row, col] = fill
        # Stage 1: polar coordinates and the revolution number of bucket 0.
        _row_polar(y, x0, dx, col0, rps, phis)
        for col in range(nx):
            m0s[col] = np.ceil((theta_ref - phis[col]) / TWO_PI)
        # Stage 2: start bucket (nearest mid radius), walking along the row.
        hint = -1
        for col in range(nx):
            hint = _start_bucket(rps[col], rmid, direction, hint)
            j0s[col] = hint
        # Stage 3: the start bucket's crossing, with no data-dependent branches
        # between points so that the CPU overlaps consecutive points.
        for col in range(nx):
            h = _crossing(j0s[col], phis[col], m0s[col], rps[col], theta, pts, bidx,
                          bstat, radius, half_width, wav, wav_s0, wav_inv_ds)
            if h < out[row, col]:  # False for NaN (no workpiece): stays NaN
                out[row, col] = h
        # Stage 4: the buckets around it that the bounds cannot exclude, and the
        # mirror family near the axis.
        hint_m = -1
        for col in range(nx):
            best = out[row, col]
            if np.isnan(best):
                continue
            rp = rps[col]
            phi = phis[col]
            best = _walk_pruned(phi, m0s[col], rp, best, j0s[col], theta, pts, bidx,
                                bstat, radius, half_width, wav, wav_s0, wav_inv_ds,
                                wav_bound, slack)
            if rp <= mirror_rmax:
                phm = phi + np.pi
                m0m = np.ceil((theta_ref - phm) / TWO_PI)
                hint_m = _start_bucket(-rp, rmid, direction, hint_m)
                h = _crossing(hint_m, phm, m0m, -rp, theta, pts, bidx, bstat, radius,
                              half_width, wav, wav_s0, wav_inv_ds)
                if h < best:
                    best = h
                best = _walk_pruned(phm, m0m, -rp, best, hint_m, theta, pts, bidx,
                                    bstat, radius, half_width, wav, wav_s0,
                                    wav_inv_ds, wav_bound, slack)
            out[row, col] = best
