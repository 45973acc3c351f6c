"""Numba kernel: the swept round-nose arc applied pass by pass, in time order.

The envelope kernels of :mod:`servosurf.kernels._sweep` take the minimum over every
pass of the edge height: the order of the passes does not matter. Material rules
that depend on what an earlier pass left make it matter; this kernel visits, for
every grid point, each crossing of the tool with the point in time order (the
unwrapped spindle angle of the crossing, which increases with time) and updates the
point's height ``s`` with the rules below. Geometry, crossings, buckets and the edge
height ``z_e`` are those of :mod:`servosurf.kernels._sweep` (the same helpers, so
with every rule off the result is the envelope kernel's, bit for bit).

Rules (all heights in m, ``h = s - z_e`` the uncut thickness along z)
-------------------------------------------------------------------
* **Cut** when ``h > h_min``: ``s <- z_e + rho(h)``. ``h_min`` is the minimum chip
  thickness (0: every contact cuts). ``rho(h) = min(h, d0 exp(-h / h_d))`` is the
  elastic recovery of the cut surface, largest where the chip thins out
  (``d0 = 0``: none).
* **Plough** when ``0 < h <= h_min``: the pass leaves the material (Brammertz's
  rule: the uncut sliver at the feed-mark ridge stays).
* **Side flow**: when the pass does not cut the point (``h <= h_min``), material
  pushed sideways from the thin end of the chip piles up beyond the cut boundary as
  a ridge ``a (1 - d / b)`` for a lateral distance ``d < b`` from the boundary.
  ``d = (h_min - h) / |sigma_e - sigma_s|``: the thickness deficit over the
  difference of the edge slope ``sigma_e`` and the surface slope ``sigma_s`` along the
  radius (the slope of the edge of the pass that last cut the point, 0 for a
  never-cut point). Two arcs of one radius differ by a linear function of the
  radius, so for parabolic arcs ``d`` is exact.

Slopes are ``(r_p - r_c) / R`` (the parabolic arc; the exact slope differs by
``(dr / R)**2 / 2``, 1e-5 within a 2 um feed of a 0.5 mm nose).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._config import CACHE, FASTMATH
from ._sweep import (
    RHI,
    RLO,
    TH_HI,
    TH_LO,
    ZLO,
    _bs,
    _height_at,
    _locate_guided,
    _pt,
    _row_polar,
)

__all__ = ["N_RULES", "_sweep_ordered"]

TWO_PI = 2.0 * np.pi

#: Length of the ``rules`` array: h_min, side-flow height, side-flow width,
#: recovery at zero thickness, recovery decay thickness (all m).
N_RULES = 5


@njit(cache=CACHE, fastmath=FASTMATH, inline="always")
def _locate(j, phi, m0, theta, pts, bidx, bstat):  # pragma: no cover - numba
    """Bracketing interval of the crossing of bucket ``j`` (or -1 outside the path).

    Parameters
    ----------
    j : int
        Bucket.
    phi, m0 : float
        Query angle (rad) and revolution number of bucket 0's crossing.
    theta, pts, bidx, bstat : ndarray
        As for :func:`servosurf.kernels._sweep._crossing` (flat views).

    Returns
    -------
    i : int
        First sample of the interval, -1 when the crossing lies outside the path.
    target : float
        Crossing angle, in rad.
    """
    target = phi + TWO_PI * (m0 + j)
    if not (target >= _bs(bstat, j, TH_LO) and target < _bs(bstat, j, TH_HI)):
        if target < theta[0] or target > theta[theta.size - 1]:
            return -1, target
    return _locate_guided(theta, pts, target, j, bidx, bstat), target


@njit(parallel=True, nogil=True, cache=CACHE, fastmath=FASTMATH)
def _sweep_ordered(theta, pts, bidx, bstat, theta_ref, radius, half_width, wav,
                   wav_s0, wav_inv_ds, wav_bound, slack, mirror_rmax, x0, dx, col0, y0,
                   dy, row0, has_fill, fill, rules, out):  # pragma: no cover - numba
    """Machined heights with time-ordered material rules, on a grid.

    Parameters
    ----------
    theta, pts, bidx, bstat, theta_ref, radius, half_width, wav, wav_s0,
    wav_inv_ds, wav_bound, slack, mirror_rmax, x0, dx, col0, y0, dy, row0
        As for :func:`servosurf.kernels._sweep._sweep_exhaustive`.
    has_fill : bool
        Start every point from ``fill`` instead of reading ``out``.
    fill : float
        Uniform pre-cut height, in m (+inf: no material limit).
    rules : ndarray of shape (N_RULES,)
        ``[h_min, a, b, d0, h_d]`` in m: minimum chip thickness, side-flow ridge
        height and half-width, recovery at zero thickness and its decay thickness
        (see the module docstring; zeros switch a rule off).
    out : ndarray of shape (ny, nx)
        In: pre-cut heights in m (NaN: no workpiece, stays NaN); out: machined
        heights in m.

    Notes
    -----
    Every bucket whose radius range lies within the arc's reach is visited in time
    order (the direct and the across-the-axis family merged by crossing angle); a
    bucket whose lower height bound stays above the current height plus the widest
    gap at which side flow still deposits cannot change the point and is skipped.
    """
    pts = pts.reshape(pts.size)
    bidx = bidx.reshape(bidx.size)
    bstat = bstat.reshape(bstat.size)
    nb = bidx.size // 4
    ny, nx = out.shape
    inv2r = 0.5 / radius
    inv_r = 1.0 / radius
    h_min = rules[0]
    flow_a = rules[1]
    flow_b = rules[2]
    rec_d0 = rules[3]
    rec_hd = rules[4]
    flow = flow_a > 0.0 and flow_b > 0.0
    recovery = rec_d0 > 0.0 and rec_hd > 0.0
    # side flow reaches gaps up to b |sigma_e - sigma_s| <= 2 b sin(phi_max)
    gap_allow = 2.0 * flow_b * half_width * inv_r if flow else 0.0
    for row in prange(ny):
        y = y0 + (row0 + row) * dy
        rps = np.empty(nx)
        phis = np.empty(nx)
        _row_polar(y, x0, dx, col0, rps, phis)
        for col in range(nx):
            s = fill if has_fill else out[row, col]
            if np.isnan(s):
                out[row, col] = s
                continue
            rp = rps[col]
            phi = phis[col]
            m0 = np.ceil((theta_ref - phi) / TWO_PI)
            phm = phi + np.pi
            m0m = np.ceil((theta_ref - phm) / TWO_PI)
            j = 0
            jm = 0 if rp <= mirror_rmax else nb
            sig_s = 0.0
            while j < nb or jm < nb:
                td = phi + TWO_PI * (m0 + j) if j < nb else np.inf
                tm = phm + TWO_PI * (m0m + jm) if jm < nb else np.inf
                if td <= tm:
                    jj = j
                    j += 1
                    q = rp
                    ph = phi
                    mq = m0
                    sign = 1.0
                else:
                    jj = jm
                    jm += 1
                    q = -rp
                    ph = phm
                    mq = m0m
                    sign = -1.0
                d = max(_bs(bstat, jj, RLO) - q, q - _bs(bstat, jj, RHI), 0.0)
                if d > half_width:
                    continue
                if _bs(bstat, jj, ZLO) + d * d * inv2r - wav_bound - slack >= \
                        s + gap_allow:
                    continue
                i, target = _locate(jj, ph, mq, theta, pts, bidx, bstat)
                if i < 0:
                    continue
                ze = _height_at(i, target, q, pts, radius, half_width, wav, wav_s0,
                                wav_inv_ds)
                if not ze < np.inf:  # a gap, or beyond the arc
                    continue
                h = s - ze
                if h > h_min:
                    rec = 0.0
                    if recovery:
                        rec = rec_d0 * np.exp(-h / rec_hd)
                        if rec > h:
                            rec = h
                    s = ze + rec
                    if flow:
                        a = (target - _pt(pts, i, 0)) * _pt(pts, i, 3)
                        r0 = _pt(pts, i, 1)
                        rc = r0 + min(max(a, 0.0), 1.0) * (_pt(pts, i + 1, 1) - r0)
                        sig_s = sign * (q - rc) * inv_r
                elif flow:
                    a = (target - _pt(pts, i, 0)) * _pt(pts, i, 3)
                    r0 = _pt(pts, i, 1)
                    rc = r0 + min(max(a, 0.0), 1.0) * (_pt(pts, i + 1, 1) - r0)
                    dsig = abs(sign * (q - rc) * inv_r - sig_s)
                    if dsig > 0.0:
                        dist = (h_min - h) / dsig
                        if dist < flow_b:
                            s += flow_a * (1.0 - dist / flow_b)
            out[row, col] = s
