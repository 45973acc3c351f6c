"""The 5 um lenslet cut in the loop (Fig. 17b) and the thrust-pressure calibration.

The seed paper's 5 um lenslets (Table 2): the tool follows
``z(t) = (A - d) - A sin(2 pi f t)`` with ``A`` = 10 um (zero to peak), ``d`` = 5 um,
``f`` = 100 Hz into a flat face at 0, with a 0.5 mm nose radius. The thrust force
``k_t A_chip(z)`` is computed every sample from the actual tool position inside the
closed loop (:class:`servosurf.cutting.ChipModel`), as ``servosurf simulate`` does.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy as sp

from ..cutting._cycle import cutting_cycle_stats
from ..cutting._force import ChipModel
from ..servo._loop import ServoLoop
from ..servo._machine import Machine
from ._structure import FIG13C_BANDWIDTH, HEAVY_MASS

__all__ = ["lenslet_cut", "solve_thrust_pressure", "LENS5"]

#: The paper's 5 um lenslet (Table 2): amplitude, depth (m), frequency (Hz), radius (m).
LENS5 = {"amplitude": 10e-6, "depth": 5e-6, "frequency": 100.0, "tool_radius": 0.5e-3}
#: Settling before the analysed cycles, s (as ``simulate``'s pre-roll).
SETTLE = 0.05


def lenslet_cut(
    loop: ServoLoop,
    thrust_pressure: float,
    *,
    amplitude: float = LENS5["amplitude"],
    depth: float = LENS5["depth"],
    frequency: float = LENS5["frequency"],
    tool_radius: float = LENS5["tool_radius"],
    periods: int = 8,
) -> dict[str, Any]:
    """Simulate repeated lenslet cuts in the loop; statistics of the last cycle.

    Parameters
    ----------
    loop : ServoLoop
        The closed loop.
    thrust_pressure : float
        Specific thrust pressure k_t, Pa.
    amplitude, depth : float
        Zero-to-peak servo amplitude and lenslet depth, m.
    frequency : float
        Servo frequency, Hz.
    tool_radius : float
        Nose radius, m.
    periods : int, default: 8
        Cycles simulated after the settling time.

    Returns
    -------
    dict
        :func:`~servosurf.cutting.cutting_cycle_stats` of the force-driven tool
        deviation (with the deepest-point lag and what the carrier sensor sees).
    """
    fs = loop.fs
    n = int(round((SETTLE + periods / frequency) * fs))
    t = np.arange(n) / fs
    z = (amplitude - depth) - amplitude * np.sin(2.0 * np.pi * frequency * t)
    base = loop.simulate(reference=z)
    tool0, sens0 = base["tool"].copy(), base["sensor"].copy()
    cut = loop.simulate(reference=z, chip=ChipModel(thrust_pressure, tool_radius, 0.0))
    k = int(SETTLE * fs)
    return cutting_cycle_stats(
        cut["force"][k:],
        cut["tool"][k:] - tool0[k:],
        fs=fs,
        frequency=frequency,
        command=z[k:],
        sensor=cut["sensor"][k:] - sens0[k:],
    )


def solve_thrust_pressure(
    machine: Machine, target: float = 295e-9, *, start: float = 1e9, rtol=1e-9
) -> float:
    """Thrust pressure (Pa) giving the paper's simulated peak deviation (Fig. 17b).

    Brent's method on ``log k_t`` at 1448 Hz, 0.175 kg (the cut's set-up).
    """
    heavy = machine.with_moving_mass(HEAVY_MASS)
    loop = ServoLoop(heavy.with_bandwidth(FIG13C_BANDWIDTH))

    def g(lk: float) -> float:
        return np.log(lenslet_cut(loop, float(np.exp(lk)))["deviation_max_m"] / target)

    a = np.log(start)
    lo, hi = a - 0.7, a + 0.7
    while g(lo) > 0:
        lo -= 0.7
    while g(hi) < 0:
        hi += 0.7
    return float(np.exp(sp.optimize.brentq(g, lo, hi, xtol=rtol, rtol=rtol)))
