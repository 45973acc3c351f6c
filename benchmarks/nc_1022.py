"""Case 1022: the real slow-tool-servo cut simulated from its NC program, kinematics
only, against the measured white-light profile of the same part.

Usage::

    python benchmarks/nc_1022.py [--out DIR] [--json]

What it runs (the command the README documents), once per tool radius of
``../shared/data/upm_sts/SOURCES.md`` (186.41, 189.36 and 191.81 um)::

    servosurf simulate 1022-spiralPath20230418T214917.nc --block-time 1e-3 \\
        --tool-radius R --profile-length 0.912e-3 --out DIR/R

``--profile-length`` is the length of the measured profile (1047 samples at
0.871 um): the simulated centre profile is evaluated over the same stretch of radii
with the same ISO 4288 cut-off (0.25 mm) and end trimming. The whole band (ISO 4288
then picks 0.8 mm) is reported as well. The time base does not change a kinematic
surface; any ``--block-time`` gives the same map.

Measurement rules: one warm-up run first (numba compilation and the on-disk cache
load are excluded); each timed run is a fresh ``python -m servosurf`` process under
``/usr/bin/time -v`` (wall time, CPU time and peak resident memory of the whole
run: imports, reading the program, the sweep, analysis, map and four figures). The
machine's load average is printed: this VM's two cores are shared.

The measured reference figures come from the white-light profile itself, read here
with plain numpy and analysed with the same
:func:`servosurf.metrology.profile_roughness` (Ra 106.0 nm, RSm 29.6 um;
SOURCES.md: Ra 106.0 nm).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("SERVOSURF_SHARED", ROOT.parent / "shared"))
CASE = SHARED / "data" / "upm_sts" / "1022"
PROGRAM = CASE / "1022-spiralPath20230418T214917.nc"
WLI = CASE / "1022-WLI-2D.csv"
RADII = (186.41e-6, 189.36e-6, 191.81e-6)
WLI_LENGTH = 0.912e-3


def measured() -> dict:
    """Roughness of the white-light profile (X and height in um, empty = void)."""
    from servosurf.metrology import Profile, profile_roughness

    rows = [ln.split(",") for ln in WLI.read_text().splitlines()[1:]]
    x = np.array([float(r[0]) for r in rows]) * 1e-6
    z = np.array([float(r[1]) if r[1].strip() else np.nan for r in rows]) * 1e-6
    res = profile_roughness(Profile(z, float(np.mean(np.diff(x)))))
    return {k: res[k] for k in ("ra_m", "rq_m", "rz_m", "rsm_m", "cutoff_m")}


def run(radius: float, out: Path, extra: list[str]) -> dict:
    """One CLI run under /usr/bin/time -v; its summary and resources."""
    cmd = [sys.executable, "-m", "servosurf", "-q", "simulate", str(PROGRAM),
           "--block-time", "1e-3", "--tool-radius", f"{radius:g}", "--out", str(out),
           *extra]
    timer = ["/usr/bin/time", "-v"] if Path("/usr/bin/time").exists() else []
    r = subprocess.run(timer + cmd, capture_output=True, text=True, check=True)
    res = {"command": " ".join(["servosurf", *cmd[3:]])}
    pats = {"wall_s": r"Elapsed \(wall clock\) time.*: (?:(\d+):)?(\d+):([\d.]+)",
            "user_s": r"User time \(seconds\): ([\d.]+)",
            "system_s": r"System time \(seconds\): ([\d.]+)",
            "max_rss_kb": r"Maximum resident set size \(kbytes\): (\d+)"}
    for key, pat in pats.items():
        m = re.search(pat, r.stderr)
        if m is None:
            continue
        if key == "wall_s":
            h, mnt, s = m.groups()
            res[key] = int(h or 0) * 3600 + int(mnt) * 60 + float(s)
        else:
            res[key] = float(m.group(1))
    summary = json.loads((out / "summary.json").read_text())
    res["roughness"] = summary["roughness"]
    return res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="output folder (default: a temp dir)")
    ap.add_argument("--json", action="store_true", help="one JSON document on stdout")
    args = ap.parse_args()
    if not PROGRAM.is_file():
        print(f"case 1022 not found at {CASE}", file=sys.stderr)
        return 1
    base = Path(args.out or tempfile.mkdtemp(prefix="nc1022-"))
    run(RADII[1], base / "warm-up", [])  # compile / load the numba cache
    ref = measured()
    rows = []
    for R in RADII:
        for label, extra in (("measured length", ["--profile-length",
                                                  f"{WLI_LENGTH:g}"]),
                             ("whole band", [])):
            tag = f"{R * 1e6:.2f}um-{'wli' if extra else 'band'}"
            res = run(R, base / tag, extra)
            res.update(tool_radius_m=R, profile=label)
            rows.append(res)
    doc = {"measured_wli": ref, "runs": rows, "load_average": os.getloadavg(),
           "out": str(base)}
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(f"measured (white light): Ra {ref['ra_m'] * 1e9:.1f} nm, Rz "
          f"{ref['rz_m'] * 1e9:.1f} nm, RSm {ref['rsm_m'] * 1e6:.2f} um "
          f"(cut-off {ref['cutoff_m'] * 1e3:g} mm)")
    print(f"{'R [um]':>7} {'profile':>16} {'Ra [nm]':>8} {'vs meas':>8} "
          f"{'Rz [nm]':>8} {'RSm [um]':>9} {'vs meas':>8} {'cut-off':>8} "
          f"{'wall [s]':>9} {'cpu [s]':>8} {'RSS [MB]':>9}")
    for r in rows:
        g = r["roughness"]
        cpu = r.get("user_s", np.nan) + r.get("system_s", np.nan)
        print(f"{r['tool_radius_m'] * 1e6:7.2f} {r['profile']:>16} "
              f"{g['ra_m'] * 1e9:8.1f} {g['ra_m'] / ref['ra_m'] - 1:+8.1%} "
              f"{g['rz_m'] * 1e9:8.1f} {g['rsm_m'] * 1e6:9.2f} "
              f"{g['rsm_m'] / ref['rsm_m'] - 1:+8.1%} {g['cutoff_m'] * 1e3:6.2f}mm "
              f"{r.get('wall_s', np.nan):9.2f} {cpu:8.2f} "
              f"{r.get('max_rss_kb', np.nan) / 1024:9.0f}")
    print(f"load average {os.getloadavg()[0]:.1f}; figures and maps in {base}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
