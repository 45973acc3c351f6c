"""Electrical pickup lines in the logged reading (DISCOVERY.md catalogue row 17)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._base import Bound, Config, Effect, EffectParams, Free, Model, quantity
from ._base_lines import line_frequencies

__all__ = ["SensorPickupParams", "SensorPickupLinesEffect"]

NAME = "sensor-pickup-lines"

#: Largest pickup amplitude referred to position, in m.
MAX_AMPLITUDE = 10e-9


@dataclass(frozen=True)
class SensorPickupParams(EffectParams):
    """One sinusoid ``a cos(2 pi f t + phi)`` in the logged position reading only
    (outside the loop: in the following-error records, not on the surface; its
    phase is free in every record)."""

    effect = NAME

    frequency: float = quantity(
        unit="Hz", doc="frequency of the line", low=1.0,
        high=Bound("fs / 2", lambda ev, p: 0.5 * ev.fs),
        source="below the logger's Nyquist frequency (the controller rate): a "
        "line beyond it aliases in every sampled record")
    amplitude: float = quantity(
        unit="m", doc="zero-to-peak amplitude referred to position", low=0.0,
        high=MAX_AMPLITUDE,
        source="at most 10 nm, ten times the capacitive gauge's specified noise "
        "(Lion Precision CPL190: 1 nm RMS at 15 kHz, the machine file's sensor): "
        "a larger line is found and shielded at commissioning (Ott, "
        "Electromagnetic Compatibility Engineering, Wiley 2009, ch. 2-3)")

    def sensor_lines(self):
        """The line as ``((frequency, amplitude),)``."""
        return ((self.frequency, self.amplitude),)


def pickup_probe(ev, f: float) -> float:
    """Amplitude (m) giving one noise level in an idle bin at ``f`` (Hz)."""
    s = ev.case.noise_psd(Model(), np.array([f]), "fe")[0]
    return math.sqrt(2 * ev.case.fs * max(s, 1e-40) / ev.record_length)


class SensorPickupLinesEffect(Effect):
    name = NAME
    title = "Sensor pickup lines"
    physics = (
        "Electrical pickup (mains harmonics, switching supplies) in the logged "
        "position reading, outside the loop: a_k cos(2 pi f_k t + phi_k) in the "
        "following error, the tool does not move."
    )
    signature = (
        "Narrow lines at fixed frequencies in every following-error record "
        "(idle too), unshaped by the loop; none on maps, profiles or FRFs."
    )
    confused_with = (
        "base-vibration-lines (through the loop: also on the maps, shaped by "
        "the base-to-error path); spindle orders (change rpm)."
    )
    channels = ("following-error", "cut")
    params = SensorPickupParams
    max_terms = 8
    #: present with the spindle stopped: the idle records must confirm a line
    #: (deviance reduction there, chi2(2) at about p = 0.01)
    require = ("spectrum", 9.0)

    def configs(self, ev, model):
        have = [q.frequency for q in model.get(NAME)]
        out = []
        for f in line_frequencies(ev):
            if all(abs(f - g) > 1.5 * ev.fs / ev.record_length for g in have):
                out.append(Config(f"{f:.1f} Hz", {"f": float(f)}))
        return out

    def columns(self, model, cfg, ev):
        a = pickup_probe(ev, cfg.values["f"])
        return [(model.add(SensorPickupParams(cfg.values["f"], a)), a)]

    def start(self, model, cfg, coefs, ev):
        f = cfg.values["f"]
        c = 1.0 if coefs is None else float(coefs[0])
        a = pickup_probe(ev, f) * math.sqrt(max(c, 0.01))
        return model.add(SensorPickupParams(f, min(a, 0.5 * MAX_AMPLITUDE)))

    def free(self, model, slot, ev, cfg=None):
        f = self.term(model, slot).frequency
        df = 1.5 * ev.fs / ev.record_length
        return [
            Free(f"frequency_{slot + 1}", NAME, slot, "frequency", max(f - df, 1.0),
                 f + df, located=True),
            Free(f"amplitude_{slot + 1}", NAME, slot, "amplitude", 1e-16,
                 MAX_AMPLITUDE, True),
        ]

    def implausible(self, model, slot, ev, cfg=None):
        """As :meth:`Effect.implausible`, except that the frequency's search window
        is centred on the line (its ends are not bounds of the physics)."""
        why = self.term(model, slot).implausible(ev)
        if why is not None:
            return why
        f = self.free(model, slot, ev, cfg)[1]
        if f.at_bound(model):
            return (f"amplitude = {f.get(model):.4g} m sits at the bound of its "
                    f"search range [{f.lo:.4g}, {f.hi:.4g}] m")
        return None

    def refine(self, engine, model, term):
        """Scan the new line's frequency over +-1.5 idle bins at a quarter of the
        longest following-error record's resolution before the local fit (the
        deviance of a coherent record oscillates in frequency with period 1/T)."""
        ev = engine.evidence
        i = term.slot
        blocks = [k for k, b in enumerate(engine.blocks)
                  if b.domain in ("time", "spectrum")]
        if not blocks:
            return model
        q0 = self.term(model, i)
        df = ev.fs / ev.record_length
        spans = [getattr(engine.blocks[k], "time_span", 0.0) for k in blocks]
        t1 = max([s for s in spans if s > 0] or [1.0 / df])

        def with_f(f):
            return model.replace_term(NAME, i, SensorPickupParams(float(f),
                                                                  q0.amplitude))

        def dev(q):
            tot = 0.0
            for k in blocks:
                r = engine.block_residual(k, q, cache=False)
                tot += float(r @ r)
            return tot

        grid = np.arange(q0.frequency - 1.5 * df, q0.frequency + 1.5 * df,
                         1.0 / (4 * t1))
        grid = grid[grid > 1.0]
        if grid.size == 0:
            return model
        best = with_f(min(grid, key=lambda f: dev(with_f(f))))
        return best if engine.deviance(best) <= engine.deviance(model) else model
