"""Stepwise selection logic of :class:`servosurf.diagnose._select.Engine`.

The engine's fitting and deviance are replaced by stubs so that only the search
logic runs: which ranked configurations get fitted and which one is accepted.
"""

from __future__ import annotations

import math

import numpy as np

from servosurf.diagnose import Mismatch, Model
from servosurf.diagnose import _select
from servosurf.diagnose._select import CHANNEL_RETRIES, Candidate, Engine, Term
from servosurf.diagnose.effects import BaseLineParams, Config, Evidence


def _ev(fs=1e4, record_length=4096.0, fts=0.0, map_line_freqs=()):
    """Evidence with lines located on a ring profile at ``map_line_freqs`` (Hz)."""
    mism = tuple(
        Mismatch("ring0.npz", "profile", f"line at {f} Hz", 10.0, "line",
                 {"frequency_hz": float(f)})
        for f in map_line_freqs
    )
    return Evidence(fs=fs, record_length=record_length, fts=fts, mismatches=mism)


def _lines_model(freqs, amps):
    return Model.of(*(BaseLineParams(f, a) for f, a in zip(freqs, amps, strict=True)))


class _Eff:
    """Minimal stand-in for a catalogue module (what ``Engine.run`` reads)."""

    def __init__(self, name):
        self.name = name
        self.n_start = 1
        self.threshold = False
        self.recalibration = False

    def configs(self, ev, p):
        return [None]

    def distinct(self, cfg, previous):
        return False


def _engine(cands, scores):
    """Engine whose first screening returns ``cands`` and whose fit of a
    candidate labelled L scores ``scores[L]`` (-inf: refused by the channel
    logic); later screenings return nothing."""
    eng = Engine([], _ev(), [c.effect for c in cands], lambda p: [])
    calls = {"screen": 0, "fitted": []}

    def screen(p, terms):
        calls["screen"] += 1
        return list(cands) if calls["screen"] == 1 else []

    def evaluate(c, p, terms, d_cur, progress=None):
        calls["fitted"].append(c.config.label)
        return scores[c.config.label], p, Term(c.effect, 0, c.config), 1.0

    eng.screen = screen
    eng._evaluate = evaluate
    eng.fit = lambda p, terms, **kw: p
    eng.prune = lambda p, terms: (p, terms)
    eng.enforce_plausibility = lambda p, terms, progress=None: (p, terms)
    return eng, calls


def _cand(eff, label, score):
    return Candidate(eff, Config(label, {}), lam=score, score=score, coefs=np.ones(1))


def test_refused_configuration_gives_way_to_the_modules_next_one():
    lines, other = _Eff("lines"), _Eff("other")
    cands = [_cand(lines, "sideband", 500.0), _cand(lines, "sideband-2", 400.0),
             _cand(lines, "true line", 300.0), _cand(other, "o", 200.0),
             _cand(lines, "later", 190.0)]
    eng, calls = _engine(cands, {"sideband": -math.inf, "sideband-2": -math.inf,
                                 "true line": 50.0, "o": -3.0, "later": 60.0})
    _, terms, _ = eng.run(max_terms=3)
    assert [t.config.label for t in terms] == ["true line"]
    # the module's configurations are fitted in rank order until one is admitted
    # (then the retries stop: "later" is not fitted)
    assert calls["fitted"] == ["sideband", "o", "sideband-2", "true line"]


def test_retries_are_bounded_and_nothing_refused_is_accepted():
    lines = _Eff("lines")
    labels = [f"s{k}" for k in range(CHANNEL_RETRIES + 3)]
    cands = [_cand(lines, lab, 100.0 - k) for k, lab in enumerate(labels)]
    scores = dict.fromkeys(labels, -math.inf)
    scores[labels[-1]] = 80.0  # beyond the retry budget: never fitted
    eng, calls = _engine(cands, scores)
    _, terms, _ = eng.run(max_terms=3)
    assert terms == []
    assert calls["fitted"] == labels[:CHANNEL_RETRIES + 1]


def test_no_retry_when_the_best_configuration_is_admitted():
    lines = _Eff("lines")
    cands = [_cand(lines, "a", 100.0), _cand(lines, "b", 90.0)]
    eng, calls = _engine(cands, {"a": 20.0, "b": 30.0})
    _, terms, _ = eng.run(max_terms=3)
    assert [t.config.label for t in terms] == ["a"]
    assert calls["fitted"] == ["a"]


# ------------------------------------------------------------------ verdict
def _mm(sig):
    from servosurf.diagnose._locate import Mismatch

    return Mismatch("idle.npz", "spectrum", "band 250-315 Hz", sig, "band-power", {})


def test_weak_remainder_does_not_make_a_verdict():
    from servosurf.diagnose._diagnose import _verdict

    # the strongest stray locator hit of 100 null cases had significance 4.98;
    # the weakest remainder of an out-of-catalogue case of the blind suite 16.5
    weak, strong = _mm(5.0), _mm(16.5)
    assert _verdict(False, False, [weak], 0.0, 0.0) == "consistent"
    assert _verdict(False, False, [], 0.0, 0.0) == "consistent"
    assert _verdict(False, False, [strong], 0.0, 10.0) == "unexplained"
    assert _verdict(False, True, [], 0.0, 0.0) == "unexplained"  # recalibration
    assert _verdict(True, False, [weak], 50.0, 0.0) == "explained"
    assert _verdict(True, False, [strong], 50.0, 10.0) == "partly-explained"
    assert _verdict(True, False, [strong], 5.0, 50.0) == "unexplained"


# ------------------------------------------------------------------ base lines
def _lines_effect():
    from servosurf.diagnose import get_effect

    return get_effect("base-vibration-lines")


def test_line_idle_bar_follows_what_the_idle_records_can_see():
    eff = _lines_effect()
    fixed = eff.require[1]
    loc = _ev(fs=2e5, record_length=4096, fts=100.0, map_line_freqs=[3050.4])
    p = _lines_model((3050.0,), (1e-7,))
    for expected in (0.0, 1.0, 9.0, 16.0, 25.0, 36.0, 400.0):
        want = min(fixed, expected - 4.0 * math.sqrt(expected))
        assert eff.channel_bar(p, 0, loc, expected) == want
    assert eff.channel_bar(p, 0, loc, 400.0) == fixed
    assert eff.channel_bar(p, 0, loc, 1.0) < 0.0
    # the lower bar needs the line to be found on a map or profile
    far = _ev(fs=2e5, record_length=4096, fts=100.0, map_line_freqs=[3052.0])
    assert eff.channel_bar(p, 0, far, 1.0) == fixed
    assert eff.channel_bar(p, 0, _ev(fs=2e5, fts=100.0), 1.0) == fixed


def test_sidebands_of_an_accepted_line_keep_the_fixed_bar():
    eff = _lines_effect()
    fixed = eff.require[1]
    found = [3050.0 + k * 100.0 + 4.0 for k in (-3, -2, -1, 1, 2, 3)] + [3230.0, 3150]
    loc = _ev(fs=2e5, record_length=4096, fts=100.0, map_line_freqs=found)
    for k in (-3, -2, -1, 1, 2, 3):
        p = _lines_model((3050.0, 3050.0 + k * 100.0 + 4.0), (1e-7, 1e-8))
        assert eff.channel_bar(p, 1, loc, 1.0) == fixed
    # 20 Hz off every sideband and harmonic: a line of its own, judged on what
    # the idle records can see
    p = _lines_model((3050.0, 3230.0), (1e-7, 1e-8))
    assert eff.channel_bar(p, 1, loc, 1.0) == 1.0 - 4.0
    # harmonics of the lenslet motion (a hysteresis locked to the FTS puts lines
    # there) need the idle records too, alone or beside another line
    for f in (400.3, 998.0):
        loc_h = _ev(fs=2e5, record_length=4096, fts=100.0, map_line_freqs=[f])
        assert eff.channel_bar(_lines_model((f,), (1e-9,)), 0, loc_h, 1.0) == fixed
    loc_h = _ev(fs=2e5, record_length=4096, fts=100.0, map_line_freqs=[430.0])
    assert eff.channel_bar(_lines_model((430.0,), (1e-9,)), 0, loc_h,
                           1.0) == 1.0 - 4.0
    # without a lenslet toolpath there are no sidebands
    loc0 = _ev(fs=2e5, record_length=4096, fts=0.0, map_line_freqs=found)
    p = _lines_model((3050.0, 3150.0), (1e-7, 1e-8))
    assert eff.channel_bar(p, 1, loc0, 1.0) == 1.0 - 4.0


class _IdleBlock:
    domain = "spectrum"
    groups = ("base_lines",)
    time_span = 0.0

    def __init__(self, data, template):
        self.data, self.template, self.n = data, template, data.size

    def residual(self, p):
        a = sum(q.amplitude for q in p.get("base-vibration-lines"))
        return self.data - a * self.template


def _channel(data, template):
    eff = _lines_effect()
    loc = _ev(fs=2e5, record_length=4096, fts=100.0, map_line_freqs=[3050.0])
    eng = Engine([_IdleBlock(data, template)], loc, [eff], lambda p: [])
    q = _lines_model((3050.0,), (1.0,))
    return eng._channel_ok(eff, q, Term(eff, 0))


def test_channel_logic_judges_a_line_by_its_own_idle_prediction():
    rng = np.random.default_rng(5)
    n = 2000
    noise = rng.standard_normal(n)
    shape = rng.standard_normal(n)
    shape /= np.linalg.norm(shape)
    strong, faint = 10.0 * shape, 1.0 * shape  # expected idle gain 100 and 1
    # visible at idle and there: admitted; visible at idle and absent: refused
    assert _channel(noise + strong, strong)
    assert not _channel(noise, strong)
    # a line the idle records cannot see (a 3 kHz base line the loop keeps out of
    # the following error) is not refused for their silence
    assert _channel(noise, faint)


class _TimeRec:
    domain = "time"
    groups = ("base_lines",)
    fs = 2e5
    n = 32768
    time_span = 32768 / 2e5  # 0.164 s


class _Profile:
    domain = "profile"
    groups = ("base_lines",)
    n = 200
    time_span = 1.49  # one revolution of a ring


def _scan(f_true, f_noise, located, lines=(), blind=True):
    loc = _ev(fs=2e5, record_length=4096, fts=100.0, map_line_freqs=list(located))
    eng = Engine([_TimeRec(), _Profile()], loc, [], lambda p: [])
    p = _lines_model(tuple(lines) + (f_noise,), (1e-7,) * (len(lines) + 1))
    slot = len(lines)

    def with_f(f):
        return p.replace_term("base-vibration-lines", slot,
                              BaseLineParams(float(f), 1e-7))

    def dev(q, which):
        f = q.get("base-vibration-lines")[slot].frequency
        # the time records barely see the line: their minimum is noise, 30 Hz off;
        # the profile's minimum is sharp (1/T of a 1.49 s revolution) at the truth
        d = 5.0 * (1.0 - math.exp(-(((f - f_noise) / 20.0) ** 2)))
        if 1 in which:
            d += 1e3 * (1.0 - math.exp(-(((f - f_true) / 0.3) ** 2)))
        return d

    df = loc.fs / loc.record_length
    return _lines_effect().scan(eng, p, f_noise, df, with_f, dev, slot,
                                list(located) if blind else [])


def test_line_search_starts_from_the_maps_peaks_when_time_records_are_blind():
    f_true = 3050.69
    # stage 1 lands on the time records' noise minimum (f_true - 30 Hz); the
    # located map peak (0.4 Hz off) brings the refinement to the truth
    best = _scan(f_true, f_true - 30.0, [f_true + 0.4, f_true + 100.5])
    assert abs(best - f_true) < 0.1
    # a located peak on another line of the model is not a start (closer than the
    # 1.49 s profile resolves: one line split in two)
    other = _scan(f_true, f_true + 60.0, [f_true + 0.4], lines=(f_true + 0.2,))
    assert abs(other - f_true) > 1.0 / 1.49
    # a line the idle records can confirm keeps the time records' frequency
    seen = _scan(f_true, f_true - 30.0, [f_true + 0.4], blind=False)
    assert abs(seen - (f_true - 30.0)) < 2.0


def test_idle_blindness_is_the_lines_own_idle_gain_against_the_bar():
    eff = _lines_effect()
    rng = np.random.default_rng(8)
    shape = rng.standard_normal(500)
    shape /= np.linalg.norm(shape)
    p = _lines_model((3050.0,), (1.0,))
    for gain, blind in ((1.0, True), (8.9, True), (9.1, False), (100.0, False)):
        blk = _IdleBlock(rng.standard_normal(500), math.sqrt(gain) * shape)
        eng = Engine([blk], _ev(fs=2e5), [eff], lambda p: [])
        assert eff.idle_blind(eng, p, Term(eff, 0)) is blind
    # no idle records: nothing can confirm the line
    eng = Engine([_Profile()], _ev(fs=2e5), [eff], lambda p: [])
    assert eff.idle_blind(eng, p, Term(eff, 0)) is True


def test_map_starts_exclude_lines_locked_to_the_fts_motion(monkeypatch):
    eff = _lines_effect()
    loc = _ev(fs=2e5, record_length=4096, fts=100.0,
              map_line_freqs=[149.7, 200.2, 3051.1])
    eng = Engine([_Profile()], loc, [eff], lambda p: [])
    seen = {}

    def scan(engine, p, f0, df, with_f, dev, slot, starts):
        seen["starts"] = list(starts)
        return f0

    monkeypatch.setattr(type(eff), "scan", lambda self, *a: scan(*a))
    eng.deviance = lambda q: 0.0
    p = _lines_model((49.99, 2950.6), (1e-9, 1e-7))
    eff.refine(eng, p, Term(eff, 1))
    # 149.7 = 49.99 + f_FTS (a sideband), 200.2 = 2 f_FTS (a harmonic)
    assert seen["starts"] == [3051.1]
    monkeypatch.setattr(type(eff), "idle_blind", lambda self, *a: False)
    eff.refine(eng, p, Term(eff, 1))
    assert seen["starts"] == []


# ------------------------------------------------------------------ plausibility
def test_a_candidate_at_a_bound_is_refused_with_its_reason(monkeypatch):
    from servosurf.diagnose import get_effect

    # no recordings here: the model-fidelity floor (test_acceptance.py) is off
    monkeypatch.setattr(_select, "FIDELITY_ENR", 0.0)

    mode = get_effect("structural-mode")
    eng = Engine([], _ev(fs=2e5), [mode], lambda p: [])
    eng.fit = lambda q, terms, **kw: q
    eng.deviance = lambda q: 100.0 if q == Model() else 10.0
    # damping 0.5: the end of the fit's range (a resonance too wide to be one)
    c = Candidate(mode, Config("6100 Hz, zeta 0.5", {"f": 6100.0, "z": 0.5}), 90.0,
                  80.0, np.ones(1))
    score, q, term, lam = eng._evaluate(c, Model(), [], 100.0)
    assert score == -math.inf and lam == 90.0
    ref = eng.refused["structural-mode"]
    assert "damping_ratio" in ref.reason and ref.score > 0
    assert ref.parameters["frequency_hz"] == 6100.0
    ok = Candidate(mode, Config("6100 Hz, zeta 0.02", {"f": 6100.0, "z": 0.02}), 90.0,
                   80.0, np.ones(1))
    assert eng._evaluate(ok, Model(), [], 100.0)[0] > 0


def test_a_term_the_refit_leaves_implausible_is_dropped(monkeypatch):
    from servosurf.diagnose import get_effect

    monkeypatch.setattr(_select, "FIDELITY_ENR", 0.0)  # no recordings here
    from servosurf.diagnose.effects import LoopDelayParams, StructuralModeParams

    mode, delay = get_effect("structural-mode"), get_effect("loop-delay")
    eng = Engine([], _ev(fs=2e5), [mode, delay], lambda p: [])
    eng.fit = lambda q, terms, **kw: q
    eng.deviance = lambda q: 0.0
    p = Model.of(StructuralModeParams(6100.0, 0.5, 1e-9), LoopDelayParams(1e-6))
    terms = [Term(mode, 0, None, 50.0, 30.0), Term(delay, 0, None, 40.0, 20.0)]
    q, kept = eng.enforce_plausibility(p, terms)
    assert q == Model.of(LoopDelayParams(1e-6))
    assert [t.effect.name for t in kept] == ["loop-delay"]
    assert "damping_ratio" in eng.refused["structural-mode"].reason


# ------------------------------------------------------------------ alternatives
def test_modules_that_fit_as_well_are_reported_with_the_named_one(monkeypatch):
    """The round's winner carries every other admitted module whose deviance
    reduction is within ALTERNATIVE_MARGIN of its own (closest first), never a
    refused one, a recalibration or another configuration of itself."""
    from servosurf.diagnose import get_effect

    names = ("elastic-recovery", "tool-radius-error", "tool-wear",
             "tool-edge-waviness", "recalibration", "thermal-drift")
    effs = {n: get_effect(n) for n in names}
    for e in effs.values():  # the models here hold no terms to report
        monkeypatch.setattr(e, "report", lambda q, slot, _n=e.name: {"of": _n})
    eng = Engine([], _ev(), list(effs.values()), lambda p: [])
    m = _select.ALTERNATIVE_MARGIN

    def res(name, lam, score=10.0):
        return (score, Model(), Term(effs[name], 0, None), lam)

    best = res("elastic-recovery", 144.7)
    results = [best, res("elastic-recovery", 144.0),      # itself
               res("tool-wear", 144.5), res("tool-radius-error", 144.6),
               res("tool-edge-waviness", 144.7 - m - 0.01),  # just outside
               res("thermal-drift", 144.7, score=-math.inf),  # refused
               res("recalibration", 150.0)]
    alts = eng._alternatives(best, results)
    assert [a["effect"] for a in alts] == ["tool-radius-error", "tool-wear"]
    assert alts[0]["delta_deviance"] == 144.6
    assert alts[0]["parameters"] == {"of": "tool-radius-error"}
    results[4] = res("tool-edge-waviness", 144.7 - m + 0.01)
    assert "tool-edge-waviness" in [a["effect"] for a in eng._alternatives(best,
                                                                           results)]
