"""Numba kernel: sample-by-sample simulation of the discrete FTS loop.

Private: called by :meth:`servosurf.servo.ServoLoop.simulate`, which checks inputs.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._config import CACHE as _CACHE
from ._config import FASTMATH as _FASTMATH

__all__ = ["_closed_loop_sim", "_segment_area"]


@njit(cache=_CACHE, fastmath=_FASTMATH)
def _segment_area(radius, depth):
    """Area (m^2) of a circle of ``radius`` (m) below a chord at ``depth`` (m).

    The uncut chip cross-section of a round-nose tool plunged ``depth`` into a flat
    surface, in the radial-axial plane.
    """
    if depth <= 0.0:
        return 0.0
    if depth >= radius:
        depth = radius
    h = radius - depth
    return radius * radius * math.acos(h / radius) - h * math.sqrt(
        max(2.0 * radius * depth - depth * depth, 0.0)
    )


@njit(cache=_CACHE, fastmath=_FASTMATH)
def _closed_loop_sim(
    ad,
    bd,
    cy,
    ac,
    bc,
    cc,
    dc,
    sens,
    nd,
    frac,
    r,
    f,
    i_n,
    s_n,
    z_off,
    chip_kind,
    chip_par,
    out,
):
    """Simulate the discrete closed loop; fills ``out`` (5, n).

    Parameters
    ----------
    ad, bd, cy : ndarray
        ZOH-discretised analogue part (states 12), inputs [u, i_n, F], outputs
        [x1, filtered measured position].
    ac, bc, cc, dc : ndarray, ndarray, ndarray, float
        Tustin PIDF state space (error in V to DAC voltage).
    sens : float
        Sensor sensitivity S in V/m.
    nd, frac : int, float
        Delay in samples: integer part and fraction.
    r, f, i_n, s_n : ndarray of shape (n,)
        Reference (m), external force (N), current noise (A), sensor noise (m).
    z_off : ndarray of shape (n,)
        Offset (m) added to x1 for the chip model only (the commanded path when the
        loop is simulated about it, i.e. with tracking switched off).
    chip_kind : int
        0 no cutting; 1 plunge into a flat top: ``F += k_t * A(top - x1)``, with
        ``chip_par = [k_t (N/m^2), tool radius (m), top (m), unused]``.
    out : ndarray of shape (5, n)
        Rows: tool x1 (m), measured (m), following error (m), u (V), force (N).

    Notes
    -----
    Seed paper Fig. 5 loop; the chip force follows section 3.2.2 with the force
    computed from the actual (deviated) tool position.
    """
    n = r.shape[0]
    na = ad.shape[0]
    nc = ac.shape[0]
    xa = np.zeros(na)
    xa_new = np.zeros(na)
    xc = np.zeros(nc)
    xc_new = np.zeros(nc)
    nreg = nd + 2
    reg = np.zeros(nreg)
    for k in range(n):
        x1 = 0.0
        ym = 0.0
        for j in range(na):
            x1 += cy[0, j] * xa[j]
            ym += cy[1, j] * xa[j]
        ym += s_n[k]
        e = sens * (r[k] - ym)
        u = dc * e
        for j in range(nc):
            u += cc[j] * xc[j]
        for i in range(nc):
            acc = bc[i, 0] * e
            for j in range(nc):
                acc += ac[i, j] * xc[j]
            xc_new[i] = acc
        for i in range(nc):
            xc[i] = xc_new[i]
        for j in range(nreg - 1, 0, -1):
            reg[j] = reg[j - 1]
        reg[0] = u
        u_app = (1.0 - frac) * reg[nd]
        if frac > 0.0:
            u_app += frac * reg[nd + 1]
        force = f[k]
        if chip_kind == 1:
            force += chip_par[0] * _segment_area(
                chip_par[1], chip_par[2] - x1 - z_off[k]
            )
        for i in range(na):
            acc = bd[i, 0] * u_app + bd[i, 1] * i_n[k] + bd[i, 2] * force
            for j in range(na):
                acc += ad[i, j] * xa[j]
            xa_new[i] = acc
        for i in range(na):
            xa[i] = xa_new[i]
        out[0, k] = x1
        out[1, k] = ym
        out[2, k] = r[k] - ym
        out[3, k] = u
        out[4, k] = force
