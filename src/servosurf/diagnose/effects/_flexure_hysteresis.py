"""Flexure hysteresis with memory (DISCOVERY.md catalogue row 5, hysteretic part)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._base import Bound, Config, Effect, EffectParams, Free, quantity

__all__ = ["FlexureHysteresisParams", "FlexureHysteresisEffect"]

NAME = "flexure-hysteresis"

#: Largest hysteretic force over the stroke, as a share of the linear flexure force.
MAX_SHARE = 0.2
#: Yield displacements searched, as shares of the case's stroke.
YIELD_SHARES = (0.03, 0.1, 0.3, 1.0)
#: Smallest and largest yield displacement, as shares of the stroke.
YIELD_RANGE = (0.01, 3.0)
#: Probe of the hysteretic stiffness, as a share of k2.
PROBE = 1e-3

_STIFFNESS_SOURCE = (
    "the hysteretic force k_h z (|z| <= z_y) is at most 20 % of the linear flexure "
    "force k2 s over the case's stroke s, i.e. k_h <= 0.2 k2 (z_y <= s); positive "
    "(a passive element dissipates): material damping of flexure metals has loss "
    "factors of 1e-4 to 1e-2 and micro-slip at clamped leaf joints a few percent "
    "of the joint stiffness (Howell, Compliant Mechanisms, Wiley 2001, ch. 5; "
    "Segalman, J. Appl. Mech. 72 (2005) 752, Iwan joint models)")
_YIELD_SOURCE = (
    "micro-slip at bolted or clamped leaf joints yields over 0.1-10 um "
    "(Segalman 2005; Ismail et al., Mech. Syst. Signal Process. 23 (2009) 1465, "
    "Bouc-Wen review); within 0.01 s to 3 s of the case's stroke s the loop is "
    "identifiable: a smaller z_y is Coulomb friction, a larger one a stiffness "
    "recalibration")


@dataclass(frozen=True)
class FlexureHysteresisParams(EffectParams):
    """Bouc-Wen hysteresis of the flexure: force ``-k_h z`` on the coil carrier,
    ``z' = v - |v| z / (2 z_y) - v |z| / (2 z_y)`` with ``v = v2 - v3`` (the
    flexure's deflection rate), so ``z`` saturates at ``+-z_y``."""

    effect = NAME

    stiffness: float = quantity(
        0.0, unit="N/m", doc="hysteretic stiffness k_h (small-amplitude slope)",
        low=0.0,
        high=Bound("0.2 k2", lambda ev, p: MAX_SHARE * ev.nominal.flexure_stiffness),
        source=_STIFFNESS_SOURCE)
    yield_displacement: float = quantity(
        1e-6, unit="m", doc="yield displacement z_y (saturation of z)",
        low=Bound("0.01 s", lambda ev, p: YIELD_RANGE[0] * ev.stroke),
        high=Bound("3 s", lambda ev, p: YIELD_RANGE[1] * ev.stroke),
        source=_YIELD_SOURCE)

    def nonlinearity(self):
        """The loop's Bouc-Wen fields (beta = gamma = 1 / (2 z_y))."""
        a = 0.5 / self.yield_displacement
        return {"bouc_wen_stiffness": self.stiffness, "bouc_wen_beta": a,
                "bouc_wen_gamma": a}


class FlexureHysteresisEffect(Effect):
    name = NAME
    title = "Flexure hysteresis"
    physics = (
        "Rate-independent hysteresis of the flexure (micro-slip, material "
        "damping): Bouc-Wen force -k_h z on the coil carrier, z following the "
        "deflection with memory and saturating at +-z_y."
    )
    signature = (
        "Commanded and cut following error: a direction-dependent residual (up- "
        "and down-strokes differ at the same position: a loop in residual vs x), "
        "odd harmonics of the FTS frequency; map: leading/trailing flank "
        "asymmetry of the lenslets."
    )
    confused_with = (
        "flexure-stiffness-nonlinearity and force-constant-position (memoryless: "
        "the same residual at the same x on both strokes); friction (a jump at "
        "each velocity reversal, no elastic pre-slip range); loop-delay (linear)."
    )
    channels = ("following-error", "cut", "surface", "profile")
    params = FlexureHysteresisParams

    def _probe(self, ev):
        return PROBE * ev.nominal.flexure_stiffness

    def configs(self, ev, model):
        return [Config(f"z_y {c:g} stroke", {"zy": c * ev.stroke})
                for c in YIELD_SHARES]

    def columns(self, model, cfg, ev):
        pr = self._probe(ev)
        q = FlexureHysteresisParams(pr, cfg.values["zy"])
        return [(model.with_terms(NAME, (q,)), pr)]

    def start(self, model, cfg, coefs, ev):
        pr = self._probe(ev)
        c = 1.0 if coefs is None else float(coefs[0])
        k = pr * float(np.clip(c, 0.02, 0.99 * MAX_SHARE / PROBE))
        return model.with_terms(NAME, (FlexureHysteresisParams(k, cfg.values["zy"]),))

    def free(self, model, slot, ev, cfg=None):
        k2 = ev.nominal.flexure_stiffness
        return [
            Free("stiffness", NAME, slot, "stiffness", 1e-2 * PROBE * k2,
                 MAX_SHARE * k2, True),
            Free("yield_displacement", NAME, slot, "yield_displacement",
                 YIELD_RANGE[0] * ev.stroke, YIELD_RANGE[1] * ev.stroke, True),
        ]
