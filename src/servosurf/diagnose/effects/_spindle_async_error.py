"""Asynchronous spindle axial error motion (DISCOVERY.md catalogue row 7)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._base import Bound, Config, Effect, EffectParams, Free, quantity
from ._base_lines import map_line_frequencies

__all__ = ["SpindleAsyncErrorParams", "SpindleAsyncErrorEffect", "async_frequencies"]

NAME = "spindle-async-error"

#: Highest frequency of an asynchronous axial error motion, in Hz.
MAX_FREQUENCY = 5e3

#: A located map line closer than this share of the spindle frequency to an
#: integer order ``h f_spindle`` is synchronous (the spindle-axial-error's).
SYNC_TOLERANCE = 0.02


@dataclass(frozen=True)
class SpindleAsyncErrorParams(EffectParams):
    """The work moves axially by ``a cos(2 pi f t + phi)`` at a frequency ``f`` that
    is not an integer multiple of the spindle frequency, outside the FTS loop."""

    effect = NAME

    frequency: float = quantity(
        unit="Hz", doc="frequency f of the error motion", low=1.0,
        high=Bound("min(5 kHz, fs / 2)",
                   lambda ev, p: min(MAX_FREQUENCY, 0.5 * ev.fs)),
        source="the axial rotor mode on the thrust-bearing film: an air or "
        "hydrostatic thrust bearing of 1e8-5e8 N/m axial stiffness carrying a "
        "2-20 kg rotor resonates at sqrt(k/m)/(2 pi) = 0.35-2.5 kHz; air-film "
        "instability (pneumatic hammer) and motor-drive ripple sit below that. "
        "5 kHz is twice the stiffest case; above it the error is sensor noise")
    amplitude: float = quantity(
        0.0, unit="m", doc="amplitude a", low=0.0, high=100e-9,
        source="asynchronous axial error motion of ultra-precision air-bearing "
        "spindles is a few nm to about 25 nm (measured per ISO 230-7 and ANSI "
        "B89.3.4; Marsh, Precision Spindle Metrology, DEStech 2010); 100 nm is "
        "four times the worst and would be a failing bearing")
    phase: float = quantity(
        0.0, unit="rad", doc="phase phi at t = 0", low=None, high=None,
        source="an angle: any value (reported in [-pi, pi))")

    def path_z(self, t, theta, r, z):
        """The axial error in m at times ``t`` (s)."""
        return self.amplitude * np.cos(2 * np.pi * self.frequency * np.asarray(t)
                                       + self.phase)

    def report(self, index=None):
        """Values under unit-suffixed keys, the phase wrapped to [-pi, pi)."""
        out = super().report(index)
        key = self.report_key("phase", index)
        out[key] = (self.phase + math.pi) % (2 * math.pi) - math.pi
        return out


#: Distance (Hz) from a harmonic of the FTS frequency within which a line is
#: locked to the lenslet phase: the 1 Hz tolerance of a located map line.
FTS_LOCK_HZ = 1.0


def _spindle_frequency(ev) -> float:
    case = ev.case
    if case is None or case.toolpath is None:
        return 0.0
    return float(case.toolpath.path.rev_per_s)


def is_synchronous(f: float, f_spindle: float) -> bool:
    """Whether ``f`` (Hz) lies within :data:`SYNC_TOLERANCE` of the spindle
    frequency ``f_spindle`` (Hz) of an integer order ``h >= 1`` (the non-integer
    order test: ``|f / f_spindle - round(f / f_spindle)| <= SYNC_TOLERANCE``)."""
    if f_spindle <= 0:
        return False
    h = f / f_spindle
    return round(h) >= 1 and abs(h - round(h)) <= SYNC_TOLERANCE


def async_frequencies(ev) -> list[float]:
    """Candidate frequencies (Hz): the lines located on maps and profiles that are
    not integer spindle orders and lie within the physical range, at most 8."""
    fsp = _spindle_frequency(ev)
    hi = min(MAX_FREQUENCY, 0.5 * ev.fs)
    out = [f for f in map_line_frequencies(ev)
           if 1.0 <= f <= hi and not is_synchronous(f, fsp)]
    return out[:8]


def _map_span(engine) -> float:
    """Longest pass-time span (s) of the map and profile blocks (0: none)."""
    spans = [b.time_span for b in engine.blocks if b.domain in ("surface", "profile")]
    return max(spans + [0.0])


class SpindleAsyncErrorEffect(Effect):
    name = NAME
    title = "Asynchronous spindle axial error motion"
    physics = (
        "Bearing-film dynamics, the rotor's axial mode, air supply: the work "
        "moves axially by a cos(2 pi f t + phi) at a frequency f that is not an "
        "integer multiple of the spindle frequency, outside the FTS loop."
    )
    signature = (
        "Maps/profiles only: a line at a non-integer order per revolution, so "
        "the pattern differs from one revolution to the next (spiral moire); "
        "none in the following error, none at idle."
    )
    confused_with = (
        "base-vibration-lines (also a fixed frequency on the map, but present "
        "in the following error and at idle); spindle-axial-error (integer "
        "orders, the same every revolution)."
    )
    channels = ("surface", "profile")
    params = SpindleAsyncErrorParams
    max_terms = 4

    def n_params(self, cfg=None):
        return 3

    def configs(self, ev, model):
        have = [q.frequency for q in model.get(NAME)]
        return [
            Config(f"{f:.2f} Hz", {"f": float(f)})
            for f in async_frequencies(ev)
            if all(abs(f - g) > 1.0 for g in have)
        ]

    def _add(self, model, f, a, ph):
        return model.add(SpindleAsyncErrorParams(float(f), float(a), float(ph)))

    def columns(self, model, cfg, ev):
        f = cfg.values["f"]
        return [
            (self._add(model, f, 1e-9, 0.0), 1e-9),
            (self._add(model, f, 1e-9, -math.pi / 2), 1e-9),
        ]

    def start(self, model, cfg, coefs, ev):
        c1, c2 = float(coefs[0]), float(coefs[1])
        return self._add(
            model, cfg.values["f"], 1e-9 * math.hypot(c1, c2), math.atan2(-c2, c1)
        )

    def free(self, model, slot, ev, cfg=None):
        f = self.term(model, slot).frequency
        df = 0.5  # Hz: half the 1 Hz tolerance of a located map line
        return [
            Free(f"frequency_{slot + 1}", NAME, slot, "frequency", max(f - df, 1.0),
                 f + df),
            Free(f"amplitude_{slot + 1}", NAME, slot, "amplitude", 0.0, 1e-6),
            Free(f"phase_{slot + 1}", NAME, slot, "phase", -4 * math.pi, 4 * math.pi),
        ]

    def implausible(self, model, slot, ev, cfg=None):
        """As :meth:`Effect.implausible`, except that the frequency's search window
        is centred on the located line (its ends are not bounds of the physics);
        also refused: a frequency on a harmonic of the FTS command (a pattern
        locked to the lenslet phase is the servo's or the tool's, not the
        spindle bearing's)."""
        why = self.term(model, slot).implausible(ev)
        if why is not None:
            return why
        f = self.term(model, slot).frequency
        k = round(f / ev.fts) if ev.fts > 0 else 0
        if k >= 1 and abs(f - k * ev.fts) <= FTS_LOCK_HZ:
            return (f"frequency = {f:.4g} Hz is {k} x the FTS frequency "
                    f"{ev.fts:.4g} Hz (within {FTS_LOCK_HZ:g} Hz): locked to the "
                    "lenslet phase, not an asynchronous spindle error")
        for f in self.free(model, slot, ev, cfg)[1:]:
            if f.at_bound(model) and f.field != "amplitude":
                return (f"{f.field} = {f.get(model):.4g} sits at the bound of its "
                        f"search range [{f.lo:.4g}, {f.hi:.4g}]")
        amp = self.free(model, slot, ev, cfg)[1]
        if amp.get(model) >= amp.hi * (1 - 1e-4):
            return (f"amplitude = {amp.get(model):.4g} m sits at the bound of its "
                    f"search range [{amp.lo:.4g}, {amp.hi:.4g}] m")
        return None

    def refine(self, engine, model, term):
        """Scan the new term's frequency over +-0.75 Hz around the located line and its
        FTS gate sidebands on the map and profile blocks (their deviance
        oscillates in frequency with period 1/T: a local solver started off the
        main lobe stops in a side lobe), with the amplitude and phase solved
        linearly at each frequency."""
        i = term.slot
        t_span = _map_span(engine)
        q0 = self.term(model, i)
        if t_span <= 0:
            return model
        blocks = [k for k, b in enumerate(engine.blocks)
                  if b.domain in ("surface", "profile")]
        base = self.remove(model, i)
        r0 = np.concatenate([engine.block_residual(k, base, cache=False)
                             for k in blocks])

        def best_at(f):
            # amplitude and phase by linear least squares on the two quadratures
            # (the heights are linear in the term); deviance of the blocks with it
            cols = []
            for ph in (0.0, -math.pi / 2):
                q = base.add(SpindleAsyncErrorParams(float(f), 1e-9, ph))
                cols.append(np.concatenate([
                    engine.block_residual(k, q, cache=False) for k in blocks]) - r0)
            a = np.column_stack(cols)
            c, *_ = np.linalg.lstsq(a, -r0, rcond=None)
            d = float(np.sum((r0 + a @ c) ** 2))
            amp = min(1e-9 * math.hypot(c[0], c[1]), 0.99e-6)
            return d, (float(f), amp, math.atan2(-c[1], c[0]))

        # maps and profiles see the tool only while it cuts (a gate at the FTS
        # frequency): the located peak may be a gate sideband f +- k f_FTS, so
        # every alias within two FTS harmonics is scanned and the best kept
        fts = engine.evidence.fts
        centres = [q0.frequency + k * fts for k in (0, -1, 1, -2, 2)] if fts > 0 \
            else [q0.frequency]
        step = 1.0 / (4 * t_span)
        cands = []
        for c in centres:
            grid = c + np.arange(-0.75, 0.75 + 1e-9, step)
            grid = grid[(grid >= 1.0) & (grid <= MAX_FREQUENCY)]
            cands += [best_at(f) for f in grid]
        if not cands:
            return model
        _d, (f, a, ph) = min(cands, key=lambda v: v[0])
        q = model.replace_term(NAME, i, SpindleAsyncErrorParams(f, a, ph))
        return q if engine.deviance(q) <= engine.deviance(model) else model
