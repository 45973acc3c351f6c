"""Capacitive-sensor nonlinearity (DISCOVERY.md catalogue row 14)."""

from __future__ import annotations

from dataclasses import dataclass

from ._base import Bound, EffectParams, TwoCoefficientEffect, quantity

__all__ = ["SensorNonlinearityParams", "SensorNonlinearityEffect"]

NAME = "sensor-nonlinearity"

#: Largest reading error over the stroke, as a share of the stroke.
MAX_SHARE = 0.02

_SOURCE = (
    "each term's reading error over the case's stroke s at most 2 % of s: "
    "capacitive gauges are specified linear to about 0.1-0.2 % of full scale "
    "(DISCOVERY.md row 14), i.e. about 1 % of a 10 um stroke on a 50 um range")


@dataclass(frozen=True)
class SensorNonlinearityParams(EffectParams):
    """The reading is ``y = x + a2 x^2 + a3 x^3``, inside the loop: the loop makes
    the reading follow the command, so the tool misses by about ``-a2 z^2 - a3
    z^3``, and the following error carries what the loop's dynamics make of the
    distorted reading (small, at the command's harmonics)."""

    effect = NAME

    a2: float = quantity(
        0.0, unit="1/m", doc="quadratic sensor coefficient",
        low=Bound("-0.02 / s", lambda ev, p: -MAX_SHARE / ev.stroke),
        high=Bound("0.02 / s", lambda ev, p: MAX_SHARE / ev.stroke), source=_SOURCE)
    a3: float = quantity(
        0.0, unit="1/m^2", doc="cubic sensor coefficient",
        low=Bound("-0.02 / s^2", lambda ev, p: -MAX_SHARE / ev.stroke**2),
        high=Bound("0.02 / s^2", lambda ev, p: MAX_SHARE / ev.stroke**2),
        source=_SOURCE)

    def nonlinearity(self):
        """The loop's sensor-reading fields (the kernel's exact in-loop law)."""
        return {"sensor_a2": self.a2, "sensor_a3": self.a3}


class SensorNonlinearityEffect(TwoCoefficientEffect):
    name = NAME
    title = "Capacitive-sensor nonlinearity"
    physics = (
        "The reading is y = x + a2 x^2 + a3 x^3 inside the loop; the loop "
        "makes the reading follow the command, so the tool misses by about "
        "-a2 z^2 - a3 z^3."
    )
    signature = (
        "Maps/profiles: a height-dependent error along the cut, identical "
        "in every lenslet (quadratic: lenslet shape error ~ z^2); the "
        "following error only weakly (the loop follows the distorted "
        "reading), at the command's harmonics."
    )
    confused_with = (
        "force-constant-position and flexure nonlinearity (both show in "
        "the following error); elastic-recovery (linear in depth and "
        "varies across the cut); a sensor gain error looks like "
        "elastic recovery on single-pass lenslets."
    )
    channels = ("following-error", "cut", "surface", "profile")
    params = SensorNonlinearityParams
    fields = ("a2", "a3")
    labels = ("quadratic (a2)", "cubic (a3)")
    bound = 1e4

    def probes(self, ev):
        return 1e-4 / ev.stroke, 1e-4 / ev.stroke**2
