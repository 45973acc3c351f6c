"""Computation / transport delay of the loop (DISCOVERY.md catalogue row 2)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._base import Bound, Config, Effect, EffectParams, Free, quantity

__all__ = ["LoopDelayParams", "LoopDelayEffect"]

NAME = "loop-delay"

#: Largest extra delay, in controller samples (see LoopDelayParams).
MAX_SAMPLES = 20.0


@dataclass(frozen=True)
class LoopDelayParams(EffectParams):
    """The command reaches the amplifier ``extra_delay`` later than modelled."""

    effect = NAME

    extra_delay: float = quantity(
        unit="s", doc="loop delay beyond the machine's",
        low=Bound("-delay / fs", lambda ev, p: -ev.nominal.delay / ev.fs),
        high=Bound("20 / fs", lambda ev, p: MAX_SAMPLES / ev.fs),
        source="the total delay cannot be negative (causality): at most the "
        "machine's calibrated computation delay (machine file controller.delay) "
        "can be removed; a digital servo's computation and conversion latency is "
        "one to a few samples and a 400 kHz current amplifier adds under 1 us "
        "(machine file), so 20 controller samples (100 us at 199.6 kHz) is a "
        "generous upper bound")

    def perturbation(self):
        """The delay as a loop perturbation."""
        from ...servo import LoopPerturbation

        return LoopPerturbation(extra_delay=self.extra_delay)


class LoopDelayEffect(Effect):
    name = NAME
    title = "Computation / transport delay"
    physics = (
        "ADC/DAC pipeline, amplifier group delay: the command reaches the "
        "amplifier tau later than modelled, u(t - tau) (fractional samples)."
    )
    signature = (
        "Open-loop FRF phase -w tau with unchanged magnitude; raised "
        "sensitivity hump near crossover in the idle following-error "
        "spectrum; lag error proportional to the command slope in cuts."
    )
    confused_with = (
        "amplifier bandwidth (magnitude roll-off too); structural mode "
        "(magnitude peak); an angular encoder offset on maps (speed)."
    )
    channels = (
        "frf-open-loop",
        "frf-closed-loop",
        "frf-force",
        "following-error",
        "cut",
        "surface",
        "profile",
    )
    params = LoopDelayParams

    def configs(self, ev, model):
        return [
            Config("+0.25 sample", {"d": 0.25}),
            Config("+1 sample", {"d": 1.0}),
            Config("-0.25 sample", {"d": -0.25}),
        ]

    def _current(self, model):
        ps = model.get(NAME)
        return ps[0].extra_delay if ps else 0.0

    def columns(self, model, cfg, ev):
        d = cfg.values["d"] / ev.fs
        q = LoopDelayParams(self._current(model) + d)
        return [(model.with_terms(NAME, (q,)), d)]

    def start(self, model, cfg, coefs, ev):
        d = cfg.values["d"] / ev.fs * float(np.clip(coefs[0], 0.05, 4.0))
        return model.with_terms(NAME, (LoopDelayParams(d),))

    def free(self, model, slot, ev, cfg=None):
        return [Free("extra_delay", NAME, slot, "extra_delay",
                     -ev.nominal.delay / ev.fs, MAX_SAMPLES / ev.fs)]
