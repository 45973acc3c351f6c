"""Numba kernels of the diagnosis simulator (private).

Called by :mod:`servosurf.diagnose._sim`, which validates inputs and allocates
outputs. Kernels take contiguous float64 arrays and scalars only.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..kernels._config import CACHE as _CACHE
from ..kernels._config import FASTMATH as _FASTMATH
from ..kernels._lti import _segment_area  # the chip section, shared

__all__ = ["_nl_loop", "_segment_area"]


@njit(cache=_CACHE, fastmath=_FASTMATH)
def _nl_loop(
    ad,
    bd,
    cx,
    ac,
    bc,
    cc,
    dc,
    sens,
    nd,
    frac,
    r,
    f_ext,
    i_n,
    s_n,
    chip_kt,
    chip_radius,
    chip_top,
    chip_area,
    u_max,
    kf_b1,
    kf_b2,
    flex_k2,
    flex_k3,
    bl,
    sat_on,
    out,
):
    """Simulate the discrete FTS loop with memoryless nonlinear modules.

    Parameters
    ----------
    ad, bd : ndarray
        ZOH-discretised analogue part, shape (n, n) and (n, 3); inputs
        ``[u (V), i_eq (A), F (N on m1)]``.
    cx : ndarray of shape (5, n)
        Output rows: tool x1 (m), filtered measured position (m), coil current I
        (A), carrier x2 (m), carriage x3 (m).
    ac, bc, cc, dc : ndarray, ndarray, ndarray, float
        Tustin PIDF (error in V to DAC volts).
    sens : float
        Sensor sensitivity S in V/m.
    nd, frac : int, float
        Delay: whole samples and fraction.
    r, f_ext, i_n, s_n : ndarray of shape (N,)
        Reference (m), external force (N), current noise (A), sensor noise (m).
    chip_kt, chip_radius, chip_top, chip_area : float
        Chip force ``kt * A``: with ``chip_area < 0`` the area is the circular
        segment of ``chip_radius`` below ``chip_top`` (lenslet plunge); otherwise
        the constant area ``chip_area`` (m^2) while the tool is below ``chip_top``.
    u_max : float
        Saturation of the DAC command in V (current demand ``G_I u``), when
        ``sat_on``.
    kf_b1, kf_b2 : float
        Force constant ``Kf(x2) = Kf0 (1 + b1 x2 + b2 x2^2)`` (1/m, 1/m^2).
    flex_k2, flex_k3 : float
        Flexure force ``-(k2q d^2 + k3 d^3)`` on m2, ``d = x2 - x3`` (N/m^2, N/m^3).
    bl : float
        Nominal force constant Kf0 in N/A (to express forces as currents).
    sat_on : int
        1 to clip the command at ``u_max``.
    out : ndarray of shape (6, N)
        Rows: tool x1 (m), measured position (m), following error (m), DAC u (V),
        force on the tool (N), coil current (A).

    Notes
    -----
    Explicit treatment: the nonlinear forces are evaluated from the state at the
    start of each sample and held (ZOH) like the command.
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
    nonlin = kf_b1 != 0.0 or kf_b2 != 0.0 or flex_k2 != 0.0 or flex_k3 != 0.0
    for k in range(n):
        x1 = 0.0
        ym = 0.0
        cur = 0.0
        x2 = 0.0
        x3 = 0.0
        for j in range(na):
            v = xa[j]
            x1 += cx[0, j] * v
            ym += cx[1, j] * v
            cur += cx[2, j] * v
            x2 += cx[3, j] * v
            x3 += cx[4, j] * v
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
        if sat_on == 1:
            if u_app > u_max:
                u_app = u_max
            elif u_app < -u_max:
                u_app = -u_max
        force = f_ext[k]
        if chip_kt != 0.0:
            if chip_area < 0.0:
                force += chip_kt * _segment_area(chip_radius, chip_top - x1)
            elif x1 < chip_top:
                force += chip_kt * chip_area
        i_eq = i_n[k]
        if nonlin:
            d = x2 - x3
            i_eq += (kf_b1 * x2 + kf_b2 * x2 * x2) * (cur + i_n[k])
            i_eq -= (flex_k2 * d * d + flex_k3 * d * d * d) / bl
        for i in range(na):
            acc = bd[i, 0] * u_app + bd[i, 1] * i_eq + bd[i, 2] * force
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
        out[5, k] = cur
