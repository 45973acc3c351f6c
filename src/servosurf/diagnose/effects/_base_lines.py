"""Base vibration lines (DISCOVERY.md catalogue row 16)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._base import Bound, Config, Effect, EffectParams, Free, Model, quantity

__all__ = ["BaseLineParams", "BaseLinesEffect"]

NAME = "base-vibration-lines"

#: Largest peak velocity of a base line, in m/s (see BaseLineParams.amplitude).
MAX_VELOCITY = 800e-6 * math.sqrt(2.0)


@dataclass(frozen=True)
class BaseLineParams(EffectParams):
    """One deterministic sinusoid of the base displacement, ``a cos(2 pi f t + phi)``,
    through the closed loop (its phase is free in every record)."""

    effect = NAME

    frequency: float = quantity(
        unit="Hz", doc="frequency of the line", low=1.0,
        high=Bound("fs / 2", lambda ev, p: 0.5 * ev.fs),
        source="below the controller's Nyquist frequency (a line beyond it aliases "
        "in every sampled record)")
    amplitude: float = quantity(
        unit="m", doc="zero-to-peak base displacement of the line", low=0.0,
        high=Bound("1.13e-3 m/s / (2 pi f)",
                   lambda ev, p: MAX_VELOCITY / (2 * math.pi * max(p.frequency, 1e-9))),
        source="peak velocity 2 pi f a at most 1.13 mm/s, the peak of 800 um/s RMS: "
        "the 'workshop' curve of ISO 2631-2:1989 / ANSI S2.71-1983, the least "
        "stringent generic building-vibration criterion; ultra-precision machines "
        "stand on floors of VC-A (50 um/s RMS) or better (Ungar and Gordon, SPIE "
        "(1983); IEST-RP-CC012). At 50 Hz that is 3.6 um, at 3 kHz 60 nm")

    def base_lines(self):
        """The line as ``((frequency, amplitude),)``."""
        return ((self.frequency, self.amplitude),)


def _located(ev):
    """Own located lines of ``ev``: (frequencies by significance, map lines)."""

    def run():
        lines, map_lines = [], []
        for mm in ev.mismatches:
            f = mm.details.get("frequency_hz")
            if mm.test == "line" and f is not None:
                lines.append((mm.significance, f))
                if mm.domain in ("surface", "profile"):
                    map_lines.append(f)
        lu: list[float] = []
        for _sig, f in sorted(lines, key=lambda v: -v[0]):
            if all(abs(f - g) > 1.0 for g in lu):
                lu.append(f)
        return lu[:16], sorted(set(map_lines))

    return ev.memo((NAME, "located"), run)


def line_frequencies(ev) -> list[float]:
    """Candidate line frequencies (Hz): the located lines by significance, then
    those located on the nominal model, at most 16."""
    own = _located(ev)[0]
    if ev.previous is None:
        return own
    return list(dict.fromkeys(own + line_frequencies(ev.previous)))[:16]


def map_line_frequencies(ev) -> list[float]:
    """Line frequencies (Hz) found significant on maps or profiles (the locator's
    frequency search is Bonferroni-corrected)."""
    own = _located(ev)[1]
    if ev.previous is None:
        return own
    return sorted(set(own + map_line_frequencies(ev.previous)))


def line_probe(ev, f: float) -> float:
    """Base amplitude (m) giving one noise level in an idle bin at ``f`` (Hz)."""
    case = ev.case
    p0 = Model()
    s = case.noise_psd(p0, np.array([f]), "fe")[0]
    h = abs(case.paths(p0, np.array([f]))[("base", "fe")][0])
    return math.sqrt(2 * case.fs * max(s, 1e-40) / ev.record_length) / max(h, 1e-12)


class BaseLinesEffect(Effect):
    name = NAME
    title = "Base vibration lines"
    physics = (
        "Deterministic sinusoids in the base (mains harmonics, pumps, floor "
        "modes) on top of the broadband base PSD, a_k cos(2 pi f_k t + phi)."
    )
    signature = (
        "Narrow lines in every following-error spectrum at fixed "
        "frequencies (idle too), not in the FRFs; on maps non-integer "
        "undulations per revolution (spiral moire)."
    )
    confused_with = (
        "spindle orders when k f_spindle coincides (change rpm); "
        "sensor EMI pickup (in the following error but not on the map); "
        "a very lightly damped structural mode (in the FRFs)."
    )
    channels = ("following-error", "cut", "surface", "profile")
    params = BaseLineParams
    max_terms = 8
    #: a line must also be seen at idle when idle records exist (fixed frequency,
    #: present with the spindle stopped): its deviance reduction there must exceed
    #: this (chi2(2) at about p = 0.01)
    require = ("spectrum", 9.0)

    #: a line within this share of the FTS frequency of ``g + k f_FTS`` (g an
    #: accepted line or 0 Hz) is a sideband or a harmonic of the lenslet motion:
    #: the idle records must confirm it
    sideband_tolerance = 0.05
    #: harmonics of the FTS frequency and sidebands of a line treated as locked to
    #: the lenslet motion (the gate's sidebands fall off with k)
    max_harmonic = 10
    max_sideband = 3
    #: a line is "found on the maps" within this many Hz of a located map line (the
    #: located peak is a periodogram bin of a ring, 1 / 1.5 s wide)
    map_tolerance = 1.0

    # ------------------------------------------------------------ channel logic
    def channel_bar(self, model, slot, ev, expected):
        """Idle confirmation a line needs: the fixed bar where the idle records can
        see it, less where they cannot.

        A true line reduces the idle deviance by ``expected`` +- ``2 sqrt(expected)``
        (one standard deviation), so the bar is ``min(bar, expected - 4
        sqrt(expected))``: a high-frequency base line the loop keeps out of the
        following error (or a line the 20 ms idle records do not resolve) is then
        judged on the maps and profiles where it shows, and a line the idle
        records should see but do not is still refused. The lower bar needs
        evidence of its own: the line must have been found significant on a map
        or profile by the locator (whose frequency search is corrected for the
        number of frequencies tried), otherwise the fixed bar stands. Harmonics
        ``k f_FTS`` and sidebands ``g + k f_FTS`` of an accepted line ``g`` keep
        the fixed bar too: on a lenslet surface anything locked to the FTS motion
        (a nonlinearity, hysteresis) and the gating of a real line put lines there
        without a base line at that frequency.
        """
        bar = self.require[1]
        f = self.term(model, slot).frequency
        if all(abs(f - g) > self.map_tolerance for g in map_line_frequencies(ev)):
            return bar
        if self.locked_to_fts(f, model, slot, ev):
            return bar
        return min(bar, expected - 4.0 * math.sqrt(max(expected, 0.0)))

    def locked_to_fts(self, f: float, model: Model, slot: int, ev) -> bool:
        """Whether ``f`` (Hz) is a harmonic ``k f_FTS`` (k = 1..``max_harmonic``) or
        a sideband ``g + k f_FTS`` (0 < |k| <= ``max_sideband``) of a line ``g`` of
        ``model`` other than ``slot``."""
        if ev.fts <= 0:
            return False
        tol = self.sideband_tolerance * ev.fts
        others = [q.frequency for j, q in enumerate(model.get(NAME)) if j != slot]
        for g, kmax in [(0.0, self.max_harmonic)] + [(g, self.max_sideband)
                                                      for g in others]:
            k = round((f - g) / ev.fts)
            if 0 < abs(k) <= kmax and abs(f - g - k * ev.fts) <= tol:
                return True
        return False

    # ------------------------------------------------------------ search
    def configs(self, ev, model):
        have = [q.frequency for q in model.get(NAME)]
        out = []
        for f in line_frequencies(ev):
            if all(abs(f - g) > 1.5 * ev.fs / ev.record_length for g in have):
                out.append(Config(f"{f:.1f} Hz", {"f": float(f)}))
        return out

    def columns(self, model, cfg, ev):
        a = line_probe(ev, cfg.values["f"])
        return [(model.add(BaseLineParams(cfg.values["f"], a)), a)]

    def start(self, model, cfg, coefs, ev):
        f = cfg.values["f"]
        a = line_probe(ev, f) * math.sqrt(max(float(coefs[0]), 0.01))
        return model.add(BaseLineParams(f, a))

    def free(self, model, slot, ev, cfg=None):
        f = self.term(model, slot).frequency
        df = 1.5 * ev.fs / ev.record_length
        return [
            Free(f"frequency_{slot + 1}", NAME, slot, "frequency", max(f - df, 1.0),
                 f + df, located=True),
            Free(f"amplitude_{slot + 1}", NAME, slot, "amplitude", 1e-16, 1e-3, True),
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

    # ------------------------------------------------------------ refinement
    def refine(self, engine, model, term):
        """Grid search of the new line's frequency before the local fit.

        The deviance of long coherent records oscillates in frequency with period
        ``1/T``; a local solver started a bin away would stop in a side minimum.
        Stage 1 scans +-1.5 idle bins at ``1/(4 T)`` of the time records; stage 2
        refines on every block at ``1/(6 T)`` of the longest map or profile around
        the stage-1 frequency, its FTS sidebands and, when the idle records cannot
        confirm the line (:meth:`idle_blind`), the lines located on the maps
        within reach that are not locked to the FTS motion.
        """
        ev = engine.evidence
        i = term.slot
        f0 = self.term(model, i).frequency
        df = ev.fs / ev.record_length

        def with_f(f):
            q = self.term(model, i)
            return model.replace_term(NAME, i, BaseLineParams(float(f), q.amplitude))

        def dev(q, which):
            tot = 0.0
            for k in which:
                b = engine.blocks[k]
                r = engine.block_residual(k, q, cache=not (set(b.groups)
                                                           & self.groups))
                tot += float(r @ r)
            return tot

        # where the idle records cannot confirm the line, the lines located on the
        # maps are starts too (not those locked to the FTS motion: they would need
        # the idle records)
        starts = [
            g for g in map_line_frequencies(ev)
            if not self.locked_to_fts(g, model, i, ev)
        ] if self.idle_blind(engine, model, term) else []
        best = self.scan(engine, model, f0, df, with_f, dev, i, starts)
        q = with_f(best)
        return q if engine.deviance(q) <= engine.deviance(model) else model

    def idle_blind(self, engine, model, term) -> bool:
        """Whether the channel's blocks (the idle records of a line) cannot confirm
        the term as started in ``model``: the gain it would make there if true is
        below the fixed channel bar, or there are no such blocks."""
        g = engine.required_gain(self, model, term.slot)
        return g is None or g[1] < self.require[1]

    def scan(self, engine, model, f0, df, with_f, dev, slot: int, starts) -> float:
        """The two-stage frequency scan of :meth:`refine`; returns Hz."""
        ev = engine.evidence
        time_blocks = [
            k for k, b in enumerate(engine.blocks) if b.domain in ("time", "spectrum")
        ]
        all_blocks = list(range(len(engine.blocks)))

        spans = [engine.blocks[k].time_span for k in time_blocks]
        t1 = max([s for s in spans if s > 0] or [1.0 / df])
        grid = np.arange(f0 - 1.5 * df, f0 + 1.5 * df, 1.0 / (4 * t1))
        best = min(grid, key=lambda f: dev(with_f(f), time_blocks))
        t2 = max([b.time_span for b in engine.blocks] + [t1])
        if t2 > 1.5 * t1:
            # maps and profiles see the tool only while it cuts (a gate at the FTS
            # frequency): a line and its gate sidebands f +- k f_FTS compete, so
            # every alias is refined and the best kept
            centres = (
                [best + k * ev.fts for k in (-1, 0, 1)]
                if ev.fts > 0
                else [best]
            )
            # ``starts`` near f0 too (the lines located on the maps, where the idle
            # records cannot see the line: a high-frequency base line the loop
            # keeps out of the following error leaves the time records' minimum
            # to noise, and the maps' own peaks are the better start). A line the
            # idle records do see keeps their frequency (a map peak near it may be
            # another line's sideband, which the channel logic would refuse).
            reach = 1.5 * df + 2.0 * ev.fts
            centres += [g for g in starts if abs(g - f0) <= reach]
            # not onto another line of the model: two lines closer than the longest
            # record resolves are one line split in two
            others = [q.frequency for j, q in enumerate(model.get(NAME)) if j != slot]
            centres = [c for c in centres if all(abs(c - g) > 1.0 / t2 for g in others)]
            cands = []
            done: list[float] = []
            for c in centres:
                if c <= 1.0 or any(abs(c - d) < 1.0 / (6 * t1) for d in done):
                    continue
                done.append(c)
                fine = np.arange(c - 1.0 / (6 * t1), c + 1.0 / (6 * t1), 1.0 / (6 * t2))
                fb = min(fine, key=lambda f: dev(with_f(f), all_blocks))
                cands.append((dev(with_f(fb), all_blocks), fb))
            best = min(cands)[1]
        return float(best)
