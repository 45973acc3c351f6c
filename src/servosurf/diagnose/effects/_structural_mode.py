"""Unmodelled structural resonance (DISCOVERY.md catalogue row 1)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._base import Bound, Config, Effect, EffectParams, Free, quantity

__all__ = ["StructuralModeParams", "StructuralModeEffect"]

NAME = "structural-mode"


@dataclass(frozen=True)
class StructuralModeParams(EffectParams):
    """An extra mode ``q'' + 2 zeta w q' + w^2 q = w^2 g Fa`` added to the tool and
    the sensor (collocated), driven by the actuator force."""

    effect = NAME

    frequency: float = quantity(
        unit="Hz", doc="natural frequency f_r",
        low=100.0, high=Bound("0.45 fs", lambda ev, p: 0.45 * ev.fs),
        source="above the FTS suspension mode (sqrt(k2 / m) / 2 pi = 54 Hz at "
        "0.175 kg, machine file): a mode above the lumped model; below the "
        "controller's Nyquist frequency fs / 2 (a mode beyond it aliases in every "
        "sampled record and cannot be told from one below), 10 % margin")
    damping_ratio: float = quantity(
        unit="1", doc="modal damping ratio zeta", low=1e-3, high=0.5,
        source="structural modes of machine-tool assemblies have 1-5 % damping "
        "(Altintas, Manufacturing Automation, 2nd ed., Cambridge 2012, ch. 3); the "
        "range spans a monolithic flexure (0.1 %) to 50 % (beyond it there is no "
        "resonance to identify)")
    compliance: float = quantity(
        unit="m/N", doc="static compliance g from actuator force to tool and sensor",
        low=0.0, high=Bound("1 / k2", lambda ev, p: 1.0 / ev.nominal.flexure_stiffness),
        source="at most the suspension flexure's own compliance 1/k2 (machine file): "
        "a mode softer than the flexure would be the lumped model's main mode, "
        "not one above it")

    def perturbation(self):
        """The mode as a loop perturbation (none at zero compliance)."""
        from ...servo import LoopPerturbation, StructuralMode

        if self.compliance == 0.0 or not self.frequency > 0.0:
            return LoopPerturbation()
        mode = StructuralMode(self.frequency, self.damping_ratio, self.compliance)
        return LoopPerturbation(modes=(mode,))


def _mode_frequencies(ev) -> list[float]:
    """Resonance candidates (Hz): narrow-band excess in the loop channels and the
    nominal FRF residual peaks, 3 % apart, at most 8."""

    def run():
        modes = []
        for mm in ev.mismatches:
            f = mm.details.get("frequency_hz")
            if f is not None and f > 500 and mm.domain in ("frf", "time", "spectrum"):
                modes.append(f)
            if "band_hz" in mm.details and mm.domain in ("frf", "spectrum", "time"):
                lo_, hi_ = mm.details["band_hz"]
                if lo_ > 400:
                    modes.append(math.sqrt(lo_ * hi_))
        modes += list(ev.frf_peaks)
        uniq: list[float] = []
        for f in modes:
            if all(abs(math.log(f / g)) > 0.03 for g in uniq):
                uniq.append(f)
        return uniq[:8]

    return ev.memo((NAME, "frequencies"), run)


class StructuralModeEffect(Effect):
    name = NAME
    title = "Unmodelled structural resonance"
    physics = (
        "A mode above the lumped model (tool shank, holder, FTS body rocking), "
        "q'' + 2 zeta w q' + w^2 q = w^2 g Fa, adding q to tool and sensor."
    )
    signature = (
        "FRFs: extra resonance/antiresonance pair; following error: "
        "spectral bump at f_r (idle, from current noise) and ringing after "
        "every lenslet cusp; map: ripple of wavelength v/f_r after cusps."
    )
    confused_with = (
        "base-vibration-lines (a line is present at idle with fixed "
        "frequency and absent from the FRFs); loop-delay (phase only)."
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
    params = StructuralModeParams
    zetas = (0.005, 0.02, 0.08)
    #: Frequencies of the search grid over [800 Hz, 0.4 fs] (log-spaced; about 10 %
    #: apart at fs = 100 kHz). A lightly damped mode (zeta 0.01: half-power width
    #: 2 %) half-way between points 20 % apart projected too weakly on either to be
    #: fitted: a 24.6 kHz mode at ENR 0.1 went unseen with 22 points.
    n_grid = 44
    n_start = 2

    def configs(self, ev, model):
        fr = list(_mode_frequencies(ev))
        grid = np.geomspace(800.0, 0.4 * ev.fs, self.n_grid)
        half_step = 0.5 * math.log(grid[1] / grid[0])
        for f in grid:  # grid points not already covered by a located frequency
            if all(abs(math.log(f / g)) > half_step for g in fr):
                fr.append(float(f))
        return [
            Config(f"{f:.0f} Hz, zeta {z:g}", {"f": float(f), "z": z})
            for f in fr
            for z in self.zetas
        ]

    def distinct(self, cfg, previous):
        """A second start must be a mode 10 % away in frequency."""
        f = cfg.values["f"]
        return all(abs(math.log(f / q.values["f"])) > 0.1 for q in previous)

    def _probe(self, cfg, ev):
        w = 2 * math.pi * cfg.values["f"]
        return 0.01 * 2 * cfg.values["z"] / (ev.nominal.moving_mass * w * w)

    def _term(self, cfg, g):
        return StructuralModeParams(cfg.values["f"], cfg.values["z"], g)

    def columns(self, model, cfg, ev):
        g = self._probe(cfg, ev)
        return [(model.with_terms(NAME, (self._term(cfg, g),)), g)]

    def start(self, model, cfg, coefs, ev):
        g = self._probe(cfg, ev) * max(float(coefs[0]), 0.05)
        return model.with_terms(NAME, (self._term(cfg, g),))

    def free(self, model, slot, ev, cfg=None):
        return [
            Free("frequency", NAME, slot, "frequency", 100.0, 0.45 * ev.fs, True),
            Free("damping_ratio", NAME, slot, "damping_ratio", 1e-3, 0.5, True),
            Free("compliance", NAME, slot, "compliance", 1e-16, 1e-5, True),
        ]
