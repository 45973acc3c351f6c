"""Synchronous spindle axial error motion (DISCOVERY.md catalogue row 6)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._base import Config, Effect, EffectParams, Free, quantity

__all__ = ["SpindleAxialErrorParams", "SpindleAxialErrorEffect"]

NAME = "spindle-axial-error"


@dataclass(frozen=True)
class SpindleAxialErrorParams(EffectParams):
    """The work moves axially by ``a cos(h theta + phi)`` (one order per term),
    outside the FTS loop."""

    effect = NAME

    order: int = quantity(
        unit="1", doc="undulations per revolution h", low=1, high=40, fitted=False,
        source="the orders the map locator tests (1-40 per revolution: bearing, "
        "motor-pole and cogging orders and their harmonics)")
    amplitude: float = quantity(
        0.0, unit="m", doc="amplitude a", low=0.0, high=2e-7,
        source="synchronous axial error motion of ultra-precision air-bearing "
        "spindles is nanometres to tens of nanometres (measured per ISO 230-7; "
        "Grejda, PhD thesis, Penn State 2002); 0.2 um in one order is several "
        "times the loosest diamond-turning spindle and would show as a visible "
        "spoke pattern on every part (a seed-2 independent null was 'explained' "
        "by 0.37 um of order 3 over a lenslet map's narrow sector, where it is "
        "almost all tilt)")
    phase: float = quantity(
        0.0, unit="rad", doc="phase phi", low=None, high=None,
        source="an angle: any value (reported in [-pi, pi))")

    def path_z(self, t, theta, r, z):
        """The axial error in m at spindle angles ``theta`` (rad)."""
        dz = np.zeros(np.shape(theta))
        dz += self.amplitude * np.cos(self.order * theta + self.phase)
        return dz

    def report(self, index=None):
        """Values under unit-suffixed keys, the phase wrapped to [-pi, pi)."""
        out = super().report(index)
        key = self.report_key("phase", index)
        out[key] = (self.phase + math.pi) % (2 * math.pi) - math.pi
        return out


class SpindleAxialErrorEffect(Effect):
    name = NAME
    title = "Synchronous spindle axial error motion"
    physics = (
        "Thrust-bearing face error, unbalance, motor cogging: the work moves "
        "axially by sum a_h cos(h theta + phi_h), outside the FTS loop."
    )
    signature = (
        "Not in the following error. Maps/profiles: integer orders per "
        "revolution, the same at every radius (spokes), stable across "
        "rings and speeds."
    )
    confused_with = (
        "lenslet-count orders; base lines when h f_spindle is a line "
        "frequency (change rpm); clamping distortion (2-3 UPR, static)."
    )
    channels = ("surface", "profile")
    params = SpindleAxialErrorParams
    max_terms = 4

    def n_params(self, cfg=None):
        return 2

    def configs(self, ev, model):
        have = [q.order for q in model.get(NAME)]
        return [
            Config(f"order {h}", {"h": int(h)})
            for h in spindle_orders(ev)
            if int(h) not in have
        ]

    def _add(self, model, h, a, ph):
        return model.add(SpindleAxialErrorParams(int(h), float(a), float(ph)))

    def columns(self, model, cfg, ev):
        h = cfg.values["h"]
        return [
            (self._add(model, h, 1e-9, 0.0), 1e-9),
            (self._add(model, h, 1e-9, -math.pi / 2), 1e-9),
        ]

    def start(self, model, cfg, coefs, ev):
        c1, c2 = float(coefs[0]), float(coefs[1])
        return self._add(
            model, cfg.values["h"], 1e-9 * math.hypot(c1, c2), math.atan2(-c2, c1)
        )

    def free(self, model, slot, ev, cfg=None):
        return [
            Free(f"amplitude_{slot + 1}", NAME, slot, "amplitude", 0.0, 1e-5),
            Free(f"phase_{slot + 1}", NAME, slot, "phase", -4 * math.pi, 4 * math.pi),
        ]


def spindle_orders(ev) -> list[int]:
    """Candidate orders: those located as significant, the map locator's most
    significant ones, then 1, 2, 3; at most 8."""
    orders = [int(mm.details["order"]) for mm in ev.mismatches
              if mm.test == "spindle-order"]
    orders += list(ev.order_candidates)
    return list(dict.fromkeys(orders + [1, 2, 3]))[:8]
