"""Out-of-sample acceptance of :class:`servosurf.diagnose._select.Engine` (issue 19
items 3 and 4): held-out test, per-recording agreement, :func:`block_split`.

The engine runs for real (its fit, split and deviance) on a linear toy world:
blocks whose whitened residual is ``y - sum_k a_k x_k`` with seeded Gaussian
noise, and modules that each add one column. The oracles are closed forms
computed here with plain numpy (least squares of one column, chi2 quantiles).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy as sp

from servosurf.diagnose._blocks import Block
from servosurf.diagnose import _select
from servosurf.diagnose._select import (
    FIDELITY_ENR,
    HELD_OUT_ALPHA,
    MAP_WINDOW,
    Engine,
    Term,
    block_split,
    recording_bar,
)


class _P:
    """Toy model: amplitudes by module name."""

    def __init__(self, a=None):
        self.a = dict(a or {})

    def key(self, groups):
        return tuple(sorted(self.a.items()))


class _Free:
    def __init__(self, name):
        self.name = name
        self.lo, self.hi, self.log = -100.0, 100.0, False
        self.located = False

    def get(self, q):
        return getattr(q, "a", {}).get(self.name, 0.0)

    def set(self, q, v):
        return _P({**q.a, self.name: float(v)})


class _Block(Block):
    """Residual ``y - sum_k a_k x_k`` of one recording."""

    groups = ("toy",)

    def __init__(self, recording, domain, y, cols):
        super().__init__(recording, "toy", domain, int(y.size))
        self.y = y
        self.cols = cols

    def residual(self, p):
        a = getattr(p, "a", {})
        r = self.y.copy()
        for k, x in self.cols.items():
            r = r - a.get(k, 0.0) * x
        return r


class _Eff:
    """Toy module: one amplitude ``a[name]``."""

    require = None
    recalibration = False
    threshold = False

    def __init__(self, name):
        self.name = name
        self.groups = frozenset({"toy"})

    def n_params(self, cfg=None):
        return 1

    def free(self, p, slot, ev, cfg):
        return [_Free(self.name)]

    def remove(self, q, slot):
        return _P({k: v for k, v in q.a.items() if k != self.name})

    def implausible(self, q, slot, ev, cfg):
        return None


def _full_fit(eng, eff):
    """The engine's fit of ``eff`` on all the data (as the in-sample pass)."""
    t = Term(eff, 0, None)
    q = eng.fit(_P({eff.name: 0.01}), [t])
    return q, t


def _oracle_held_drop(y, x, fit, held):
    """Closed-form held-out drop of one column fitted on ``fit`` (plain numpy)."""
    a = float(x[fit] @ y[fit]) / float(x[fit] @ x[fit])
    yb, xb = y[held], x[held]
    return float(yb @ yb) - float((yb - a * xb) @ (yb - a * xb))


def test_pure_noise_in_sample_bic_pick_is_refused_by_the_held_out_rule():
    rng = np.random.default_rng(3)
    n, m = 256, 60
    y = rng.standard_normal(n)
    xs = rng.standard_normal((m, n))
    # plain-numpy in-sample pick: largest one-column deviance drop vs BIC's ln n
    lam = (xs @ y) ** 2 / np.einsum("ij,ij->i", xs, xs)
    k = int(np.argmax(lam))
    assert lam[k] > math.log(n)  # BIC (q = 1) would accept this noise column
    block = _Block("fe", "force", y, {f"c{k}": xs[k]})
    eng = Engine([block], None, [], None)
    eff = _Eff(f"c{k}")
    q, t = _full_fit(eng, eff)
    assert q.a[eff.name] == pytest.approx(
        float(xs[k] @ y) / float(xs[k] @ xs[k]), rel=1e-4
    )
    h = eng.held_out(eff, q, t, [])
    fit, held = block_split(block)
    drop = _oracle_held_drop(y, xs[k], fit, held)
    assert h["delta_deviance"] == pytest.approx(drop, abs=0.02)
    assert not h["in_sample_fallback"]
    assert not h["passed"]
    assert drop < sp.stats.chi2.isf(HELD_OUT_ALPHA, 1)
    why = eng.out_of_sample_refusal(eff, q, t, [])
    assert why is not None and why.startswith("no held-out improvement")


def test_true_effect_passes_the_held_out_rule():
    rng = np.random.default_rng(4)
    n = 256
    x = rng.standard_normal(n)
    y = rng.standard_normal(n) + 0.5 * x
    block = _Block("fe", "force", y, {"true": x})
    eng = Engine([block], None, [], None)
    eff = _Eff("true")
    q, t = _full_fit(eng, eff)
    h = eng.held_out(eff, q, t, [])
    fit, held = block_split(block)
    drop = _oracle_held_drop(y, x, fit, held)
    thr = float(sp.stats.chi2.isf(HELD_OUT_ALPHA, 1))
    assert drop > thr
    assert h["passed"] and h["delta_deviance"] == pytest.approx(drop, abs=0.02)
    assert h["p_value"] == pytest.approx(float(sp.stats.chi2.sf(drop, 1)), rel=1e-3)
    assert h["threshold"] == pytest.approx(thr, abs=0.01)
    assert eng.out_of_sample_refusal(eff, q, t, []) is None
    assert t.held_out == h


def test_too_few_held_out_values_fall_back_to_the_in_sample_rule():
    rng = np.random.default_rng(5)
    y = rng.standard_normal(100)  # 50 held-out values < HELD_OUT_MIN
    block = _Block("fe", "force", y, {"c": rng.standard_normal(100)})
    eng = Engine([block], None, [], None)
    eff = _Eff("c")
    q, t = _full_fit(eng, eff)
    assert eng.out_of_sample_refusal(eff, q, t, []) is None
    h = t.held_out
    assert h["in_sample_fallback"] and h["passed"] and h["n_held_out"] == 50
    acc = eng.acceptance([t])
    assert acc["in_sample_fallback"] is True


def _two_recordings(map_amp, seed=6, amp=0.5):
    """A line of amplitude ``amp`` on the following error whose map signature
    in the data is ``map_amp`` times the one it predicts there."""
    rng = np.random.default_rng(seed)
    n = 256
    x_fe = rng.standard_normal(n)
    x_map = rng.standard_normal(n)
    y_fe = rng.standard_normal(n) + amp * x_fe
    y_map = rng.standard_normal(n) + map_amp * amp * x_map
    blocks = [
        _Block("fe", "time", y_fe, {"line": x_fe}),
        _Block("map", "map", y_map, {"line": x_map}),
    ]
    return blocks, (y_fe, x_fe, y_map, x_map)


@pytest.mark.parametrize("map_amp", [0.0, 1.0])
def test_line_fitted_on_following_error_must_show_on_the_map(map_amp):
    blocks, (y_fe, x_fe, y_map, x_map) = _two_recordings(map_amp)
    eng = Engine(blocks, None, [], None)
    eff = _Eff("line")
    q, t = _full_fit(eng, eff)
    # oracle: joint least squares and the map's observed / expected reduction
    a = float(x_fe @ y_fe + x_map @ y_map) / float(x_fe @ x_fe + x_map @ x_map)
    assert q.a["line"] == pytest.approx(a, rel=1e-4)
    expected = a**2 * float(x_map @ x_map)
    observed = float(y_map @ y_map) - float((y_map - a * x_map) @ (y_map - a * x_map))
    bar = 0.5 * expected - 6.0 * math.sqrt(expected)
    assert recording_bar(expected) == pytest.approx(bar)
    why = eng.refusal(eff, q, t)
    if map_amp == 0.0:
        assert expected > 9 and observed < bar
        assert why is not None and "predicted on map (map), not seen" in why
    else:
        assert observed >= bar
        assert why is None
        # leave one recording out: each recording predicts the other's signature
        assert eng.recording_refusal(eff, q, t, []) is None


def test_leave_one_recording_out_refuses_a_signature_carried_by_one_recording():
    # the map shows a weak, partial signature: in sample the joint fit passes the
    # map's bar, but fitted on the following error alone it predicts far more
    blocks, (y_fe, x_fe, y_map, x_map) = _two_recordings(0.5, seed=8, amp=1.875)
    eng = Engine(blocks, None, [], None)
    eff = _Eff("line")
    q, t = _full_fit(eng, eff)
    a_fe = float(x_fe @ y_fe) / float(x_fe @ x_fe)  # oracle: fit without the map
    exp_map = a_fe**2 * float(x_map @ x_map)
    obs_map = float(y_map @ y_map) - float(
        (y_map - a_fe * x_map) @ (y_map - a_fe * x_map)
    )
    assert obs_map < 0.5 * exp_map - 6.0 * math.sqrt(exp_map)
    assert eng.refusal(eff, q, t) is None
    why = eng.recording_refusal(eff, q, t, [])
    assert why is not None and "predicted on map" in why
    assert "other recordings" in why


def test_an_idle_spectrum_alone_does_not_predict_another_recording():
    """The same weak map signature, but the recording that carries the line is an
    idle spectrum: its line level is not separable from the noise level in a
    bin, so the map is not left out to be predicted from it alone (the
    in-sample bar still applies); the time-record version is refused above."""
    blocks, _ = _two_recordings(0.5, seed=8, amp=1.875)
    blocks[0].domain = "spectrum"
    eng = Engine(blocks, None, [], None)
    eff = _Eff("line")
    q, t = _full_fit(eng, eff)
    assert eng.refusal(eff, q, t) is None
    assert eng.recording_refusal(eff, q, t, []) is None


# ------------------------------------------------------------ fidelity floor
def test_signature_is_the_rms_of_the_whitened_change_in_its_largest_recording():
    rng = np.random.default_rng(11)
    x_fe, x_map = rng.standard_normal(300), rng.standard_normal(1200)
    y_fe = rng.standard_normal(300) + 0.3 * x_fe
    y_map = rng.standard_normal(1200) + 0.3 * x_map
    blocks = [_Block("fe", "time", y_fe, {"c": x_fe}),
              _Block("map", "map", y_map, {"c": x_map})]
    eng = Engine(blocks, None, [], None)
    eff = _Eff("c")
    q, t = _full_fit(eng, eff)
    a = q.a["c"]
    sig = eng.signature(eff, q, 0)
    # oracle, plain numpy: RMS of a x over the unit noise RMS, per recording
    for name, x, y in (("fe", x_fe, y_fe), ("map", x_map, y_map)):
        rec = sig["by_recording"][name]
        assert rec["n_values"] == x.size
        assert rec["signature_enr"] == pytest.approx(
            math.sqrt(float(np.mean((a * x) ** 2))), rel=1e-9)
        assert rec["expected_delta_deviance"] == pytest.approx(
            a**2 * float(x @ x), abs=0.01)
        obs = float(y @ y) - float((y - a * x) @ (y - a * x))
        assert rec["delta_deviance"] == pytest.approx(obs, abs=0.01)
    best = max(("fe", "map"), key=lambda r: sig["by_recording"][r]["signature_enr"])
    assert sig["recording"] == best
    assert sig["signature_enr"] == sig["by_recording"][best]["signature_enr"]


@pytest.mark.parametrize("share", [0.5, 3.0])
def test_a_significant_term_below_the_fidelity_floor_is_not_named(share):
    """A real column at ``share`` times the floor, on enough values that even
    the small one is significant by far: below the floor it is refused with
    the reason, above it is admitted."""
    assert FIDELITY_ENR > 0  # the floor is derived, never switched off
    n = int(math.ceil(400.0 / FIDELITY_ENR**2))  # deviance ~ 400 share^2
    rng = np.random.default_rng(12)
    x = rng.standard_normal(n)
    y = rng.standard_normal(n) + share * FIDELITY_ENR * x
    eng = Engine([_Block("map", "map", y, {"c": x})], None, [], None)
    eff = _Eff("c")
    q, t = _full_fit(eng, eff)
    lam = float(y @ y) - float((y - q.a["c"] * x) @ (y - q.a["c"] * x))
    assert lam > sp.stats.chi2.isf(1e-6, 1)  # significant either way
    why = eng.refusal(eff, q, t)
    if share < 1:
        assert why is not None and "model-fidelity floor" in why
        assert "map" in why
    else:
        assert why is None
    assert eng.signature(eff, q, 0)["recording"] == "map"


def test_the_fidelity_floor_does_not_apply_to_recalibration(monkeypatch):
    n = 4000
    rng = np.random.default_rng(13)
    x = rng.standard_normal(n)
    y = rng.standard_normal(n) + 0.2 * FIDELITY_ENR * x
    eng = Engine([_Block("map", "map", y, {"c": x})], None, [], None)
    eff = _Eff("c")
    q, t = _full_fit(eng, eff)
    assert eng.fidelity_refusal(eff, q, t) is not None
    eff.recalibration = True
    assert eng.fidelity_refusal(eff, q, t) is None
    monkeypatch.setattr(_select, "FIDELITY_ENR", 0.0)
    eff.recalibration = False
    assert eng.fidelity_refusal(eff, q, t) is None


def _meta(sizes):
    return [(np.ones(m, dtype=bool), None, None) for m in sizes]


@pytest.mark.parametrize(
    ("domain", "n", "sizes"),
    [
        ("time", 2 * (10 + 12 + 10), (10, 12, 10)),
        ("time", 2 * 33, (33,)),
        ("frf", 2 * 41, ()),
        ("spectrum", 77, ()),
        ("map", 101, ()),
        ("profile", 64, ()),
        ("force", 9, ()),
    ],
)
def test_block_split_halves_are_disjoint_and_cover_everything(domain, n, sizes):
    b = Block("r", "k", domain, n)
    if sizes:
        b.meta = _meta(sizes)
    fit, held = block_split(b)
    assert np.intersect1d(fit, held).size == 0
    assert np.array_equal(np.sort(np.concatenate([fit, held])), np.arange(n))
    assert abs(fit.size - held.size) <= max(MAP_WINDOW, 2 * max(sizes, default=1))
    half = np.zeros(n, dtype=int)
    half[held] = 1
    if domain == "time" and len(sizes) >= 2:
        # whole records alternate: record 1 (both parts) held out, 0 and 2 fitted
        assert np.all(half[:20] == 0) and np.all(half[20:44] == 1)
        assert np.all(half[44:] == 0)
    elif domain == "time":
        # bins alternate, the real and imaginary part of a bin together
        assert np.array_equal(half[:33], np.arange(33) % 2)
        assert np.array_equal(half[:33], half[33:])
    elif domain == "frf":
        assert np.array_equal(half[:41], half[41:])
        assert np.array_equal(half[:41], np.arange(41) % 2)
    elif domain in ("map", "profile"):
        assert np.array_equal(half, (np.arange(n) // MAP_WINDOW) % 2)
    else:
        assert np.array_equal(half, np.arange(n) % 2)
