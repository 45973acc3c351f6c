"""Coulomb friction on the moving mass (DISCOVERY.md catalogue row 5, guides)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._base import Bound, Config, Effect, EffectParams, Free, quantity

__all__ = ["FrictionParams", "FrictionEffect"]

NAME = "friction"

#: Largest friction force, as a share of the actuator's rated force Kf0 I_max.
MAX_SHARE = 0.05
#: Smoothing velocities searched, m/s.
VELOCITIES = (1e-6, 1e-5, 1e-4)
#: Smallest and largest smoothing velocity, m/s.
VELOCITY_RANGE = (1e-7, 1e-3)
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
    "of 0.1-10 um over reversal times of 10 us to 1 ms give 1e-7 to 1e-3 m/s "
    "(Armstrong-Helouvry et al. 1994; Canudas de Wit et al., IEEE TAC 40 (1995) "
    "419, LuGre bristle stiffness)")


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
        low=VELOCITY_RANGE[0], high=VELOCITY_RANGE[1], source=_VELOCITY_SOURCE)

    def nonlinearity(self):
        """The loop's friction fields."""
        return {"friction": self.level, "friction_velocity": self.velocity}


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
        return [Config(f"v_s {v:g} m/s", {"vs": v}) for v in VELOCITIES]

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
            Free("velocity", NAME, slot, "velocity", *VELOCITY_RANGE, True),
        ]
