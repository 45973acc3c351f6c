"""Score the blind diagnoses of an independent suite against its sealed key.

Usage::

    python benchmarks/discovery/independent/score.py DIR [--json]

Reads ``DIR/results/case_NNNN.json`` (``servosurf diagnose --json`` plus runtime),
then opens the key. Prints and writes ``DIR/table.md`` and ``DIR/score.json``:

* top-1 attribution at ENR >= 0.1 on catalogue-like cases: the physics
  explanation with the largest delta-BIC is one the effect's ``expected`` names,
  and the verdict is ``explained`` or ``partly-explained``;
* out-of-catalogue cases called ``unexplained`` or ``partly-explained`` (and the
  share confidently ``explained``);
* false alarms on nulls: a verdict other than ``consistent`` that is not a
  noise-model flag alone (a noise-model term, ``sensor-noise-shape``, and nothing
  else), per null kind;
* explanations with a parameter outside its physical bounds (:data:`BOUNDS`, all
  cases);
* median parameter error of correct top-1 attributions at ENR >= 0.1 where the
  effect has a catalogue-comparable parameter;
* a per-effect confusion table: what each generated effect was called.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:
    sys.path.insert(0, str(HERE.parent))

TARGETS = {
    "top1_enr_ge_0.1": 0.95,
    "ool_flagged": 0.80,
    "false_alarm_rate": 0.02,
    "out_of_bounds_explanations": 0,
    "median_param_error_enr_ge_0.1": 0.10,
}
#: Catalogue terms that describe the noise model, not a mechanism.
NOISE_MODEL = {"sensor-noise-shape"}

FS = 199.6e3
K2 = 2.0e4  # N/m, flexure stiffness of the machine file
STROKE = 15e-6  # m, largest excursion of the lenslet command
#: Physical plausibility bounds of the catalogue's parameters (SI), with the reason.
BOUNDS = {
    "base-vibration-lines": {
        "amplitude_*": (0.0, 1e-6, "base lines of an isolated ultra-precision "
                        "machine are nm to tens of nm; 1 um is a generous ceiling"),
        "frequency_*": (0.0, FS / 2, "below the controller's Nyquist frequency"),
    },
    "structural-mode": {
        "frequency": (500.0, FS / 2, "above the suspension mode, below Nyquist"),
        "damping_ratio": (1e-3, 0.5, "structural modes: 0.1 % to 50 %"),
        "compliance": (0.0, 1e-5, "static compliance of a stiff FTS: <= 10 um/N"),
    },
    "loop-delay": {
        "extra_delay": (-0.51 / FS, 10 / FS, "total delay >= 0; <= 10 samples "
                        "(a firmware pipeline, not a re-designed controller)"),
    },
    "thermal-drift": {
        "amplitude": (-2e-6, 2e-6, "thermal drift over a 4.5 s cut: < 2 um"),
        "rate": (-1e-6, 1e-6, "< 1 um/s"),
        "time_constant": (0.01, 1e4, "thermal time constants 10 ms .. 3 h"),
    },
    "flexure-stiffness-nonlinearity": {
        "k_quadratic": (-K2 / STROKE, K2 / STROKE,
                        "nonlinear force below the linear force over the stroke"),
        "k_cubic": (-K2 / STROKE**2, K2 / STROKE**2,
                    "nonlinear force below the linear force over the stroke"),
    },
    "force-constant-position": {
        "b1": (-0.5 / STROKE, 0.5 / STROKE, "Kf changes < 50 % over the stroke"),
        "b2": (-0.5 / STROKE**2, 0.5 / STROKE**2, "Kf changes < 50 % over the stroke"),
    },
    "amplifier-saturation": {
        "max_current": (1e-3, 10.0, "a current limit between 1 mA and 10 A"),
    },
    "sensor-nonlinearity": {
        "a2": (-0.01 / 10e-6, 0.01 / 10e-6, "capacitive sensor linearity error "
               "< 1 % of a 10 um range (datasheets: ~0.1 %)"),
        "a3": (-0.01 / 10e-6**2, 0.01 / 10e-6**2, "as a2"),
    },
    "sensor-noise-shape": {
        "floor": (0.0, 5e-11, "10x the machine file's white floor"),
        "corner": (1e3, FS / 2, "sensor electronics corner"),
    },
    "tool-edge-waviness": {
        "p*": (-1e-6, 1e-6, "controlled-waviness tools: < 0.05 um; 1 um ceiling"),
    },
    "tool-radius-error": {
        "radius_error": (-50e-6, 50e-6, "10 % of the 0.5 mm nose radius"),
    },
    "cutting-force-coefficient": {
        "specific_force": (1e8, 2e10, "specific thrust pressures of metals"),
    },
    "spindle-axial-error": {
        "amplitude_*": (0.0, 1e-6, "air-bearing spindles: tens of nm"),
    },
    "elastic-recovery": {"recovery": (0.0, 0.2, "spring-back < 20 % of depth")},
    "recalibration": {
        "moving_mass": (0.7 * 0.175, 1.3 * 0.175, "weighed mass +-30 %"),
        "flexure_stiffness": (0.5 * K2, 2.0 * K2, "flexure design value x0.5..2"),
        "flexure_damping": (0.0, 20.0, "10x the machine file's"),
        "force_constant": (0.7 * 8.0, 1.3 * 8.0, "motor constant +-30 %"),
        "sensor_bandwidth": (5e3, 50e3, "CPL190-class electronics"),
    },
    "spindle-async-error": {
        "amplitude_*": (0.0, 1e-7, "asynchronous axial error motion of air-bearing "
                        "spindles: a few nm to about 25 nm"),
        "frequency_*": (0.0, 5e3, "below the rotor's axial mode on its bearing film"),
    },
    "tool-wear": {
        "growth": (0.0, 1e-3, "wear only grows the radius; 1 mm per m of cutting "
                   "length would wear a 0.5 mm nose away in a lenslet field"),
    },
}


def out_of_bounds(effect: str, params: dict) -> list[str]:
    """Parameters of an explanation outside :data:`BOUNDS` (``name=value``)."""
    bad = []
    for pat, (lo, hi, _why) in BOUNDS.get(effect, {}).items():
        for k, v in params.items():
            if fnmatch.fnmatch(k, pat) and isinstance(v, int | float):
                if not (lo <= float(v) <= hi) or not math.isfinite(float(v)):
                    bad.append(f"{k}={v:.3g}")
    return bad


def _rel(a, b):
    return abs(a - b) / max(abs(b), 1e-300)


def _poly_curve_err(curve: dict, est: dict, names, powers) -> float:
    x = np.asarray(curve["x"])
    y = np.asarray(curve["y"])
    e = sum(est.get(n, 0.0) * x**k for n, k in zip(names, powers, strict=True))
    return float(np.linalg.norm(e - y) / max(np.linalg.norm(y), 1e-300))


def param_error(named: str, comp: dict, est: dict, kt0: float) -> float | None:
    """Relative error of a fitted parameter against the comparable truth."""
    if not comp:
        return None
    if named == "structural-mode" and "frequency" in comp:
        return _rel(est.get("frequency", math.nan), comp["frequency"])
    if named == "loop-delay":
        return _rel(est.get("extra_delay", math.nan), comp["extra_delay"])
    if named == "base-vibration-lines":
        f0, a0 = comp["frequency_1"], comp["amplitude_1"]
        best = None
        for k in range(1, 10):
            f = est.get(f"frequency_{k}")
            if f is not None and (best is None or abs(f - f0) < abs(best[0] - f0)):
                best = (f, est.get(f"amplitude_{k}", math.nan))
        return math.inf if best is None else max(_rel(best[0], f0), _rel(best[1], a0))
    if named == "thermal-drift":
        c = comp["drift_curve"]
        t = np.asarray(c["x"])
        tau = max(est.get("time_constant", 1.0), 1e-9)
        d = est.get("amplitude", 0.0) * -np.expm1(-t / tau) + est.get("rate", 0.0) * t
        y = np.asarray(c["y"])
        return float(np.linalg.norm(d - y) / max(np.linalg.norm(y), 1e-300))
    if named == "force-constant-position":
        return _poly_curve_err(comp["kf_relative_curve"], est, ("b1", "b2"), (1, 2))
    if named == "flexure-stiffness-nonlinearity":
        return _poly_curve_err(comp["flexure_force_curve"], est,
                               ("k_quadratic", "k_cubic"), (2, 3))
    if named == "sensor-nonlinearity":
        return _poly_curve_err(comp["sensor_error_curve"], est, ("a2", "a3"), (2, 3))
    if named == "amplifier-saturation":
        return _rel(est.get("max_current", math.nan), comp["max_current"])
    if named == "spindle-axial-error":
        for k in range(1, 10):
            if est.get(f"order_{k}") == comp["order_1"]:
                return _rel(est[f"amplitude_{k}"], comp["amplitude_1"])
        return math.inf
    if named == "tool-radius-error":
        return _rel(est.get("radius_error", math.nan), comp["radius_error"])
    if named == "spindle-async-error" and "frequency_1" in comp:
        f0, a0 = comp["frequency_1"], comp["amplitude_1"]
        best = None
        for k in range(1, 10):
            f = est.get(f"frequency_{k}", est.get(f"frequency_{k}_hz"))
            a = est.get(f"amplitude_{k}", est.get(f"amplitude_{k}_m", math.nan))
            if f is not None and (best is None or abs(f - f0) < abs(best[0] - f0)):
                best = (f, a)
        return math.inf if best is None else max(_rel(best[0], f0), _rel(best[1], a0))
    if named == "tool-wear" and "radius_growth_rate" in comp:
        v = est.get("cutting_speed", est.get("cutting_speed_m_per_s", math.nan))
        return _rel(est.get("growth", math.nan) * v, comp["radius_growth_rate"])
    if named == "cutting-force-coefficient":
        return abs(est.get("specific_force", math.nan) - comp["specific_force"]) / abs(
            comp["specific_force"] - kt0)
    if named == "flexure-hysteresis" and "stiffness" in comp:
        # small-amplitude slopes of the Dahl and Bouc-Wen elements
        return _rel(est.get("stiffness", math.nan), comp["stiffness"])
    if named == "friction" and "level" in comp:
        return _rel(est.get("level", math.nan), comp["level"])
    if named == "converter-quantisation":
        for k in ("dac_step", "adc_step", "dead_band"):
            if k in comp:
                return _rel(est.get(k, math.nan), comp[k])
    return None


def _bic(e: dict) -> float:
    """An explanation's delta-BIC; a missing or non-finite one (the diagnosis has
    written ``null``) ranks last."""
    v = e.get("delta_bic")
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else -math.inf


def classify(res: dict) -> dict:
    """Verdict, physics named (by delta-BIC), noise-model and recalibration terms."""
    if "error" in res:
        return {"verdict": "error", "physics": [], "noise": [], "recal": False,
                "label": "error", "top": None}
    ex = sorted(res.get("explanations", []), key=lambda e: -_bic(e))
    phys = [e for e in ex if e["effect"] not in NOISE_MODEL]
    noise = [e for e in ex if e["effect"] in NOISE_MODEL]
    recal = bool(res.get("recalibration"))
    verdict = res.get("verdict", "?")
    top = phys[0] if phys else None
    label = top["effect"] if top else verdict
    return {"verdict": verdict, "physics": phys, "noise": noise, "recal": recal,
            "label": label, "top": top}


def _workpiece_kt() -> float:
    """The workpiece file's specific thrust pressure (Pa), the cases' nominal k_t."""
    import tomllib

    from independent.campaign import WORKPIECE

    with open(WORKPIECE, "rb") as fh:
        return float(tomllib.load(fh)["material"]["specific-thrust-pressure"])


def _mismatched(res: dict, folder: Path) -> list[str]:
    """Recordings with a mismatch, each with its rate when not the controller's
    (``aircut.csv@99.8k``), strongest first."""
    best: dict = {}
    for m in res.get("mismatches", []):
        rec = m.get("recording", "?").split(":")[0]
        best[rec] = max(best.get(rec, 0.0), float(m.get("significance") or 0.0))
    out = []
    for rec in sorted(best, key=lambda k: -best[k]):
        fs = _record_rate(folder / rec)
        tag = "" if fs is None or abs(fs / FS - 1) < 1e-3 else f"@{fs / 1e3:.1f}k"
        out.append(rec + tag)
    return out


def _record_rate(path: Path) -> float | None:
    """Sampling rate (Hz) of a time record written by the generator, else None."""
    try:
        if path.suffix == ".npz":
            with np.load(path) as z:
                return float(z["fs_hz"]) if "fs_hz" in z.files else None
        if path.suffix == ".csv" and path.name.split(".")[0] in (
                "idle", "aircut", "aircut_b", "cut"):
            t = np.loadtxt(path, delimiter=",", skiprows=1, max_rows=2, usecols=0)
            return float(1.0 / (t[1] - t[0]))
    except (OSError, ValueError, KeyError, IndexError):
        return None
    return None


def score(out: Path) -> dict:
    """Metrics of a run (opens the key)."""
    from independent.generate import unseal

    out = Path(out)
    res = {f.stem: json.loads(f.read_text())
           for f in sorted((out / "results").glob("case_*.json"))}
    key = unseal(out)
    kt0 = _workpiece_kt()
    rows = []
    for k in key["cases"]:
        if "generation_error" in k:
            rows.append({"case": k.get("case"), "effect": k["effect"],
                         "generation_error": k["generation_error"]})
            continue
        r = res.get(k["case"])
        c = classify(r) if r is not None else {"verdict": "missing", "physics": [],
                                              "noise": [], "recal": False,
                                              "label": "missing", "top": None}
        row = {"case": k["case"], "effect": k["effect"], "klass": k["klass"],
               "form": k.get("form", ""), "enr": k["enr_target"],
               "enr_achieved": k.get("enr"), "verdict": c["verdict"],
               "label": c["label"], "named": [e["effect"] for e in c["physics"]],
               "noise_flag": bool(c["noise"]), "recal": c["recal"],
               "low_freq_base": k["campaign"]["low_freq_base"],
               "runtime_s": (r or {}).get("runtime_s"),
               "mismatched": _mismatched(r or {}, out / "cases" / k["case"])}
        bad = []
        for e in c["physics"] + c["noise"] + list((r or {}).get("recalibration", [])):
            b = out_of_bounds(e["effect"], e.get("parameters", {}))
            if b:
                bad.append({"effect": e["effect"], "parameters": b})
        row["out_of_bounds"] = bad
        if k["klass"] == "catalogue":
            row["top1"] = (c["top"] is not None and c["top"]["effect"] in k["expected"]
                           and c["verdict"] in ("explained", "partly-explained"))
            if row["top1"]:
                row["param_error"] = param_error(c["top"]["effect"], k["comparable"],
                                                 c["top"]["parameters"], kt0)
            hit = [e for e in c["physics"] if e["effect"] in k["expected"]]
            if hit:  # the expected name anywhere in the list, not only on top
                row["param_error_named"] = param_error(
                    hit[0]["effect"], k["comparable"], hit[0]["parameters"], kt0)
        elif k["klass"] == "out-of-catalogue":
            row["flagged"] = c["verdict"] in ("unexplained", "partly-explained")
        else:
            only_noise = not c["physics"] and c["verdict"] != "consistent" and (
                c["noise"])
            row["false_alarm"] = c["verdict"] != "consistent" and not only_noise
        row["outcome"] = outcome(row)
        rows.append(row)
    return summarise(rows, key)


#: Outcome columns of the per-effect table, in order.
OUTCOMES = ("correct", "wrong", "unexplained", "noise-flag", "consistent", "error")


def outcome(row: dict) -> str:
    """One case's outcome for the per-effect table.

    ``correct``: the largest-delta-BIC physics term is an expected name;
    ``wrong``: a physics term is named but not an expected one (for
    out-of-catalogue effects and nulls every physics name is wrong);
    ``unexplained``: not consistent and nothing named; ``noise-flag``: only a
    noise-model term; ``consistent``; ``error``: no diagnosis (error, timeout).
    """
    if row["verdict"] in ("error", "missing"):
        return "error"
    if row["verdict"] == "consistent":
        return "consistent"
    if row.get("top1"):
        return "correct"
    if row["named"]:
        return "wrong"
    return "noise-flag" if row["noise_flag"] else "unexplained"


def per_effect(rows: list[dict]) -> list[dict]:
    """Per generated effect: outcome counts, parameter errors, names given."""
    out = []
    for eff in sorted({r["effect"] for r in rows if "outcome" in r}):
        rr = [r for r in rows if r.get("effect") == eff and "outcome" in r]
        counts = {o: sum(1 for r in rr if r["outcome"] == o) for o in OUTCOMES}
        pe = [r["param_error"] for r in rr if r.get("param_error") is not None]
        pn = [r["param_error_named"] for r in rr
              if r.get("param_error_named") is not None]
        names: dict = {}
        for r in rr:
            for nm in r["named"]:
                names[nm] = names.get(nm, 0) + 1
        out.append({"effect": eff, "klass": rr[0]["klass"], "n": len(rr),
                    **counts, "param_errors_top1": pe, "param_errors_named": pn,
                    "names": names,
                    "runtime_s": [r.get("runtime_s") for r in rr]})
    return out


def _rate(rows, pred):
    rows = list(rows)
    return (sum(1 for r in rows if pred(r)) / len(rows)) if rows else math.nan


def summarise(rows: list[dict], key: dict) -> dict:
    """Aggregate metrics, the confusion table and per-case rows."""
    ok = [r for r in rows if "generation_error" not in r]
    # rates over diagnosed cases only (a timeout or an error is no verdict)
    done = [r for r in ok if r["verdict"] not in ("error", "missing")]
    cat = [r for r in done if r["klass"] == "catalogue"]
    cat1 = [r for r in cat if r["enr"] >= 0.1]
    ooc = [r for r in done if r["klass"] == "out-of-catalogue"]
    nul = [r for r in done if r["klass"] == "null"]
    errs = [r["param_error"] for r in cat1 if r.get("param_error") is not None]
    conf: dict = {}
    for r in ok:
        conf.setdefault(r["effect"], {})
        conf[r["effect"]][r["label"]] = conf[r["effect"]].get(r["label"], 0) + 1
    by_null = {}
    for kind in sorted({r["effect"] for r in nul}):
        rr = [r for r in nul if r["effect"] == kind]
        by_null[kind] = {"n": len(rr), "false_alarm": _rate(rr, lambda r: r[
            "false_alarm"])}
    m = {
        "cases": len(rows),
        "not_generated": len(rows) - len(ok),
        "errors": sum(1 for r in ok if r["verdict"] in ("error", "missing")),
        "top1_enr_ge_0.1": _rate(cat1, lambda r: r["top1"]),
        "detected_enr_ge_0.1": _rate(cat1, lambda r: r["verdict"] != "consistent"),
        "ool_flagged": _rate(ooc, lambda r: r["flagged"]),
        "ool_explained": _rate(ooc, lambda r: r["verdict"] == "explained"),
        "ool_consistent": _rate(ooc, lambda r: r["verdict"] == "consistent"),
        "false_alarm_rate": _rate(nul, lambda r: r["false_alarm"]),
        "false_alarm_by_null": by_null,
        "out_of_bounds_explanations": sum(len(r["out_of_bounds"]) for r in ok),
        "cases_with_out_of_bounds": _rate(ok, lambda r: bool(r["out_of_bounds"])),
        "median_param_error_enr_ge_0.1": float(np.median(errs)) if errs else math.nan,
        "n_param_errors": len(errs),
        "n": {"catalogue_enr_ge_0.1": len(cat1), "out_of_catalogue": len(ooc),
              "null": len(nul)},
        "confusion": conf,
        "per_effect": per_effect(rows),
        "chip_force": key.get("chip_force", "continuous"),
        "seed": key.get("seed"),
        "rows": rows,
    }
    return m


def _pct(x) -> str:
    """A relative error as a percentage; ``n/a`` without a comparable truth and
    ``unmatched`` when the named term has no component to compare (an infinite
    error: another spindle order, no line near the true frequency)."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    if math.isinf(x):
        return "unmatched"
    return f"{100 * x:.0f} %"


def table(m: dict) -> str:
    """Markdown tables of a score."""
    lines = ["| metric | value | target |", "|---|---|---|"]

    def row(name, val, tgt):
        lines.append(f"| {name} | {val} | {tgt} |")

    n = m["n"]
    row(f"top-1 attribution, ENR >= 0.1 (n={n['catalogue_enr_ge_0.1']})",
        _pct(m["top1_enr_ge_0.1"]), ">= 95 %")
    row("detected (not consistent), ENR >= 0.1", _pct(m["detected_enr_ge_0.1"]), "")
    row(f"out-of-catalogue called unexplained/partly (n={n['out_of_catalogue']})",
        _pct(m["ool_flagged"]), ">= 80 %")
    row("out-of-catalogue called explained", _pct(m["ool_explained"]), "")
    row("out-of-catalogue called consistent", _pct(m["ool_consistent"]), "")
    row(f"false alarms on nulls (n={n['null']})", _pct(m["false_alarm_rate"]),
        "<= 2 %")
    for kind, v in m["false_alarm_by_null"].items():
        row(f"  {kind} (n={v['n']})", _pct(v["false_alarm"]), "")
    row("explanations with a parameter outside physical bounds",
        str(m["out_of_bounds_explanations"]), "0")
    row(f"median parameter error, ENR >= 0.1 (n={m['n_param_errors']})",
        _pct(m["median_param_error_enr_ge_0.1"]), "<= 10 %")
    lines.append("")
    lines.append(f"cases {m['cases']} (not generated {m['not_generated']}, "
                 f"no diagnosis (timeout, error, not run) {m['errors']}; rates over "
                 f"diagnosed cases), chip force {m['chip_force']}, "
                 f"seed {m['seed']}")
    lines.append("")
    lines.append("| generated effect | class | n | named correctly | named wrong | "
                 "unexplained (nothing named) | noise flag only | consistent | "
                 "no diagnosis | param. error (top-1; expected name anywhere) | "
                 "physics named (count) |")
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|")
    order = {"catalogue": 0, "out-of-catalogue": 1, "null": 2}
    for e in sorted(m["per_effect"], key=lambda e: (order.get(e["klass"], 3),
                                                     e["effect"])):
        pe = ", ".join(_pct(x) for x in e["param_errors_top1"]) or "-"
        pn = ", ".join(_pct(x) for x in e["param_errors_named"]) or "-"
        names = ", ".join(f"{k} ({v})" for k, v in sorted(
            e["names"].items(), key=lambda kv: (-kv[1], kv[0])))
        lines.append(f"| {e['effect']} | {e['klass']} | {e['n']} | "
                     + " | ".join(str(e[o] or "") for o in OUTCOMES)
                     + f" | {pe}; {pn} | {names} |")
    lines.append("")
    labels = sorted({lab for v in m["confusion"].values() for lab in v})
    lines.append("| generated effect | " + " | ".join(labels) + " |")
    lines.append("|---|" + "---|" * len(labels))
    for eff in sorted(m["confusion"]):
        v = m["confusion"][eff]
        lines.append(f"| {eff} | " + " | ".join(str(v.get(lab, "")) for lab in labels)
                     + " |")
    lines.append("")
    lines.append("| case | effect | form | ENR | verdict | named (by delta-BIC) | "
                 "out of bounds | mismatched recordings (strongest first) | "
                 "runtime (s) |")
    lines.append("|---|---|---|---|---|---|---|---|---|")
    for r in sorted(m["rows"], key=lambda r: (r.get("klass", ""), r["effect"])):
        if "generation_error" in r:
            lines.append(f"| {r['case']} | {r['effect']} | | | not generated | "
                         f"{r['generation_error']} | |")
            continue
        ob = "; ".join(f"{b['effect']}: {', '.join(b['parameters'])}"
                       for b in r["out_of_bounds"])
        lines.append(f"| {r['case']} | {r['effect']} | {r['form']} | {r['enr']:g} | "
                     f"{r['verdict']} | {', '.join(r['named'])} | {ob} | "
                     f"{', '.join(r.get('mismatched', []))} | "
                     f"{r['runtime_s'] or 0:.0f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="suite directory")
    ap.add_argument("--json", action="store_true", help="print the metrics as JSON")
    a = ap.parse_args(argv)
    m = score(a.out)
    t = table(m)
    (a.out / "table.md").write_text(t + "\n")
    (a.out / "score.json").write_text(json.dumps(m, indent=1, default=str))
    print(json.dumps({k: v for k, v in m.items() if k != "rows"}, indent=1,
                     default=str) if a.json else t)
    return 0


if __name__ == "__main__":
    sys.exit(main())
