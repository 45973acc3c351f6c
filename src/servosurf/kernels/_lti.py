"""Numba kernel: sample-by-sample simulation of the discrete FTS loop.

Private: called by :meth:`servosurf.servo.ServoLoop.simulate`, which checks inputs,
assembles the discrete model (ZOH analogue part, Tustin PIDF, delay registers) and
packs the nonlinearity vector (:class:`servosurf.servo.Nonlinearity`). This is the
one time-domain loop of servosurf: ``simulate``, ``diagnose`` and the benchmarks all
run it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._config import CACHE as _CACHE
from ._config import FASTMATH as _FASTMATH

__all__ = ["_closed_loop_sim", "_segment_area", "CX_ROWS"]

#: Rows of the output matrix ``cx`` the kernel reads: tool x1, sensor-filtered
#: measured position y, coil current I, carrier x2, carriage x3, carrier velocity v2,
#: carriage velocity v3 (SI).
CX_ROWS = ("x1", "y", "current", "x2", "x3", "v2", "v3")


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
    cx,
    ac,
    bc,
    cc,
    dc,
    sens,
    nd,
    r,
    f,
    i_n,
    s_n,
    z_off,
    chip_kind,
    chip_par,
    nl,
    bl,
    dt,
    out,
):
    """Simulate the discrete closed loop; fills ``out`` (6, n).

    Parameters
    ----------
    ad, bd : ndarray
        ZOH-discretised analogue part (amplifier, mechanics, sensor filter and any
        extra modes), shapes (na, na) and (na, 5); inputs ``[u[k - nd] (V), i (A),
        F (N on m1), u[k - nd - 1] (V), F[k + 1] - F[k] (N)]``: the two command
        columns split the sample at the DAC's update time (exact fractional
        delay); the last is the force's ramp over the sample (first-order hold).
    cx : ndarray of shape (7, na)
        Output rows, see :data:`CX_ROWS`.
    ac, bc, cc, dc : ndarray, ndarray, ndarray, float
        Tustin PIDF state space (error in V to DAC voltage); ``cc`` flattened.
    sens : float
        Sensor sensitivity S in V/m.
    nd : int
        Whole samples of the loop delay (its fraction is in ``bd``).
    r, f, i_n, s_n : ndarray of shape (n,)
        Reference (m), external force (N), current noise (A), sensor noise (m).
    z_off : ndarray of shape (n,)
        Offset (m) added to x1 for the chip model only (the commanded path when the
        loop is simulated about it, i.e. with tracking switched off).
    chip_kind : int
        0 no cutting; 1 plunge into a flat top: ``F += k_t * A(top - x1 - z_off)``
        with ``chip_par = [k_t (N/m^2), tool radius (m), top (m), unused]``.
    nl : ndarray of shape (16,)
        Nonlinearity parameters in the order of ``servo._perturb.NL_FIELDS``:
        command limit (V, 0 = none), Kf b1 (1/m), b2 (1/m^2), flexure k2q
        (N/m^2), k3 (N/m^3), sensor a2 (1/m), a3 (1/m^2), Coulomb level (N), its
        smoothing velocity (m/s), quadratic damping (N s^2/m^2), Bouc-Wen k (N/m),
        beta (1/m), gamma (1/m), DAC step (V), dead band (V), ADC step (m).
    bl : float
        Nominal force constant Kf0 in N/A (forces on m2 enter as currents).
    dt : float
        Controller period in s (integration of the hysteresis state).
    out : ndarray of shape (6, n)
        Rows: tool x1 (m), measured position (m), following error (m), DAC u (V),
        force on the tool (N), coil current (A).

    Notes
    -----
    Seed paper Fig. 5 loop; the chip force follows section 3.2.2 with the force
    computed from the actual (deviated) tool position. The force on the tool
    varies linearly between the samples (first-order hold): ``F[k + 1]`` depends
    on the tool position at ``k + 1``, which depends on ``F[k + 1]`` through the
    ramp column, so it is found by fixed-point iteration from ``F[k]`` (the
    contraction factor is ``Cx[0] Bd[:, 4]`` times the chip stiffness, about
    4e-6: three iterations reach rounding). The external force ``f`` is
    interpolated the same way (``f[n - 1]`` held over the last sample).
    Nonlinear forces on the carrier are evaluated from the state at the start of
    each sample and held over it (ZOH), like the command. With every
    nonlinearity off the arithmetic is exactly the linear loop's.
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
    sat = nl[0] > 0.0
    kf = nl[1] != 0.0 or nl[2] != 0.0
    flex = nl[3] != 0.0 or nl[4] != 0.0
    snl = nl[5] != 0.0 or nl[6] != 0.0
    fric = nl[7] > 0.0
    qdamp = nl[9] != 0.0
    bw = nl[10] != 0.0
    dac = nl[13] > 0.0
    dead = nl[14] > 0.0
    adc = nl[15] > 0.0
    state = kf or flex or fric or qdamp or bw
    zbw = 0.0
    # tool displacement per unit force ramp over one sample (m/N)
    q_ramp = 0.0
    for j in range(na):
        q_ramp += cx[0, j] * bd[j, 4]
    force = 0.0
    for k in range(n):
        x1 = 0.0
        ym = 0.0
        for j in range(na):
            x1 += cx[0, j] * xa[j]
            ym += cx[1, j] * xa[j]
        cur = 0.0
        x2 = 0.0
        x3 = 0.0
        v2 = 0.0
        v3 = 0.0
        if state:
            for j in range(na):
                v = xa[j]
                cur += cx[2, j] * v
                x2 += cx[3, j] * v
                x3 += cx[4, j] * v
                v2 += cx[5, j] * v
                v3 += cx[6, j] * v
        else:
            for j in range(na):
                cur += cx[2, j] * xa[j]
        if snl:
            ym = ym + nl[5] * ym * ym + nl[6] * ym * ym * ym
        ym += s_n[k]
        if adc:
            ym = nl[15] * math.floor(ym / nl[15] + 0.5)
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
        # the DAC: dead band, quantisation, saturation of the held command
        u_dac = u
        if dead:
            if abs(u_dac) <= nl[14]:
                u_dac = 0.0
            elif u_dac > 0.0:
                u_dac -= nl[14]
            else:
                u_dac += nl[14]
        if dac:
            u_dac = nl[13] * math.floor(u_dac / nl[13] + 0.5)
        if sat:
            if u_dac > nl[0]:
                u_dac = nl[0]
            elif u_dac < -nl[0]:
                u_dac = -nl[0]
        for j in range(nreg - 1, 0, -1):
            reg[j] = reg[j - 1]
        reg[0] = u_dac
        u_new = reg[nd]
        u_old = reg[nd + 1]
        if k == 0:
            force = f[0]
            if chip_kind == 1:
                force += chip_par[0] * _segment_area(
                    chip_par[1], chip_par[2] - x1 - z_off[0]
                )
        i_eq = i_n[k]
        if state:
            extra = 0.0
            if kf:
                i_eq += (nl[1] * x2 + nl[2] * x2 * x2) * (cur + i_n[k])
            if flex:
                d = x2 - x3
                extra -= nl[3] * d * d + nl[4] * d * d * d
            if fric:
                extra -= nl[7] * math.tanh(v2 / nl[8])
            if qdamp:
                extra -= nl[9] * abs(v2) * v2
            if bw:
                extra -= nl[10] * zbw
                vr = v2 - v3
                zbw += dt * (vr - nl[11] * abs(vr) * zbw - nl[12] * vr * abs(zbw))
            i_eq += extra / bl
        for i in range(na):
            acc = (bd[i, 0] * u_new + bd[i, 3] * u_old + bd[i, 1] * i_eq
                   + bd[i, 2] * force)
            for j in range(na):
                acc += ad[i, j] * xa[j]
            xa_new[i] = acc
        # the force at the next sample (first-order hold over this one)
        kn = k + 1 if k + 1 < n else k
        f_next = f[kn]
        if chip_kind == 1:
            x1p = 0.0
            for j in range(na):
                x1p += cx[0, j] * xa_new[j]
            fn = force
            for _it in range(3):
                fn = f_next + chip_par[0] * _segment_area(
                    chip_par[1],
                    chip_par[2] - (x1p + q_ramp * (fn - force)) - z_off[kn],
                )
            f_next = fn
        dfo = f_next - force
        for i in range(na):
            xa[i] = xa_new[i] + bd[i, 4] * dfo
        out[0, k] = x1
        out[1, k] = ym
        out[2, k] = r[k] - ym
        out[3, k] = u
        out[4, k] = force
        out[5, k] = cur
        force = f_next
