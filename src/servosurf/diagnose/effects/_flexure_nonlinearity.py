"""Flexure stiffness nonlinearity (DISCOVERY.md catalogue row 5, memoryless part)."""

from __future__ import annotations

from dataclasses import dataclass

from ._base import Bound, EffectParams, TwoCoefficientEffect, quantity

__all__ = ["FlexureNonlinearityParams", "FlexureNonlinearityEffect"]

NAME = "flexure-stiffness-nonlinearity"

#: Largest nonlinear flexure force over the stroke, as a share of the linear one.
MAX_SHARE = 0.2

_SOURCE = (
    "the nonlinear force over the case's stroke s (largest command) at most 20 % of "
    "the linear flexure force k2 s: flexure bearings are designed to stay linear "
    "over their stroke, large-deflection stiffening setting in as the deflection "
    "approaches the leaf thickness (Howell, Compliant Mechanisms, Wiley 2001, "
    "ch. 5; Smith, Foundations of Ultraprecision Mechanism Design, 2000)")


@dataclass(frozen=True)
class FlexureNonlinearityParams(EffectParams):
    """Extra flexure force ``-(k2q d^2 + k3 d^3)`` on the coil carrier (d = x2 - x3)."""

    effect = NAME

    k_quadratic: float = quantity(
        0.0, unit="N/m^2", doc="quadratic flexure stiffness k2q",
        low=Bound("-0.2 k2 / s", lambda ev, p: -MAX_SHARE * ev.nominal.flexure_stiffness
                  / ev.stroke),
        high=Bound("0.2 k2 / s", lambda ev, p: MAX_SHARE * ev.nominal.flexure_stiffness
                   / ev.stroke),
        source=_SOURCE)
    k_cubic: float = quantity(
        0.0, unit="N/m^3", doc="cubic flexure stiffness k3",
        low=Bound("-0.2 k2 / s^2", lambda ev, p: -MAX_SHARE
                  * ev.nominal.flexure_stiffness / ev.stroke**2),
        high=Bound("0.2 k2 / s^2", lambda ev, p: MAX_SHARE
                   * ev.nominal.flexure_stiffness / ev.stroke**2),
        source=_SOURCE)

    def nonlinearity(self):
        """The loop's flexure nonlinearity fields."""
        return {"flexure_k2": self.k_quadratic, "flexure_k3": self.k_cubic}


class FlexureNonlinearityEffect(TwoCoefficientEffect):
    name = NAME
    title = "Flexure stiffness nonlinearity"
    physics = (
        "Large-deflection stiffening of the flexure bearing: extra force "
        "-(k2q d^2 + k3 d^3) on the coil carrier, d = x2 - x3."
    )
    signature = (
        "Commanded and cut following error: harmonics of the FTS frequency "
        "growing with stroke but not with speed; map: height-dependent "
        "shape error along the cut."
    )
    confused_with = (
        "force-constant-position (its error multiplies the inertial "
        "force too, so it grows with rpm^2: needs a second speed); "
        "sensor-nonlinearity (invisible in the following error)."
    )
    channels = ("following-error", "cut", "surface", "profile")
    params = FlexureNonlinearityParams
    fields = ("k_quadratic", "k_cubic")
    labels = ("quadratic", "cubic")

    def probes(self, ev):
        s = ev.stroke
        k2 = ev.nominal.flexure_stiffness
        return 1e-3 * k2 / s, 1e-3 * k2 / s**2
