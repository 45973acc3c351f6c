"""The real cut 1022 diagnosed (issue 19 item 8): the WLI profile of a real
slow-tool-servo cut against the diagnosis's model of its NC program.

``benchmarks/real_cut_1022_diagnose.py`` writes the profile-only manifest (paths
into ../shared), registers the profile's line and runs the diagnosis; this test
runs it and checks the discipline the issue asks of any verdict on real data:

* no accepted explanation has a parameter at or outside its catalogue bounds
  (the numeric bounds of :meth:`Effect.describe`, checked here independently of
  the selection's own refusal);
* the verdict is either an explanation with a held-out improvement or
  "unexplained"/"partly-explained" with the residual located (a mismatch on the
  profile with a ``where``).

Skipped when ../shared is absent.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import pytest

from servosurf.diagnose._select import FIDELITY_ENR

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "benchmarks" / "real_cut_1022_diagnose.py"
SHARED = ROOT.parent / "shared" / "data" / "upm_sts" / "1022"

#: distance to a bound, relative to the bound, that counts as "at the bound"
AT_BOUND = 1e-3

pytestmark = pytest.mark.skipif(
    not (SHARED / "1022-WLI-2D.csv").is_file()
    or not (SHARED / "1022-spiralPath20230418T214917.nc").is_file(),
    reason="../shared/data/upm_sts/1022 is absent",
)


def _bench():
    spec = importlib.util.spec_from_file_location("real_cut_1022_diagnose", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _numeric_bounds(effect: str) -> dict[str, tuple[float | None, float | None]]:
    from servosurf.diagnose import get_effect

    out = {}
    for p in get_effect(effect).describe()["parameters"]:
        lo = p["low"] if isinstance(p["low"], float) else None
        hi = p["high"] if isinstance(p["high"], float) else None
        out[p["name"]] = (lo, hi)
    return out


def _inside(value: float, lo, hi) -> bool:
    if not math.isfinite(value):
        return False
    # "at" a bound: within AT_BOUND of it, relative to the bound's own size
    if lo is not None and value <= lo + AT_BOUND * max(abs(lo), 1e-300):
        return False
    return not (hi is not None and value >= hi - AT_BOUND * max(abs(hi), 1e-300))


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    """The benchmark's run: registration, manifest and diagnosis (~80 s)."""
    return _bench().run(tmp_path_factory.mktemp("r1022"))


@pytest.mark.slow
def test_real_cut_1022_no_explanation_at_a_bound(result):
    reg = result["registration"]
    assert reg["correlation"] > 0.3, reg  # the line was found on the spiral
    d = result["diagnosis"]
    for e in d["explanations"]:
        bounds = _numeric_bounds(e["effect"])
        for key, value in e["parameters"].items():
            name = next((n for n in bounds if key.startswith(n)), None)
            if name is None:
                continue
            lo, hi = bounds[name]
            assert _inside(float(value), lo, hi), (e["effect"], key, value, lo, hi)


@pytest.mark.slow
def test_real_cut_1022_verdict_is_held_out_or_located(result):
    d = result["diagnosis"]
    for e in d["explanations"]:  # whatever the verdict, nothing without held-out
        h = e["held_out_improvement"]
        assert h["passed"] and not h["in_sample_fallback"], e
        assert h["delta_deviance"] > 0, e
        assert e["signature"]["signature_enr"] >= FIDELITY_ENR, e
    if d["verdict"] == "explained":
        assert d["explanations"]
    else:
        assert d["verdict"] in ("unexplained", "partly-explained"), d["verdict"]
        located = [
            m
            for m in d["mismatches"] + d["remainder"]
            if m["domain"] == "profile" and m["where"]
        ]
        assert located, d
