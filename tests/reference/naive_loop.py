"""Plain-numpy closed loop: the oracle of the numba loop kernel (``kernels/_lti.py``).

Written from the loop's description (seed paper Fig. 5, ``servo/_loop.py`` and
``servo/_perturb.py`` docstrings), one sample at a time with matrix products and
named nonlinearity fields (it never reads the kernel's parameter vector), so a
wrong packing, index or branch in the kernel shows as a difference. It takes the
discrete model (ZOH analogue part, Tustin PIDF) from
:meth:`servosurf.servo.ServoLoop.discrete_models`; that discretisation is checked
separately against the frequency-domain model.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["closed_loop"]


def _chip_area(radius: float, depth: float) -> float:
    """Circular segment below a chord ``depth`` into a circle (m^2), by integration.

    Numerical quadrature of the chord width, not the closed form the kernel uses.
    """
    if depth <= 0:
        return 0.0
    depth = min(depth, radius)
    z = np.linspace(0.0, depth, 20001)  # height above the lowest point of the arc
    width = 2 * np.sqrt(np.maximum(radius**2 - (radius - z) ** 2, 0.0))
    return float(np.trapezoid(width, z))


def closed_loop(loop, *, reference, force=None, current_noise=None,
                sensor_noise=None, chip=None, chip_offset=None, perturbation=None,
                nonlinearity=None):
    """Simulate ``loop`` sample by sample; returns the kernel's six outputs.

    Parameters are those of :meth:`servosurf.servo.ServoLoop.simulate` (SI);
    ``chip`` is a :class:`servosurf.cutting.ChipModel`.

    Returns
    -------
    dict of str to ndarray
        ``tool``, ``sensor``, ``following_error``, ``u``, ``force``, ``current``.
    """
    lp = loop.perturbed(perturbation)
    mach = lp.machine
    ad, bd, cx, ac, bc, cc, dc = lp.discrete_models()
    cc = np.asarray(cc).ravel()
    dc = float(np.asarray(dc).ravel()[0])
    nd = int(math.floor(mach.controller.delay))
    n = len(reference)
    z = np.zeros(n)
    f_ext = z if force is None else np.asarray(force, float)
    i_n = z if current_noise is None else np.asarray(current_noise, float)
    s_n = z if sensor_noise is None else np.asarray(sensor_noise, float)
    z_off = z if chip_offset is None else np.asarray(chip_offset, float)
    nl = nonlinearity
    bl = mach.actuator.force_constant
    gi = mach.actuator.current_gain
    s_gain = mach.sensor.sensitivity
    dt = 1.0 / mach.controller.sample_rate
    ramp = _force_ramp(lp, dt)
    tool_row = cx[0]
    xa = np.zeros(ad.shape[0])
    xc = np.zeros(ac.shape[0])
    history = [0.0] * (nd + 2)  # history[j] = u[k - j]
    hyst = 0.0
    out = {k: np.zeros(n) for k in ("tool", "sensor", "following_error", "u",
                                    "force", "current")}
    for k in range(n):
        x1, y, cur, x2, x3, v2, v3 = cx @ xa
        reading = y
        if nl is not None:
            reading = y + nl.sensor_a2 * y**2 + nl.sensor_a3 * y**3
        reading += s_n[k]
        if nl is not None and nl.adc_step > 0:
            reading = nl.adc_step * np.floor(reading / nl.adc_step + 0.5)
        e = s_gain * (reference[k] - reading)
        u = float(cc @ xc) + dc * e
        xc = ac @ xc + bc[:, 0] * e
        held = u  # what the DAC and the amplifier make of the command
        if nl is not None:
            if nl.dac_dead_band > 0:
                b = nl.dac_dead_band
                held = 0.0 if abs(held) <= b else held - math.copysign(b, held)
            if nl.dac_step > 0:
                held = nl.dac_step * np.floor(held / nl.dac_step + 0.5)
            if math.isfinite(nl.max_current):
                limit = nl.max_current / gi
                held = min(max(held, -limit), limit)
        history = [held] + history[:-1]
        # the DAC updates frac of a sample late: the older command is held over
        # the sample's first part, the newer over the rest (two columns of bd)
        newer, older = history[nd], history[nd + 1]
        if k == 0:
            tool_force = f_ext[0] + _chip_force(chip, x1, z_off[0])
        carrier_force = 0.0  # N on m2 besides the motor's
        current_error = 0.0  # A: the force constant's position dependence
        if nl is not None:
            current_error = (nl.kf_b1 * x2 + nl.kf_b2 * x2**2) * (cur + i_n[k])
            defl = x2 - x3
            carrier_force -= nl.flexure_k2 * defl**2 + nl.flexure_k3 * defl**3
            carrier_force -= nl.friction * np.tanh(v2 / nl.friction_velocity)
            carrier_force -= nl.quadratic_damping * abs(v2) * v2
            carrier_force -= nl.bouc_wen_stiffness * hyst
            rate = v2 - v3
            hyst += dt * (rate - nl.bouc_wen_beta * abs(rate) * hyst
                          - nl.bouc_wen_gamma * rate * abs(hyst))
        i_total = i_n[k] + current_error + carrier_force / bl
        held_part = ad @ xa + bd[:, :4] @ np.array([newer, i_total, tool_force, older])
        # the force on the tool ramps linearly to its value at the next sample,
        # which depends on where the ramp puts the tool: solved by iteration
        j = min(k + 1, n - 1)
        nxt = f_ext[j]
        for _ in range(30):
            x1_next = tool_row @ (held_part + ramp * (nxt - tool_force))
            nxt = f_ext[j] + _chip_force(chip, x1_next, z_off[j])
        for key, v in (("tool", x1), ("sensor", reading),
                       ("following_error", reference[k] - reading), ("u", u),
                       ("force", tool_force), ("current", cur)):
            out[key][k] = v
        xa = held_part + ramp * (nxt - tool_force)
        tool_force = nxt
    return out


def _chip_force(chip, x1: float, offset: float) -> float:
    """Chip thrust (N) at tool height ``x1`` (m) and chip offset (m)."""
    if chip is None:
        return 0.0
    return chip.thrust_pressure * _chip_area(chip.tool_radius, chip.top - x1 - offset)


def _force_ramp(loop, dt: float) -> np.ndarray:
    """State after one sample of a tool force ramping from 0 to 1 N (first-order
    hold), ``int_0^dt exp(A (dt - s)) B_F s / dt ds``, by 64-point Gauss-Legendre
    quadrature of the matrix exponential (not the augmented-matrix formula the
    loop uses)."""
    import scipy.linalg

    a, b, _c = loop.analogue_ss()
    b_force = b[:, 2]
    nodes, weights = np.polynomial.legendre.leggauss(64)
    s = 0.5 * dt * (nodes + 1.0)
    acc = np.zeros(a.shape[0])
    for si, wi in zip(s, weights, strict=True):
        acc += wi * (scipy.linalg.expm(a * (dt - si)) @ b_force) * si / dt
    return 0.5 * dt * acc
