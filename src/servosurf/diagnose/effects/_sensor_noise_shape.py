"""Sensor noise floor and roll-off differ from the calibration (noise-model term)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ._base import Bound, Config, Effect, EffectParams, Free, quantity

__all__ = ["SensorNoiseShapeParams", "SensorNoiseShapeEffect"]

NAME = "sensor-noise-shape"


@dataclass(frozen=True)
class SensorNoiseShapeParams(EffectParams):
    """The machine's sensor-noise PSD with another white floor and roll-off corner,
    ``Ws(f) = (level^2 (f/f0)^s + floor^2) / (1 + (f/corner)^order)``."""

    effect = NAME

    floor: float = quantity(
        unit="m/sqrt(Hz)", doc="white floor of the sensor noise", low=0.0,
        high=Bound("10 max(floor, level at 1 kHz)", lambda ev, p: 10.0 * max(
            ev.nominal.sensor_floor, ev.nominal.sensor_level)),
        source="at most ten times the machine file's calibrated sensor noise (the "
        "larger of its white floor and its density at 1 kHz): a noise model off "
        "by a factor is a recalibration (issue 19, item 5), one off by more than "
        "a decade is another sensor")
    corner: float = quantity(
        unit="Hz", doc="roll-off corner of the sensor noise", low=100.0,
        high=Bound("fs / 2", lambda ev, p: 0.5 * ev.fs),
        source="identifiable only between the loop bandwidth's decade and the "
        "controller's Nyquist frequency, where the idle records resolve it")

    def machine(self, m):
        """The machine with this sensor-noise floor and corner."""
        d = m.disturbances
        sn = dataclasses.replace(d.sensor_noise, floor=float(self.floor),
                                 corner=float(self.corner))
        return dataclasses.replace(m, disturbances=dataclasses.replace(
            d, sensor_noise=sn))


class SensorNoiseShapeEffect(Effect):
    name = NAME
    title = "Sensor noise floor and roll-off differ"
    physics = (
        "The capacitive sensor's white floor (electronics) and its roll-off "
        "corner differ from the calibration: Ws(f) = (level^2 (f/f0)^s + "
        "floor^2) / (1 + (f/corner)^order)."
    )
    signature = (
        "Idle following-error spectrum: broadband excess or deficit above "
        "the bandwidth (where sensor noise dominates), changing shape at "
        "the corner; none in FRFs or deterministic responses."
    )
    confused_with = (
        "a 1/f sensor-noise excess (rises towards low frequency: not "
        "this module); current-noise level (dominates below the "
        "bandwidth)."
    )
    channels = ("following-error",)
    params = SensorNoiseShapeParams

    def _current(self, model, ev):
        ps = model.get(NAME)
        if ps:
            return ps[0].floor, ps[0].corner
        return ev.nominal.sensor_floor, ev.nominal.sensor_corner

    def _probe_floor(self, ev):
        return math.sqrt(ev.nominal.sensor_floor**2 + (0.15 * ev.nominal.sensor_level)
                         ** 2)

    def configs(self, ev, model):
        return [Config("default")]

    def columns(self, model, cfg, ev):
        fl, co = self._current(model, ev)
        return [
            (model.with_terms(NAME, (SensorNoiseShapeParams(self._probe_floor(ev),
                                                            co),)), 1.0),
            (model.with_terms(NAME, (SensorNoiseShapeParams(fl, co * 1.05),)), 1.0),
        ]

    def start(self, model, cfg, coefs, ev):
        fl, co = self._current(model, ev)
        f2 = fl**2 + float(coefs[0]) * (self._probe_floor(ev) ** 2 - fl**2)
        q = SensorNoiseShapeParams(
            math.sqrt(max(f2, (0.02 * ev.nominal.sensor_level) ** 2)),
            co * (1.0 + 0.05 * float(np.clip(coefs[1], -10, 10))),
        )
        return model.with_terms(NAME, (q,))

    def free(self, model, slot, ev, cfg=None):
        return [
            Free("floor", NAME, slot, "floor", 1e-16, 1e-8, True),
            Free("corner", NAME, slot, "corner", 100.0, 0.5 * ev.fs, True),
        ]
