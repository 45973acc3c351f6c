"""Force constant depending on position, B l(x) (DISCOVERY.md catalogue row 4)."""

from __future__ import annotations

from dataclasses import dataclass

from ._base import Bound, EffectParams, TwoCoefficientEffect, quantity

__all__ = ["ForceConstantPositionParams", "ForceConstantPositionEffect"]

NAME = "force-constant-position"

#: Largest change of the force constant over the stroke (relative).
MAX_CHANGE = 0.3

_SOURCE = (
    "each term changes Kf by at most 30 % over the case's stroke s: a voice coil "
    "working inside its gap keeps B l within a few % over its rated stroke "
    "(manufacturers' force-constant uniformity); 30 % is a coil leaving the gap")


@dataclass(frozen=True)
class ForceConstantPositionParams(EffectParams):
    """``Kf(x2) = Kf0 (1 + b1 x2 + b2 x2^2)`` on the actuator force."""

    effect = NAME

    b1: float = quantity(
        0.0, unit="1/m", doc="linear position coefficient of Kf",
        low=Bound("-0.3 / s", lambda ev, p: -MAX_CHANGE / ev.stroke),
        high=Bound("0.3 / s", lambda ev, p: MAX_CHANGE / ev.stroke), source=_SOURCE)
    b2: float = quantity(
        0.0, unit="1/m^2", doc="quadratic position coefficient of Kf",
        low=Bound("-0.3 / s^2", lambda ev, p: -MAX_CHANGE / ev.stroke**2),
        high=Bound("0.3 / s^2", lambda ev, p: MAX_CHANGE / ev.stroke**2),
        source=_SOURCE)

    def nonlinearity(self):
        """The loop's force-constant fields."""
        return {"kf_b1": self.b1, "kf_b2": self.b2}


class ForceConstantPositionEffect(TwoCoefficientEffect):
    name = NAME
    title = "Force constant depends on position, B*l(x)"
    physics = (
        "The coil leaves the uniform gap field: Kf(x2) = Kf0 (1 + b1 x2 + "
        "b2 x2^2) on the actuator force."
    )
    signature = (
        "Commanded and cut following error: harmonics of the FTS frequency "
        "that grow with stroke and with speed (the inertial force is "
        "multiplied too); current per metre varies with position."
    )
    confused_with = (
        "flexure-stiffness-nonlinearity (speed-independent); sensor-"
        "nonlinearity (no following-error or current signature)."
    )
    channels = ("following-error", "cut", "surface", "profile")
    params = ForceConstantPositionParams
    fields = ("b1", "b2")
    labels = ("odd (b1)", "even (b2)")
    bound = 300.0

    def probes(self, ev):
        return 1e-3 / ev.stroke, 1e-3 / ev.stroke**2
