"""Time-domain loop of the independent generator (own integrator, numba).

Discretisation (not servosurf's matrix exponential): the controller samples the
sensor at ``t_k = k T``, computes the Tustin PIDF output ``u[k]`` and the DAC holds
it from ``t_k + D T`` (``D`` = machine delay + extra delay, samples) as a true
transport delay: inside ``[t_k, t_k+1)`` the held value switches from
``u[k - nd - 1]`` to ``u[k - nd]`` at ``t_k + frac T`` (``D = nd + frac``). Each
piece is integrated in sub-steps:

* the current amplifier (critically damped double pole, Eq 5) exactly, with the
  closed form ``exp(A t) = exp(-w t) [[1 + w t, t], [-w^2 t, 1 - w t]]``;
* mechanics, sensor filter and hysteresis state with classical RK4, the amplifier
  current evaluated exactly at the stage times.

Forces (SI): the actuator ``Kf(x2) (I + i_n)`` on the carrier m2; the cutting
force ``k_t A(d) + k_e b(d)`` on the tool m1 from the actual depth
``d = -(x1 + z_off)`` below the flat face (``A`` the circular segment of the nose
arc, ``b`` its chord); the flexure between m2 and the carriage m3 with optional
sinh stiffening, Bouc-Wen or Dahl hysteresis and Coulomb (tanh) friction; an
optional appended mass on a spring at the tool; base displacement (noise, linearly
interpolated, plus analytic lines) through k3/c3 and k5/c5. The sensor filter
(Eq 7) sees the capacitive transducer's reading ``g(x_m)`` of the sensed DOF.
ADC and DAC quantisation round to their LSB.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from .machine import Controller, LinearExtras, Machine


@dataclass(frozen=True)
class LoopEffects:
    """Time-domain effects of the loop (all default: none). SI units.

    Attributes
    ----------
    linear : LinearExtras
        Appended mass, extra delay, small-signal flexure terms, Kf scale.
    sat_imax, sat_p : float
        Soft-knee current limit ``I = I_max x / (1 + |x|^p)^(1/p)``, ``x = I_dem /
        I_max`` (A, -); ``inf`` = none.
    kf_amp, kf_xc, kf_w : float
        ``Kf(x2) = Kf0 (1 + kf_amp g(x2))``, ``g(x) = (1 + (xc/w)^2) / (1 +
        ((x - xc)/w)^2) - 1``: a coil leaving a Lorentzian field profile (-, m, m).
    fl_amp, fl_w, fl_d0 : float
        Flexure stiffening ``F = fl_amp [sinh((d - d0)/w) + sinh(d0/w) -
        cosh(d0/w) d / w]`` on ``d = x2 - x3`` (N, m, m).
    hyst : int
        0 none, 1 Bouc-Wen ``F = h_k z``, ``z' = v - h_a |v| z - h_b v |z|``;
        2 Dahl ``F' = h_k v (1 - F sgn(v) / h_a)``; 3 LuGre friction (Canudas de
        Wit et al. 1995) ``F = h_k z``, ``z' = v - h_k |v| z / g(v)``, ``g(v) =
        h_a + (h_b - h_a) exp(-(v / fric_vs)^2)`` (bristle damping and viscous
        term zero).
    h_k, h_a, h_b : float
        Hysteresis parameters (N/m, 1/m, 1/m for Bouc-Wen; N/m, N for Dahl;
        bristle stiffness N/m, Coulomb and static force N for LuGre).
    fric_fc, fric_vs : float
        Coulomb friction ``F = fc tanh(v / vs)`` on the flexure velocity (N, m/s).
    sn_eps, sn_g0 : float
        Capacitive sensor reading ``x + eps g0 (1 / (1 - x / g0) - 1 - x / g0)``
        (-, m).
    adc_q : float
        ADC LSB as sensed position, m (0 = none).
    dac_q : float
        DAC LSB, V (0 = none).
    dac_dead : float
        Soft dead zone of the command ``u - b tanh(u / b)`` ahead of the DAC, V
        (0 = none).
    conv_trunc : bool
        Integer converters: the DAC code truncates toward zero and the ADC code
        floors (two's complement), instead of rounding to the nearest level.
    """

    linear: LinearExtras = field(default_factory=LinearExtras)
    sat_imax: float = math.inf
    sat_p: float = 2.0
    kf_amp: float = 0.0
    kf_xc: float = 0.0
    kf_w: float = 1.0
    fl_amp: float = 0.0
    fl_w: float = 1.0
    fl_d0: float = 0.0
    hyst: int = 0
    h_k: float = 0.0
    h_a: float = 0.0
    h_b: float = 0.0
    fric_fc: float = 0.0
    fric_vs: float = 1.0
    sn_eps: float = 0.0
    sn_g0: float = 1.0
    adc_q: float = 0.0
    dac_q: float = 0.0
    dac_dead: float = 0.0
    conv_trunc: bool = False


@dataclass(frozen=True)
class Chip:
    """Cutting-force model: ``F = kt A(d) + ke b(d)`` (Pa, N/m), nose radius (m).

    ``hold``: the force computed at each sample is held over the sample (a
    zero-order-hold force model, for comparison); default: the force follows the
    tool continuously inside the integrator.
    """

    kt: float
    radius: float
    ke: float = 0.0
    hold: bool = False


# parameter vector layout
_P = [
    "m1", "m2", "m3", "m4", "m5", "k1", "k2", "k3", "k4", "k5", "c1", "c2", "c3",
    "c4", "c5", "kr", "cr", "kf", "gi", "wa", "ws", "sdof", "sat_imax", "sat_p",
    "kf_amp", "kf_xc", "kf_w", "fl_amp", "fl_w", "fl_d0", "hyst", "h_k", "h_a",
    "h_b", "fric_fc", "fric_vs", "sn_eps", "sn_g0", "kt", "ke", "R", "chip",
    "chip_hold", "chip_held",
]
IDX = {n: i for i, n in enumerate(_P)}

#: RK4 sub-steps per held piece of the DAC output in the recordings. Measured on
#: the 5 um lenslet cut (tool height, 0.1-0.2 s, continuous chip force): 1 step
#: differs from 32 by 10 pm RMS at the lenslet harmonics (99.8/199.6/299.4 Hz),
#: 2 by 15 pm, 4 by 2.1 pm, 8 by 0.17 pm, 16 by 0.011 pm. With 1 step (used until
#: 2026-12-02) that error was the size of an ENR-0.1 effect on maps and ring
#: profiles, and the diagnosis fitted it on nulls; with 16 the air cut agrees with
#: ``ServoLoop.simulate`` to 0.02 pm and the cut with the diagnosis's model to 1 pm
#: (its first-order hold of the chip force).
NSUB = 16


@njit(cache=True)
def _rhs(X, cur, xg, vg, zoff, p, dX):
    x1, x2, x3, x4, x5 = X[0], X[1], X[2], X[3], X[4]
    v1, v2, v3, v4, v5 = X[5], X[6], X[7], X[8], X[9]
    y, yd, zh = X[10], X[11], X[12]
    kf = p[17]
    if p[24] != 0.0:
        xc, w = p[25], p[26]
        g = (1.0 + (xc / w) ** 2) / (1.0 + ((x2 - xc) / w) ** 2) - 1.0
        kf = kf * (1.0 + p[24] * g)
    fa = kf * cur
    fchip = 0.0
    if p[41] != 0.0:
        d = -(x1 + zoff)
        R = p[40]
        if d > 0.0:
            if d > R:
                d = R
            h = R - d
            s2 = 2.0 * R * d - d * d
            if s2 < 0.0:
                s2 = 0.0
            sq = math.sqrt(s2)
            area = R * R * math.acos(h / R) - h * sq
            fchip = p[38] * area + p[39] * 2.0 * sq
    if p[42] != 0.0 and p[41] != 0.0:
        fchip = p[43]  # the force of the last sample, held (a ZOH force model)
    d23 = x2 - x3
    v23 = v2 - v3
    fflex = p[6] * d23 + p[11] * v23
    if p[27] != 0.0:
        w, d0 = p[28], p[29]
        fflex += p[27] * (
            math.sinh((d23 - d0) / w) + math.sinh(d0 / w) - math.cosh(d0 / w) * d23 / w
        )
    dz = 0.0
    hk = int(p[30])
    if hk == 1:
        fflex += p[31] * zh
        dz = v23 - p[32] * abs(v23) * zh - p[33] * v23 * abs(zh)
    elif hk == 2:
        fflex += zh
        sg = 1.0 if v23 > 0.0 else (-1.0 if v23 < 0.0 else 0.0)
        dz = p[31] * v23 * (1.0 - zh * sg / p[32])
    elif hk == 3:
        fflex += p[31] * zh
        g = p[32] + (p[33] - p[32]) * math.exp(-((v23 / p[35]) ** 2))
        dz = v23 - p[31] * abs(v23) * zh / g
    if p[34] != 0.0:
        fflex += p[34] * math.tanh(v23 / p[35])
    f1 = fchip + p[5] * (x2 - x1) + p[10] * (v2 - v1)
    f5 = 0.0
    if p[4] > 0.0:
        fr = p[15] * (x5 - x1) + p[16] * (v5 - v1)
        f1 += fr
        f5 = -fr
    f2 = (
        fa
        - p[5] * (x2 - x1)
        - p[10] * (v2 - v1)
        - fflex
        - p[8] * (x2 - x4)
        - p[13] * (v2 - v4)
        + p[9] * (xg - x2)
        + p[14] * (vg - v2)
    )
    f3 = fflex + p[7] * (xg - x3) + p[12] * (vg - v3)
    f4 = p[8] * (x2 - x4) + p[13] * (v2 - v4)
    dX[0] = v1
    dX[1] = v2
    dX[2] = v3
    dX[3] = v4
    dX[4] = v5 if p[4] > 0.0 else 0.0
    dX[5] = f1 / p[0]
    dX[6] = f2 / p[1]
    dX[7] = f3 / p[2]
    dX[8] = f4 / p[3]
    dX[9] = f5 / p[4] if p[4] > 0.0 else 0.0
    xm = x2 if p[21] > 0.5 else x1
    if p[36] != 0.0:
        g0 = p[37]
        xm = xm + p[36] * g0 * (1.0 / (1.0 - xm / g0) - 1.0 - xm / g0)
    ws = p[20]
    dX[10] = yd
    dX[11] = ws * ws * (xm - y) - 2.0 * ws * yd
    dX[12] = dz
    return fchip


@njit(cache=True)
def _amp_step(i0, j0, c, w, t):
    """Exact amplifier state ``(I, dI/dt)`` a time t after (i0, j0), target c.

    ``I'' + 2 w I' + w^2 I = w^2 c`` with c constant: the deviation from c
    evolves with ``exp(A t) = exp(-w t) [[1 + w t, t], [-w^2 t, 1 - w t]]``.
    """
    e = math.exp(-w * t)
    d0 = i0 - c
    return (c + e * ((1.0 + w * t) * d0 + t * j0),
            e * (-w * w * t * d0 + (1.0 - w * t) * j0))


@njit(cache=True)
def _amp_at(i0, j0, c, w, t):
    """Amplifier current at time t after a step to target c from (i0, di/dt j0)."""
    return _amp_step(i0, j0, c, w, t)[0]


@njit(cache=True)
def _base(t, lf, la, lp):
    xg = 0.0
    vg = 0.0
    for j in range(lf.size):
        ph = 2.0 * math.pi * lf[j] * t + lp[j]
        xg += la[j] * math.cos(ph)
        vg -= la[j] * 2.0 * math.pi * lf[j] * math.sin(ph)
    return xg, vg


@njit(cache=True)
def _sim(p, ctrl, T, dtot, nsub, adc_q, dac_q, dac_dead, trunc, sens, r, nsen,
         icur, xgn, zoff, lf, la, lp, t0, out):
    n = r.size
    X = np.zeros(13)
    Xs = np.zeros(13)
    k1 = np.zeros(13)
    k2 = np.zeros(13)
    k3 = np.zeros(13)
    k4 = np.zeros(13)
    kp, ki, kd, tf = ctrl[0], ctrl[1], ctrl[2], ctrl[3]
    ad = (2.0 * tf - T) / (2.0 * tf + T)
    bd = 2.0 * kd / (2.0 * tf + T)
    integ = 0.0
    deriv = 0.0
    e_prev = 0.0
    nd = int(math.floor(dtot + 1e-12))
    frac = dtot - nd
    if frac < 1e-9:
        frac = 0.0
    buf = np.zeros(nd + 2)
    amp_i = 0.0
    amp_j = 0.0
    wa = p[19]
    gi = p[18]
    imax = p[22]
    sp = p[23]
    for k in range(n):
        # ---- sample and control
        y_meas = X[10] + nsen[k]
        if adc_q > 0.0:
            if trunc:
                y_meas = adc_q * math.floor(y_meas / adc_q)
            else:
                y_meas = adc_q * math.floor(y_meas / adc_q + 0.5)
        e = sens * (r[k] - y_meas)
        integ += 0.5 * T * ki * (e + e_prev)
        deriv = ad * deriv + bd * (e - e_prev)
        e_prev = e
        u = kp * e + integ + deriv
        if dac_dead > 0.0:
            u = u - dac_dead * math.tanh(u / dac_dead)
        if dac_q > 0.0:
            if trunc:
                u = dac_q * math.trunc(u / dac_q)
            else:
                u = dac_q * math.floor(u / dac_q + 0.5)
        for j in range(nd + 1, 0, -1):
            buf[j] = buf[j - 1]
        buf[0] = u
        # outputs at t_k
        out[0, k] = X[0]
        out[1, k] = y_meas
        out[2, k] = r[k] - y_meas
        out[3, k] = u
        xl0, vl0 = _base(t0 + k * T, lf, la, lp)
        hold = p[42]
        p[42] = 0.0
        out[4, k] = _rhs(X, amp_i + icur[k], xgn[k] + xl0, vl0, zoff[k], p, k4)
        p[42] = hold
        p[43] = out[4, k]
        # ---- integrate over [t_k, t_k+1)
        kn = k + 1 if k + 1 < n else k
        ia, ib = icur[k], icur[kn]
        ga, gb = xgn[k], xgn[kn]
        vgn = (gb - ga) / T
        for seg in range(2):
            if seg == 0:
                if frac == 0.0:
                    continue
                ua = buf[nd + 1]
                ta, tb = 0.0, frac * T
            else:
                ua = buf[nd]
                ta, tb = frac * T, T
            c = gi * ua
            if imax < 1e30:
                x = c / imax
                c = imax * x / (1.0 + abs(x) ** sp) ** (1.0 / sp)
            h = (tb - ta) / nsub
            for s in range(nsub):
                tau0 = ta + s * h
                # stage inputs at tau0, tau0 + h/2, tau0 + h
                for st in range(4):
                    if st == 0:
                        dt = 0.0
                    elif st == 3:
                        dt = h
                    else:
                        dt = 0.5 * h
                    tl = tau0 + dt
                    a = tl / T
                    cur = _amp_at(amp_i, amp_j, c, wa, dt) + ia + (ib - ia) * a
                    xg = ga + (gb - ga) * a
                    xl, vl = _base(t0 + k * T + tl, lf, la, lp)
                    if st == 0:
                        _rhs(X, cur, xg + xl, vgn + vl, zoff[k], p, k1)
                    elif st == 1:
                        for q in range(13):
                            Xs[q] = X[q] + 0.5 * h * k1[q]
                        _rhs(Xs, cur, xg + xl, vgn + vl, zoff[k], p, k2)
                    elif st == 2:
                        for q in range(13):
                            Xs[q] = X[q] + 0.5 * h * k2[q]
                        _rhs(Xs, cur, xg + xl, vgn + vl, zoff[k], p, k3)
                    else:
                        for q in range(13):
                            Xs[q] = X[q] + h * k3[q]
                        _rhs(Xs, cur, xg + xl, vgn + vl, zoff[k], p, k4)
                for q in range(13):
                    X[q] += h / 6.0 * (k1[q] + 2.0 * k2[q] + 2.0 * k3[q] + k4[q])
                # exact amplifier update over h
                amp_i, amp_j = _amp_step(amp_i, amp_j, c, wa, h)
        out[5, k] = amp_i


def param_vector(mach: Machine, eff: LoopEffects, chip: Chip | None) -> np.ndarray:
    """Kernel parameter vector (layout ``IDX``)."""
    ex = eff.linear
    p = np.zeros(len(_P))
    v = dict(
        m1=mach.m[0], m2=mach.m[1], m3=mach.m[2], m4=mach.m[3], m5=ex.mode_mass,
        k1=mach.k[0], k2=mach.k[1], k3=mach.k[2], k4=mach.k[3],
        k5=mach.k[4], c1=mach.c[0], c2=mach.c[1], c3=mach.c[2], c4=mach.c[3],
        c5=mach.c[4], kr=ex.mode_k, cr=ex.mode_c, kf=mach.kf * ex.kf_scale,
        gi=mach.gi, wa=mach.w_amp, ws=mach.w_sens, sdof=float(mach.sensor_dof),
        sat_imax=eff.sat_imax if math.isfinite(eff.sat_imax) else 1e300,
        sat_p=eff.sat_p, kf_amp=eff.kf_amp, kf_xc=eff.kf_xc, kf_w=eff.kf_w,
        fl_amp=eff.fl_amp, fl_w=eff.fl_w, fl_d0=eff.fl_d0, hyst=float(eff.hyst),
        h_k=eff.h_k, h_a=eff.h_a, h_b=eff.h_b, fric_fc=eff.fric_fc,
        fric_vs=eff.fric_vs, sn_eps=eff.sn_eps, sn_g0=eff.sn_g0,
    )
    if chip is not None:
        v.update(kt=chip.kt, ke=chip.ke, R=chip.radius, chip=1.0,
                 chip_hold=1.0 if chip.hold else 0.0)
    else:
        v.update(R=1.0)
    for k, val in v.items():
        p[IDX[k]] = val
    return p


def simulate(
    mach: Machine,
    ctrl: Controller,
    reference: np.ndarray,
    *,
    eff: LoopEffects | None = None,
    chip: Chip | None = None,
    sensor_noise: np.ndarray | None = None,
    current_noise: np.ndarray | None = None,
    base: np.ndarray | None = None,
    lines: tuple = (),
    zoff: np.ndarray | None = None,
    t0: float = 0.0,
    nsub: int = NSUB,
) -> dict:
    """Run the loop from rest over ``reference`` (m, one value per sample).

    Parameters
    ----------
    mach, ctrl : Machine, Controller
        Machine and installed controller.
    reference : ndarray of shape (n,)
        Commanded position, m.
    eff : LoopEffects, optional
        Effects in the loop.
    chip : Chip, optional
        Cutting-force model (the tool cuts a flat face at z = 0).
    sensor_noise, current_noise, base : ndarray of shape (n,), optional
        Noise sources at the controller rate: m, A, m (base displacement).
    lines : sequence of (f Hz, amplitude m, phase rad)
        Deterministic base-vibration lines ``a cos(2 pi f t + phase)``.
    zoff : ndarray of shape (n,), optional
        Tool height offset outside the loop (m) that changes the chip depth.
    t0 : float
        Absolute time of sample 0 (phase of the lines), s.
    nsub : int, default: NSUB
        RK4 sub-steps per held piece of the DAC output (``NSUB`` is converged to
        0.01 pm on a lenslet cut; fewer are for convergence tests).

    Returns
    -------
    dict of ndarray of shape (n,)
        ``tool`` (x1 at t_k, m), ``measured`` (m), ``fe`` (r - measured, m),
        ``u`` (V), ``force`` (chip force at t_k, N), ``current`` (A).
    """
    eff = eff or LoopEffects()
    r = np.ascontiguousarray(reference, dtype=float)
    n = r.size

    def arr(a):
        return np.zeros(n) if a is None else np.ascontiguousarray(a, dtype=float)

    p = param_vector(mach, eff, chip)
    ln = np.array([[f, a, ph] for f, a, ph in lines], dtype=float).reshape(-1, 3)
    out = np.zeros((6, n))
    ctrl_v = np.array([ctrl.kp, ctrl.ki, ctrl.kd, ctrl.tf])
    dtot = mach.delay + eff.linear.extra_delay * mach.fs
    if dtot < 0:
        raise ValueError(f"total loop delay must be >= 0 samples, got {dtot}")
    _sim(p, ctrl_v, 1.0 / mach.fs, dtot, int(nsub), eff.adc_q, eff.dac_q,
         eff.dac_dead, bool(eff.conv_trunc), mach.sens, r, arr(sensor_noise),
         arr(current_noise), arr(base), arr(zoff),
         np.ascontiguousarray(ln[:, 0]), np.ascontiguousarray(ln[:, 1]),
         np.ascontiguousarray(ln[:, 2]), float(t0), out)
    return {
        "tool": out[0],
        "measured": out[1],
        "fe": out[2],
        "u": out[3],
        "force": out[4],
        "current": out[5],
    }
