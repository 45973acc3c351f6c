"""Stepwise selection logic of :class:`servosurf.diagnose._select.Engine`.

The engine's fitting and deviance are replaced by stubs so that only the search
logic runs: which ranked configurations get fitted and which one is accepted.
"""

from __future__ import annotations

import math

import numpy as np

from servosurf.diagnose._catalogue import Config, Locations
from servosurf.diagnose._select import CHANNEL_RETRIES, Candidate, Engine, Term


class _Eff:
    """Minimal stand-in for a catalogue module (what ``Engine.run`` reads)."""

    def __init__(self, name):
        self.name = name
        self.n_start = 1
        self.threshold = False
        self.recalibration = False

    def configs(self, loc, p):
        return [None]


def _engine(cands, scores):
    """Engine whose first screening returns ``cands`` and whose fit of a
    candidate labelled L scores ``scores[L]`` (-inf: refused by the channel
    logic); later screenings return nothing."""
    eng = Engine([], Locations(fs=1e4), [c.effect for c in cands], lambda p: [])
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
