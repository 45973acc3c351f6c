"""Amplifier current saturation (DISCOVERY.md catalogue row 3)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._base import Bound, Config, Effect, EffectParams, Free, quantity

__all__ = ["AmplifierSaturationParams", "AmplifierSaturationEffect"]

NAME = "amplifier-saturation"


@dataclass(frozen=True)
class AmplifierSaturationParams(EffectParams):
    """The current demand ``G_I u`` clipped at ``+-max_current``."""

    effect = NAME

    max_current: float = quantity(
        unit="A", doc="current limit I_max", low=0.0,
        high=Bound("peak current demand of the records", lambda ev, p: float(
            ev.current_demand.max()) if ev.current_demand.size else math.inf),
        source="identifiable only below the largest current the records demand "
        "(a higher limit never clips: no signature); the machine file's rating "
        "(actuator.max-current) is assumed there, so it bounds nothing")

    def nonlinearity(self):
        """The loop's saturation field."""
        return {"max_current": self.max_current}


def current_levels(ev) -> list[float]:
    """Saturation levels (A) placed on the observed demand: a log grid up to 98 %
    of the peak, then fractions 1 - {1e-2 ... 3e-4} of the peak (DISCOVERY 5.2)."""

    def run():
        c = ev.current_demand
        if c.size == 0:
            return []
        peak = float(c.max())
        lo, hi = np.quantile(c, 0.8), 0.98 * peak
        if not hi > lo > 0:
            return []
        return list(np.geomspace(lo, hi, 10)) + [
            peak * (1 - x) for x in (1e-2, 3e-3, 1e-3, 3e-4)
        ]

    return ev.memo((NAME, "levels"), run)


class AmplifierSaturationEffect(Effect):
    name = NAME
    title = "Amplifier current saturation"
    physics = (
        "The current demand G_I u is clipped at +-I_max (voltage headroom at "
        "steep flanks and cusps)."
    )
    signature = (
        "Commanded and cut following error: errors localised in time at the "
        "current peaks (cusps, start-up), thresholded, growing "
        "superlinearly with speed; flat-topped current."
    )
    confused_with = (
        "stiffness or Kf(x) nonlinearity (position-, not "
        "current-dependent, present in slow air cuts); loop-delay "
        "(linear, not thresholded)."
    )
    channels = ("following-error", "cut", "surface", "profile")
    params = AmplifierSaturationParams
    threshold = True

    def configs(self, ev, model):
        return [Config(f"{c:.4g} A", {"i": float(c)}) for c in current_levels(ev)]

    def _term(self, model, cfg):
        return model.with_terms(NAME, (AmplifierSaturationParams(cfg.values["i"]),))

    def columns(self, model, cfg, ev):
        return [(self._term(model, cfg), 1.0)]

    def start(self, model, cfg, coefs, ev):
        return self._term(model, cfg)

    def free(self, model, slot, ev, cfg=None):
        return [Free("max_current", NAME, slot, "max_current", 1e-4, 1e3, True)]
