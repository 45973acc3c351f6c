"""What the model says about the mechanisms behind the paper's figures.

* :func:`stability_mechanism`: where the glued mass sits (m1 or m2) decides whether
  the 0.175 kg loop goes unstable, at which crossover, and which closed-loop pole
  leaves the unit circle (named by the spring that stores most of its energy).
* :func:`overshoot_gap`: the 5 um cut's overshoot after the cut as the tool and as
  the carrier sensor see it, against the measured 34 nm, and its sensitivity to the
  loop's integral action.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..noise._study import loop_limit
from ..servo._loop import ServoLoop
from ..servo._machine import Machine
from ._structure import FIG13C_BANDWIDTH, HEAVY_MASS

__all__ = ["stability_mechanism", "critical_pole", "overshoot_gap", "SPRING_NAMES"]

#: Springs of the network and the mode they carry.
SPRING_NAMES = {
    "k1": "tool mode (k1: tool m1 on the carrier)",
    "k2": "suspension mode (k2: flexure)",
    "k3": "carriage mode (k3: carriage to ground)",
    "k4": "appendage mode (k4: flexible appendage m4 on the carrier)",
}

# state layout of ServoLoop.analogue_ss: [I, dI/dt, x1..x4, v1..v4, y, dy/dt]
_X = slice(2, 6)


def critical_pole(loop: ServoLoop) -> dict[str, Any]:
    """The closed-loop pole of largest modulus, its frequency and its mode.

    Returns
    -------
    dict
        ``abs_z`` (modulus), ``frequency_hz`` (``|arg z| fs / 2 pi``), ``mode``
        (the spring storing most of the eigenvector's potential energy, see
        :data:`SPRING_NAMES`) and ``energy_shares`` per spring.
    """
    a = loop.closed_loop_matrix()
    w, v = np.linalg.eig(a)
    i = int(np.argmax(np.abs(w)))
    x = v[_X, i]
    mech = loop.machine.mechanics
    energy = {
        "k1": mech.k1 * abs(x[0] - x[1]) ** 2,
        "k2": mech.k2 * abs(x[1] - x[2]) ** 2,
        "k3": mech.k3 * abs(x[2]) ** 2,
        "k4": mech.k4 * abs(x[3] - x[1]) ** 2,
    }
    tot = sum(energy.values()) or 1.0
    shares = {k: float(e / tot) for k, e in energy.items()}
    mode = max(shares, key=shares.get)
    return {
        "abs_z": float(abs(w[i])),
        "frequency_hz": float(abs(np.angle(w[i])) * loop.fs / (2 * np.pi)),
        "mode": SPRING_NAMES[mode],
        "energy_shares": shares,
    }


def stability_mechanism(machine: Machine, *, mass: float = HEAVY_MASS) -> list[dict]:
    """The loop limit at ``mass`` with the added mass on m1 and on m2.

    Returns
    -------
    list of dict
        Per placement: ``added_mass_on``, ``limit_hz``, ``kind`` (``"unstable"``,
        ``"untunable"``: no positive PIDF gains, which is not an instability, or
        ``"none"``), ``gain_margin_db_at_1448`` (dB, inf if no phase crossover),
        and for an instability ``critical_pole`` (:func:`critical_pole` just above
        the limit).
    """
    out = []
    for place in ("m1", "m2"):
        m = dataclasses.replace(
            machine,
            mechanics=dataclasses.replace(machine.mechanics, added_mass_on=place),
        ).with_moving_mass(mass)
        lim = loop_limit(m, rtol=1e-4)
        row: dict[str, Any] = {
            "added_mass_on": place,
            "limit_hz": lim.bandwidth_hz,
            "kind": lim.kind,
        }
        try:
            row["gain_margin_db_at_1448"] = ServoLoop(
                m.with_bandwidth(FIG13C_BANDWIDTH)
            ).margins()["gain_margin_db"]
        except Exception:  # noqa: BLE001 - an untunable loop has no margin
            row["gain_margin_db_at_1448"] = float("nan")
        if lim.kind == "unstable":
            row["critical_pole"] = critical_pole(
                ServoLoop(m.with_bandwidth(lim.bandwidth_hz * 1.0001))
            )
        out.append(row)
    return out


def overshoot_gap(machine: Machine, thrust_pressure: float) -> dict[str, Any]:
    """The 5 um cut's overshoot after the cut: tool, carrier sensor, sensitivity.

    Returns
    -------
    dict
        ``tool_overshoot_m``, ``sensor_overshoot_m`` (m, what the carrier sensor and
        so the measured following error see), ``deviation_max_m``, ``sensor_max_m``
        and ``rho_sensitivity``: the sensor overshoot / sensor maximum with the
        integral ratio rho scaled by 0.5 and 0.25 (the experiment's controller need
        not follow servosurf's tuning rule).
    """
    from ._cut import lenslet_cut

    heavy = machine.with_moving_mass(HEAVY_MASS)
    base = lenslet_cut(
        ServoLoop(heavy.with_bandwidth(FIG13C_BANDWIDTH)), thrust_pressure
    )
    sens = []
    for scale in (1.5, 0.5, 0.25):
        c = dataclasses.replace(
            heavy.controller, integral_ratio=heavy.controller.integral_ratio * scale
        )
        r = lenslet_cut(
            ServoLoop(
                dataclasses.replace(heavy, controller=c).with_bandwidth(
                    FIG13C_BANDWIDTH
                )
            ),
            thrust_pressure,
        )
        sens.append(
            {
                "rho_scale": scale,
                "sensor_overshoot_m": r["sensor_overshoot_m"],
                "sensor_max_m": r["sensor_max_m"],
                "tool_overshoot_m": r["deviation_overshoot_m"],
                "deviation_max_m": r["deviation_max_m"],
            }
        )
    return {
        "tool_overshoot_m": base["deviation_overshoot_m"],
        "sensor_overshoot_m": base["sensor_overshoot_m"],
        "deviation_max_m": base["deviation_max_m"],
        "sensor_max_m": base["sensor_max_m"],
        "deviation_lag_deepest_s": base["deviation_lag_deepest_s"],
        "deviation_lag_s": base["deviation_lag_s"],
        "rho_sensitivity": sens,
    }
