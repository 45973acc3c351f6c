"""Case 1022 end to end: the real slow-tool-servo cut from its NC program, kinematics
only, against the white-light profile (WLI) and the Formtracer contour of the part.

Usage::

    python benchmarks/real_cut_1022.py [--out DIR] [--json] [--repeat N]

The documented procedure (README, ``examples/real_cut/``), timed as three fresh
``python -m servosurf`` processes under ``/usr/bin/time -v`` (wall time, CPU time
and peak resident memory of each; the whole run is their sum and maximum)::

    servosurf simulate 1022-spiralPath20230418T214917.nc --block-time 1e-3 \\
        --tool-radius 189.36e-6 --out OUT
    servosurf compare 1022-WLI-2D.csv --simulated OUT/surface.datx \\
        --cutoff 2.5e-4 --out OUT-wli --json
    servosurf compare 1022-contour.DAT --simulated OUT/surface.datx \\
        --x-range -0.00099 0.00099 --cutoff 2.5e-4 --labels Formtracer simulated \\
        --out OUT-formtracer --json

Then the same for each tool model (``simulate`` flags in brackets):

* round nose R = 186.41, 189.36, 191.81 um (``--tool-radius R``), the three fits
  of SOURCES.md;
* the measured edge ``tool/r200.csv`` swept, shape and fitted radius (``--tool
  EDGE``), and the same trace mirrored (which side is outward cannot be read from
  a trace; a toolpath TOML with ``edge-mirror = true``);
* the measured edge's radius only (``--tool EDGE --edge-compensated``).

Each model's table row: Ra, Rq, Rz and RSm simulated against measured on the
same span with the same cut-off (0.25 mm, the reference figures' lambda_c) and
end trimming, the correlation of the roughness profiles after registration, the
spindle axis found on the measured profile and the halves' offset. A reference
row compares the two instruments with each other over the WLI's span (WLI
against the Formtracer contour cropped to its cut zone, registered by halves).
For the round nose of 189.36 um and the swept edge, Ra of the Formtracer
comparison is also given per 0.1 mm of radius, measured against simulated.

The kinematic run's own time is measured in-process after a warm-up (numba
compilation and the on-disk cache load excluded): the median of ``--repeat``
calls of :func:`servosurf.simulation.simulate` on the program (reading and
interpolating the blocks, the sweep of the 5 x 4125 band).

Issue 17's targets: Ra within 10 % of the measured 106 nm and RSm within 10 % of
the measured RSm, with the correlation stated. The load average is printed: this
VM's two cores are shared.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("SERVOSURF_SHARED", ROOT.parent / "shared"))
UPM = SHARED / "data" / "upm_sts"
CASE = UPM / "1022"
PROGRAM = CASE / "1022-spiralPath20230418T214917.nc"
WLI = CASE / "1022-WLI-2D.csv"
CONTOUR = CASE / "1022-contour.DAT"
EDGE = UPM / "tool" / "r200.csv"
CUTOFF = "2.5e-4"
CUT_ZONE = ("-0.00099", "0.00099")
TARGET = 0.10  # issue 17: within 10 % of the measured Ra and RSm

MODELS: tuple[tuple[str, list[str]], ...] = (
    ("round nose R = 186.41 um", ["--tool-radius", "186.41e-6"]),
    ("round nose R = 189.36 um", ["--tool-radius", "189.36e-6"]),
    ("round nose R = 191.81 um", ["--tool-radius", "191.81e-6"]),
    ("measured edge swept", ["--tool", str(EDGE)]),
    ("measured edge swept, mirrored", []),  # a TOML with edge-mirror = true
    ("measured edge, radius only", ["--tool", str(EDGE), "--edge-compensated"]),
)
DEFAULT_MODEL = 1  # the documented procedure: R = 189.36 um


def timed(args: list[str]) -> tuple[dict, str]:
    """Run ``python -m servosurf ARGS`` under /usr/bin/time -v: resources, stdout."""
    cmd = [sys.executable, "-m", "servosurf", "-q", *args]
    timer = ["/usr/bin/time", "-v"] if Path("/usr/bin/time").exists() else []
    t0 = time.perf_counter()
    r = subprocess.run(timer + cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"failed: servosurf {' '.join(args)}\n{r.stderr}")
    res: dict = {"command": "servosurf " + " ".join(args), "wall_s": wall}
    pats = {"user_s": r"User time \(seconds\): ([\d.]+)",
            "system_s": r"System time \(seconds\): ([\d.]+)",
            "max_rss_kb": r"Maximum resident set size \(kbytes\): (\d+)"}
    for key, pat in pats.items():
        m = re.search(pat, r.stderr)
        if m is not None:
            res[key] = float(m.group(1))
    m = re.search(r"Elapsed \(wall clock\) time.*: (?:(\d+):)?(\d+):([\d.]+)",
                  r.stderr)
    if m is not None:
        h, mnt, s = m.groups()
        res["wall_s"] = int(h or 0) * 3600 + int(mnt) * 60 + float(s)
    return res, r.stdout


def procedure(out: Path, tool_args: list[str]) -> dict:
    """simulate + compare WLI + compare Formtracer, each a timed process."""
    sim, _ = timed(["simulate", str(PROGRAM), "--block-time", "1e-3", *tool_args,
                    "--out", str(out)])
    band = str(out / "surface.datx")
    wli, text = timed(["compare", str(WLI), "--simulated", band, "--cutoff",
                       CUTOFF, "--out", f"{out}-wli", "--json"])
    wli["result"] = json.loads(text)
    ft, text = timed(["compare", str(CONTOUR), "--simulated", band, "--x-range",
                      *CUT_ZONE, "--cutoff", CUTOFF, "--labels", "Formtracer",
                      "simulated", "--out", f"{out}-formtracer", "--json"])
    ft["result"] = json.loads(text)
    sim["summary"] = json.loads((out / "summary.json").read_text())["roughness"]
    return {"simulate": sim, "wli": wli, "formtracer": ft}


def mirrored_toml(folder: Path) -> Path:
    """A toolpath of kind nc whose tool is the trace with the other side outward."""
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / "1022-edge-mirrored.toml"
    p.write_text(
        'kind = "nc"\n[nc]\n'
        f'program = "{PROGRAM}"\nblock-time = 1e-3\n'
        f'[tool]\nedge-trace = "{EDGE}"\nedge-mirror = true\n')
    return p


def kinematic_time(repeat: int) -> dict:
    """Median in-process time of simulate() on the program, after a warm-up."""
    import servosurf.toolpath as tp
    from servosurf._progress import set_quiet
    from servosurf.simulation import simulate

    set_quiet(True)
    tool = tp.Tool(nose_radius=189.36e-6)
    simulate(tp.nc_spec(PROGRAM, block_time=1e-3, tool=tool))  # compile / load
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        simulate(tp.nc_spec(PROGRAM, block_time=1e-3, tool=tool))
        times.append(time.perf_counter() - t0)
    return {"median_s": statistics.median(times), "min_s": min(times),
            "repeat": repeat}


def instruments() -> dict:
    """WLI against the Formtracer contour over the WLI's span (in-process)."""
    from servosurf.io import read_profile
    from servosurf.metrology import crop_profile
    from servosurf.report import compare_profiles

    w = read_profile(WLI)
    c = crop_profile(read_profile(CONTOUR), float(CUT_ZONE[0]), float(CUT_ZONE[1]))
    return compare_profiles(w, c, cutoff=float(CUTOFF), split=True,
                            labels=("WLI", "Formtracer")).to_dict()


def radial_ra(band: Path, step: float = 0.1e-3) -> list[tuple[float, float, float]]:
    """Ra of the Formtracer comparison per ``step`` of radius (in-process).

    The compare of the procedure, then the mean |roughness| of both sides over
    the evaluated samples with ``k step <= |x - axis| < (k + 1) step``: (r_lo in
    m, measured Ra in m, simulated Ra in m) per band of radius.
    """
    import numpy as np

    from servosurf.io import read_any, read_profile
    from servosurf.report import compare_profiles

    res = compare_profiles(read_profile(CONTOUR), read_any(band)[0],
                           x_range=(float(CUT_ZONE[0]), float(CUT_ZONE[1])),
                           cutoff=float(CUTOFF))
    rm, rs = res.measured_roughness.z, res.simulated_roughness.z
    r = np.abs(res.measured.x - res.shift)
    ok = np.isfinite(rm) & np.isfinite(rs)
    out = []
    for k in range(int(np.nanmax(r[ok]) / step) + 1):
        sel = ok & (r >= k * step) & (r < (k + 1) * step)
        if sel.sum() * res.measured.dx >= 0.5 * step:
            out.append((k * step, float(np.mean(np.abs(rm[sel]))),
                        float(np.mean(np.abs(rs[sel])))))
    return out


def _pct(a, b):
    return f"{b / a - 1:+6.1%}"


def _row(name: str, d: dict) -> str:
    """One table line: simulated/measured Ra, Rq, Rz (nm), RSm (um), registration."""
    nm, um = 1e9, 1e6
    ra, rsm = d["simulated_ra_m"], d["simulated_rsm_m"]
    mra, mrsm = d["measured_ra_m"], d["measured_rsm_m"]
    return (f"{name:32} {ra * nm:6.1f}/{mra * nm:5.1f} {_pct(mra, ra)}"
            f"  {d['simulated_rq_m'] * nm:5.0f}/{d['measured_rq_m'] * nm:3.0f}"
            f"  {d['simulated_rz_m'] * nm:5.0f}/{d['measured_rz_m'] * nm:3.0f}"
            f"  {rsm * um:5.2f}/{mrsm * um:5.2f} {_pct(mrsm, rsm)} "
            f"{d['correlation']:6.3f} {d['shift_m'] * um:10.2f} "
            f"{(d['half_offset_m'] or 0.0) * um:7.2f}")


def table(rows: list[dict], side: str, ref: dict | None = None) -> list[str]:
    """Text table of one measured side ("wli" or "formtracer")."""
    lines = [f"{'model':32} {'Ra sim/meas [nm]':>19} {'Rq [nm]':>10} "
             f"{'Rz [nm]':>10} {'RSm sim/meas [um]':>19} {'corr':>6} "
             f"{'axis [um]':>10} {'offset':>7}"]
    lines += [_row(r["model"], r[side]["result"]) for r in rows]
    if ref is not None:
        lines.append(_row("(Formtracer vs WLI, same span)", ref))
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="output folder (default: a temp dir)")
    ap.add_argument("--json", action="store_true", help="one JSON document on stdout")
    ap.add_argument("--repeat", type=int, default=5,
                    help="timed in-process kinematic runs (default 5)")
    args = ap.parse_args()
    if not PROGRAM.is_file():
        print(f"case 1022 not found at {CASE}", file=sys.stderr)
        return 1
    base = Path(args.out or tempfile.mkdtemp(prefix="realcut1022-"))
    timed(["simulate", str(PROGRAM), "--block-time", "1e-3", "--tool-radius",
           "189.36e-6", "--out", str(base / "warm-up")])  # numba cache
    rows = []
    for k, (name, tool_args) in enumerate(MODELS):
        out = base / f"model{k}"
        if not tool_args:  # the mirrored trace: through a toolpath TOML
            toml = mirrored_toml(base)
            sim, _ = timed(["simulate", str(toml), "--out", str(out)])
            band = str(out / "surface.datx")
            wli, t1 = timed(["compare", str(WLI), "--simulated", band, "--cutoff",
                             CUTOFF, "--out", f"{out}-wli", "--json"])
            ft, t2 = timed(["compare", str(CONTOUR), "--simulated", band,
                            "--x-range", *CUT_ZONE, "--cutoff", CUTOFF, "--out",
                            str(out / "formtracer"), "--json"])
            wli["result"], ft["result"] = json.loads(t1), json.loads(t2)
            sim["summary"] = json.loads((out / "summary.json").read_text())[
                "roughness"]
            run = {"simulate": sim, "wli": wli, "formtracer": ft}
        else:
            run = procedure(out, tool_args)
        run["model"] = name
        rows.append(run)
    whole = rows[DEFAULT_MODEL]
    steps = [whole[k] for k in ("simulate", "wli", "formtracer")]
    total = {
        "wall_s": sum(s["wall_s"] for s in steps),
        "cpu_s": sum(s.get("user_s", 0.0) + s.get("system_s", 0.0) for s in steps),
        "max_rss_mb": max(s.get("max_rss_kb", 0.0) for s in steps) / 1024,
        "commands": [s["command"] for s in steps],
        "steps_wall_s": [s["wall_s"] for s in steps],
    }
    kin = kinematic_time(args.repeat)
    ref = instruments()
    radial = {rows[k]["model"]: radial_ra(base / f"model{k}" / "surface.datx")
              for k in (DEFAULT_MODEL, 3)}
    doc = {"models": rows, "procedure": total, "kinematic_run": kin,
           "instruments": ref, "radial_ra_formtracer": radial,
           "load_average": os.getloadavg(), "out": str(base)}
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print("Case 1022, kinematics only: simulated against measured on the same span, "
          f"lambda_c {float(CUTOFF) * 1e3:g} mm, ends trimmed")
    print("\nwhite-light profile (WLI, 0.91 mm through the centre)")
    print("\n".join(table(rows, "wli", ref)))
    print("\nFormtracer contour (cut zone +-0.99 mm)")
    print("\n".join(table(rows, "formtracer")))
    print("\nRa along the radius, Formtracer comparison (|r| bands of 0.1 mm), "
          "measured / simulated [nm]")
    first = next(iter(radial.values()))
    print(f"{'|r| [mm]':32} " + " ".join(f"{r0 * 1e3:>9.1f}" for r0, _, _ in first))
    print(f"{'measured':32} " + " ".join(f"{m * 1e9:9.0f}" for _, m, _ in first))
    for name, vals in radial.items():
        print(f"{name:32} " + " ".join(f"{s_ * 1e9:9.0f}" for _, _, s_ in vals))
    print("\nissue 17 targets (Ra and RSm within 10 % of the measured, WLI):")
    for r in rows:
        d = r["wli"]["result"]
        ra = d["simulated_ra_m"] / d["measured_ra_m"] - 1
        rsm = d["simulated_rsm_m"] / d["measured_rsm_m"] - 1
        ok = "met" if abs(ra) <= TARGET and abs(rsm) <= TARGET else "missed"
        print(f"  {r['model']:32} Ra {ra:+6.1%}  RSm {rsm:+6.1%}  correlation "
              f"{d['correlation']:.3f}  -> {ok}")
    print(f"\nthe documented procedure ({MODELS[DEFAULT_MODEL][0]}): "
          f"{len(steps)} processes, wall {total['wall_s']:.1f} s (" +
          " + ".join(f"{w:.1f}" for w in total["steps_wall_s"]) +
          f"), CPU {total['cpu_s']:.1f} s, peak RSS {total['max_rss_mb']:.0f} MB")
    print(f"kinematic run in-process after compilation: median {kin['median_s']:.2f} "
          f"s, min {kin['min_s']:.2f} s of {kin['repeat']}")
    print(f"load average {os.getloadavg()[0]:.1f}; figures and maps in {base}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
