"""Statistics of one lenslet cutting cycle: peak deviation, overshoot and lags.

One implementation used by the surface analysis (``servosurf simulate`` and the
``paper`` rows) and by the calibration of the thrust pressure, so that both read the
same number off the same record (seed paper section 5.3, Fig. 17b).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["cutting_cycle_stats"]


def cutting_cycle_stats(
    force: np.ndarray,
    deviation: np.ndarray,
    *,
    fs: float,
    frequency: float,
    command: np.ndarray | None = None,
    sensor: np.ndarray | None = None,
) -> dict[str, Any]:
    """Peak, overshoot and lags of the force-driven deviation in the last full cycle.

    Parameters
    ----------
    force : ndarray of shape (n,)
        Thrust force on the tool, N (> 0 while cutting).
    deviation : ndarray of shape (n,)
        Force-driven tool deviation, m (+ away from the work).
    fs : float
        Sampling rate, Hz.
    frequency : float
        Servo frequency of the lenslet cut, Hz.
    command : ndarray of shape (n,), optional
        Commanded tool height, m: the deepest commanded point of the cycle (the
        kinematic lens centre) is the reference of ``deviation_lag_deepest_s``.
    sensor : ndarray of shape (n,), optional
        Force-driven deviation of the measured position (the sensor's mass), m.

    Returns
    -------
    dict
        ``force_max_n`` (N); ``deviation_max_m`` (m); ``deviation_overshoot_m`` (m,
        the largest deviation towards the work after the cut, positive);
        ``deviation_lag_s`` (s, deviation peak after the force peak);
        ``deviation_lag_deepest_s`` (s, deviation peak after the deepest commanded
        point; with ``command``); ``sensor_max_m`` and ``sensor_overshoot_m`` (m;
        with ``sensor``). Empty apart from ``force_max_n`` when nothing is cut.

    Notes
    -----
    The cycle is the last run of samples with ``force > 0`` that starts at least a
    sixth of a period after the record's start, taken from a sixth of a period before
    it to one period after its start. The lags are sample-exact (no registration).
    """
    force = np.asarray(force, dtype=float)
    dev = np.asarray(deviation, dtype=float)
    out: dict[str, Any] = {"force_max_n": float(force.max()) if force.size else 0.0}
    cutting = np.nonzero(force > 0)[0]
    if cutting.size == 0:
        return out
    period = int(round(fs / frequency))
    start = int(cutting[-1])
    while start > 0 and force[start - 1] > 0:
        start -= 1
    seg = slice(max(start - period // 6, 0), min(start + period, force.size))
    fc, dc = force[seg], dev[seg]
    i_f, i_d = int(np.argmax(fc)), int(np.argmax(dc))
    out.update(
        force_max_n=float(fc.max()),
        deviation_max_m=float(dc.max()),
        deviation_overshoot_m=float(-dc.min()),
        deviation_lag_s=float((i_d - i_f) / fs),
    )
    if command is not None:
        i_c = int(np.argmin(np.asarray(command, dtype=float)[seg]))
        out["deviation_lag_deepest_s"] = float((i_d - i_c) / fs)
    if sensor is not None:
        sc = np.asarray(sensor, dtype=float)[seg]
        out["sensor_max_m"] = float(sc.max())
        out["sensor_overshoot_m"] = float(-sc.min())
    return out
