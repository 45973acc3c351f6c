"""The loop-side catalogue effects detected on cases of the independent generator.

Each case is written by the independent simulator (``benchmarks/discovery/
independent``: its own loop, noise and effect forms, none of them the catalogue's
fitting form): LuGre friction with a Stribeck peak, Dahl hysteresis, a soft dead
zone ahead of a truncating DAC, mains pickup harmonics with a drifting phase. The
campaign is small (idle records and one air cut, following error only) so that a
diagnosis takes about a minute; the diagnosis must name the effect first (the
pickup lines: or a base line, which only a map would refuse), never call the case
consistent. Seeds are fixed; the strengths put each effect a
few noise levels above the records' noise.
"""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.diagnose import CATALOGUE, diagnose

#: Catalogue modules of the following-error channel the cases are compared with
#: (the map-only modules cannot change these recordings).
TIME_CHANNEL = [e.name for e in CATALOGUE if "following-error" in e.channels]


@pytest.fixture(scope="module")
def gen(discovery):
    class NS:
        campaign = discovery("independent.campaign")
        effects = discovery("independent.effects")
        loop = discovery("independent.loop")

    NS.ctx = NS.campaign.context(False)
    return NS


def _case(gen, tmp_path, spec, seed):
    cp = gen.campaign
    camp = cp.Campaign(idle={"records": 8, "length": 4096, "div": 1, "fmt": "npz"},
                       air={"length": 16384, "div": 1, "fmt": "npz"})
    rec = cp.recordings(gen.ctx, camp, spec, seed)
    cp.write_case(tmp_path, gen.ctx, camp, rec)
    effects = [e for e in CATALOGUE if e.name in TIME_CHANNEL]
    return diagnose(tmp_path / "manifest.toml", effects=effects)


def _named(d):
    """Physics named, the largest delta-BIC first."""
    ex = sorted(d.explanations, key=lambda e: -(e.get("delta_bic") or 0.0))
    return [e["effect"] for e in ex]


CASES = {
    # name: (generator spec, expected catalogue name)
    "lugre-friction": (lambda E: E.Spec(loop=E.LoopEffects(
        hyst=3, h_k=0.02 / 0.5e-6, h_a=0.02, h_b=0.026, fric_vs=3e-5)), "friction"),
    "dahl-hysteresis": (lambda E: E.Spec(loop=E.LoopEffects(
        hyst=2, h_k=400.0, h_a=400.0 * 1.5e-6)), "flexure-hysteresis"),
    "soft-dead-zone": (lambda E: E.Spec(loop=E.LoopEffects(
        dac_dead=2e-3, dac_q=3e-5, conv_trunc=True)), "converter-quantisation"),
    # without a map a line in the following error has two explanations of equal
    # likelihood (a base line's amplitude through the loop is free too): only
    # the maps tell a sensor line from a base line (issue 19, item 4), so here
    # either name counts and the case must not be called consistent
    "mains-pickup": (lambda E: E.Spec(pickup=((150.0, 4e-9, 0.2, 0.1),
                                              (450.0, 1.5e-9, 0.6, 0.1))),
                     ("sensor-pickup-lines", "base-vibration-lines")),
}


#: Cases run by the suite (a diagnosis each: 10-90 s). The others are a
#: measurement, run by ``python tests/diagnose/test_loop_effects_detection.py``
#: (every case, one row each); on 2026-11-29 all four named their effect first.
IN_SUITE = ("dahl-hysteresis",)


@pytest.mark.slow
@pytest.mark.parametrize("name", IN_SUITE)
def test_loop_effect_is_not_called_consistent(gen, tmp_path, name):
    make, expected = CASES[name]
    d = _case(gen, tmp_path, make(gen.effects), seed=17)
    names = _named(d)
    assert d.verdict != "consistent", (name, d.verdict)
    allowed = expected if isinstance(expected, tuple) else (expected,)
    assert names and names[0] in allowed, (name, d.verdict, names)
    assert np.isfinite(d.fit_after_percent)


if __name__ == "__main__":  # the whole table (about 4 minutes on 2 cores)
    import importlib
    import sys
    import tempfile
    from pathlib import Path

    bench = Path(__file__).resolve().parents[2] / "benchmarks" / "discovery"
    sys.path.insert(0, str(bench))

    class _Gen:
        campaign = importlib.import_module("independent.campaign")
        effects = importlib.import_module("independent.effects")

    _Gen.ctx = _Gen.campaign.context(False)
    print(f"{'case':16s} {'verdict':18s} named first (expected)")
    for name, (make, expected) in sorted(CASES.items()):
        with tempfile.TemporaryDirectory() as tmp:
            d = _case(_Gen, Path(tmp), make(_Gen.effects), seed=17)
        names = _named(d)
        print(f"{name:16s} {d.verdict:18s} {names[0] if names else '-'} ({expected})")
