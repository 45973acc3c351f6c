"""Coulomb friction on the moving mass (DISCOVERY.md catalogue row 5, guides)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._base import Bound, Config, Effect, EffectParams, Free, quantity

__all__ = ["FrictionParams", "FrictionEffect"]

NAME = "friction"

#: Largest friction force, as a share of the actuator's rated force Kf0 I_max.
MAX_SHARE = 0.05
#: Smoothing velocities searched, as shares of the largest (see _max_velocity).
VELOCITY_SHARES = (1e-4, 1e-3, 1e-2, 0.1, 0.3)
#: Smallest smoothing velocity, m/s.
MIN_VELOCITY = 1e-7
#: Largest smoothing velocity, as a share of the command's peak velocity.
MAX_VELOCITY_SHARE = 3.0
#: Peak velocity assumed without an FTS frequency (a facing cut), m/s.
SLOW_VELOCITY = 3e-3
#: Probe of the friction level, as a share of the largest level.
PROBE = 1e-3

_LEVEL_SOURCE = (
    "at most 5 % of the actuator's rated force Kf0 I_max (machine file): an FTS "
    "is guided by flexures or air bearings, friction arising only from seals, "
    "cables and wipers; rolling guides give a friction coefficient of 0.001-0.005 "
    "of the load (Armstrong-Helouvry, Dupont and Canudas de Wit, Automatica 30 "
    "(1994) 1083), and a friction that eats more than 5 % of the peak force "
    "would stall the tool at each reversal of a lenslet stroke")
_VELOCITY_SOURCE = (
    "the velocity over which friction changes sign: pre-sliding displacements "
    "of 0.1-10 um (Armstrong-Helouvry et al. 1994; Canudas de Wit et al., IEEE "
    "TAC 40 (1995) 419, LuGre bristle stiffness) traversed at the stroke's "
    "reversal give 1e-7 m/s and up; above 3 times the command's peak velocity "
    "2 pi f_FTS s the law is linear to 4 % over the stroke (tanh(1/3) = 0.32): "
    "viscous damping (a recalibration), not friction")


@dataclass(frozen=True)
class FrictionParams(EffectParams):
    """Smoothed Coulomb friction ``-F_c tanh(v2 / v_s)`` on the coil carrier."""

    effect = NAME

    level: float = quantity(
        0.0, unit="N", doc="Coulomb friction force F_c", low=0.0,
        high=Bound("0.05 Kf0 I_max", lambda ev, p: MAX_SHARE * _rated(ev)),
        source=_LEVEL_SOURCE)
    velocity: float = quantity(
        1e-5, unit="m/s", doc="smoothing velocity v_s of the sign",
        low=MIN_VELOCITY,
        high=Bound("3 (2 pi f_FTS s)", lambda ev, p: _max_velocity(ev)),
        source=_VELOCITY_SOURCE)

    def nonlinearity(self):
        """The loop's friction fields."""
        return {"friction": self.level, "friction_velocity": self.velocity}


def _max_velocity(ev) -> float:
    """Largest smoothing velocity in m/s: 3 times the command's peak velocity."""
    if ev.fts > 0:
        return MAX_VELOCITY_SHARE * 2 * math.pi * ev.fts * ev.stroke
    return MAX_VELOCITY_SHARE * SLOW_VELOCITY


def _rated(ev) -> float:
    """The actuator's rated force Kf0 I_max in N."""
    return ev.nominal.force_constant * ev.nominal.max_current


class FrictionEffect(Effect):
    name = NAME
    title = "Coulomb friction"
    physics = (
        "Friction of guides, seals or cables on the moving mass: a force "
        "-F_c tanh(v / v_s) that changes sign with the carrier velocity v."
    )
    signature = (
        "Commanded and cut following error: a step-like error at every velocity "
        "reversal (the lenslet apices and troughs), odd harmonics of the FTS "
        "frequency with a slowly decaying spectrum; map: flats or steps at the "
        "stroke reversals; larger relative to the stroke at small amplitudes."
    )
    confused_with = (
        "flexure-hysteresis (an elastic pre-slip range before the reversal jump); "
        "amplifier-saturation (thresholded at current peaks, not at reversals); "
        "quadratic damping (grows with speed, zero at reversals)."
    )
    channels = ("following-error", "cut", "surface", "profile")
    params = FrictionParams

    def _probe(self, ev):
        return PROBE * MAX_SHARE * _rated(ev)

    def configs(self, ev, model):
        vmax = _max_velocity(ev)
        return [Config(f"v_s {c * vmax:.3g} m/s", {"vs": c * vmax})
                for c in VELOCITY_SHARES]

    def columns(self, model, cfg, ev):
        pr = self._probe(ev)
        return [(model.with_terms(NAME, (FrictionParams(pr, cfg.values["vs"]),)), pr)]

    def start(self, model, cfg, coefs, ev):
        pr = self._probe(ev)
        c = 1.0 if coefs is None else float(coefs[0])
        level = pr * float(np.clip(c, 0.02, 0.99 / PROBE))
        return model.with_terms(NAME, (FrictionParams(level, cfg.values["vs"]),))

    def free(self, model, slot, ev, cfg=None):
        hi = MAX_SHARE * _rated(ev)
        return [
            Free("level", NAME, slot, "level", 1e-2 * PROBE * hi, hi, True),
            Free("velocity", NAME, slot, "velocity", MIN_VELOCITY, _max_velocity(ev),
                 True),
        ]
