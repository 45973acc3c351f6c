"""Case 1022 diagnosed: the real slow-tool-servo cut's white-light profile against
the diagnosis's model of its NC program (issue 19 item 8).

Usage::

    python benchmarks/real_cut_1022_diagnose.py [--out DIR] [--json]

Writes a profile-only manifest whose paths point into ``../shared`` (the NC TOML
``examples/real_cut/1022.toml`` and the WLI profile ``1022-WLI-2D.csv``, never
copied), runs ``servosurf diagnose`` on it and prints the verdict, the fit, the
refused candidates and where the residual is.

Decisions (the data leave them open, see ``../shared/data/upm_sts/SOURCES.md``):

* **Machine and time base**: the diagnosis models the seed paper's FTS loop, so
  the case's machine is ``seed-prototype`` at its own bandwidth. The program runs
  in inverse time with no usable time base; the NC TOML written beside the
  manifest (program in ``../shared``, tip reference, counter-clockwise, nose
  radius 189.36 um as ``examples/real_cut/1022.toml``) gives it 0.1 ms a block
  (72 ms a revolution), at which the loop follows the slow STS commands to a
  fraction of a nanometre: the model is the kinematic envelope of the blocks
  with the loop's small lag, on a record ten times shorter than at the
  example's 1 ms (each model evaluation simulates the loop over it).
* **Form**: the WLI export has its form removed, so the manifest says
  ``form-order = 4`` (the sphere of radius 10.99 mm over the profile's +-0.46 mm
  is a quadratic plus a 4 nm quartic): data and model lose the same polynomial.
* **Where the profile lies** (not recorded beyond "through the centre"): the
  line through the spindle axis whose azimuth and axis position on the profile
  maximise the correlation of the measured roughness with the model's nominal
  profile (a grid over the azimuth in 1/64 turn and the axis position in one
  sample over +-60 um, then refined). Two lines of the spiral's scallop phase,
  azimuth and axis, fix both halves of the profile at once (the grooves cross a
  line through the axis displaced inward on both sides).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "upm_sts" / "1022"
PROFILE = SHARED / "1022-WLI-2D.csv"
PROGRAM = SHARED / "1022-spiralPath20230418T214917.nc"
MACHINE = "seed-prototype"
#: s per block: 72 ms a revolution (833 rpm); the program gives no time base
BLOCK_TIME = 1e-4
#: the planner's fit of the measured edge of diamond D906, m (SOURCES.md)
NOSE_RADIUS = 189.36e-6
#: polynomial order of the form removed from the WLI export (sphere -> order 4)
FORM_ORDER = 4


def _detrend(s: np.ndarray, z: np.ndarray, order: int) -> np.ndarray:
    u = (s - s.mean()) / max(float(np.ptp(s)), 1e-12)
    a = np.vander(u, order + 1)
    return z - a @ np.linalg.lstsq(a, z, rcond=None)[0]


def register(
    case, s: np.ndarray, z: np.ndarray, *, span: float = 60e-6, n_azimuth: int = 64
) -> dict:
    """The line through the axis (azimuth, axis position on the profile, m)
    whose nominal model profile correlates best with the measured one."""
    from servosurf.diagnose._blocks import Context
    from servosurf.diagnose._surface import PointSet, surface_heights
    from servosurf.diagnose.effects import Model

    ctx = Context(case)
    centre = 0.5 * (s[0] + s[-1])
    ctx.cover(np.array([0.0, 0.5 * np.ptp(s) + span + 1e-6]))
    traj = ctx.trajectory(Model())
    zd = _detrend(s, z, FORM_ORDER)
    zd = (zd - zd.mean()) / zd.std()

    def corr(phi: float, s_axis: float) -> float:
        d = s - s_axis
        x, y = d * math.cos(phi), d * math.sin(phi)
        h = surface_heights(case, PointSet(case, x, y), Model(), traj)
        if not np.all(np.isfinite(h)) or np.std(h) == 0:
            return -1.0
        hd = _detrend(s, h, FORM_ORDER)
        return float(np.mean(zd * (hd - hd.mean()) / hd.std()))

    step = float(np.median(np.diff(s)))
    axes = centre + np.arange(-span, span + step / 2, step)
    best = (-2.0, 0.0, centre)
    for phi in np.arange(n_azimuth) * 2 * math.pi / n_azimuth:
        for sa in axes[::4]:
            c = corr(phi, sa)
            if c > best[0]:
                best = (c, phi, sa)
    # refine around the best: finer azimuth and every axis sample
    c0, phi0, sa0 = best
    dphi = 2 * math.pi / n_azimuth
    for phi in phi0 + np.linspace(-dphi, dphi, 9):
        for sa in sa0 + np.arange(-4, 5) * step:
            c = corr(phi, sa)
            if c > best[0]:
                best = (c, phi, sa)
    c, phi, sa = best
    return {
        "correlation": c,
        "azimuth_rad": float(phi % (2 * math.pi)),
        "axis_on_profile_m": float(sa),
    }


def write_toolpath(folder: Path) -> Path:
    """The NC TOML of case 1022 with this benchmark's time base."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "1022_nc.toml"
    path.write_text(
        'kind = "nc"\ndescription = "1022: concave sphere, STS spiral"\n[nc]\n'
        f'program = "{PROGRAM.as_posix()}"\nblock-time = {BLOCK_TIME!r}  # s\n'
        'reference = "tip"\nrotation = "ccw"\n'
        f"[tool]\nnose-radius = {NOSE_RADIUS!r}  # m\n"
    )
    return path


def write_manifest(folder: Path, reg: dict) -> Path:
    """The profile-only manifest of case 1022 (paths into ../shared)."""
    phi, sa = float(reg["azimuth_rad"]), float(reg["axis_on_profile_m"])
    start = (-sa * math.cos(phi), -sa * math.sin(phi))
    toolpath = write_toolpath(folder)
    text = (
        "# Case 1022 (../shared/data/upm_sts/SOURCES.md): the WLI profile through\n"
        "# the centre against the NC program's spiral (benchmarks/"
        "real_cut_1022_diagnose.py)\n"
        f'[case]\nmachine = "{MACHINE}"\n'
        f'toolpath = "{toolpath.as_posix()}"\n\n'
        f'[[recording]]\npath = "{PROFILE.as_posix()}"\nkind = "profile"\n'
        f"start = [{start[0]!r}, {start[1]!r}]  # m, the profile's s = 0\n"
        f"direction = {phi!r}  # rad, registered azimuth of the line\n"
        f"form-order = {FORM_ORDER}  # the WLI export's form removed\n"
    )
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "manifest.toml"
    path.write_text(text)
    return path


def run(out: Path) -> dict:
    """Register, write the manifest, diagnose; the result as a dict (SI units)."""
    from servosurf.diagnose import build_case, diagnose, load_manifest
    from servosurf.io import read_profile

    prof = read_profile(PROFILE)
    z = np.asarray(prof.z, dtype=float)
    s = prof.x0 + prof.dx * np.arange(z.size)
    ok = np.isfinite(z)
    # a first manifest (any line) gives the case; the registration needs it only
    tmp = write_manifest(
        out, {"azimuth_rad": 0.0, "axis_on_profile_m": 0.5 * (s[0] + s[-1])}
    )
    case = build_case(load_manifest(tmp))
    reg = register(case, s[ok], z[ok])
    manifest = write_manifest(out, reg)
    d = diagnose(manifest)
    res = d.to_dict() if hasattr(d, "to_dict") else dict(d)
    return {"registration": reg, "manifest": str(manifest), "diagnosis": res}


def _summary(r: dict) -> list[str]:
    d = r["diagnosis"]
    reg = r["registration"]
    lines = [
        f"registration: azimuth {math.degrees(reg['azimuth_rad']):.1f} deg, axis at "
        f"{reg['axis_on_profile_m'] * 1e6:.1f} um on the profile, correlation "
        f"{reg['correlation']:.3f}",
        f"verdict: {d.get('verdict')}",
        f"fit: {d.get('fit_before_percent'):.2f} % nominal -> "
        f"{d.get('fit_after_percent'):.2f} % fitted; unexplained share "
        f"{d.get('unexplained_power_fraction'):.2f}",
    ]
    for e in d.get("explanations", []):
        lines.append(
            f"explanation: {e.get('effect')} {e.get('parameters')} "
            f"dBIC {e.get('delta_bic')}"
        )
    for e in d.get("refused", []):
        lines.append(f"refused: {e['effect']} {e['parameters']}: {e['reason']}")
    for m in d.get("mismatches", []):
        lines.append(
            f"mismatch (nominal): {m['where']} ({m['test']}, -log10 p "
            f"{m['significance']})"
        )
    for m in d.get("remainder", []):
        lines.append(
            f"residual after the fit: {m['where']} ({m['test']}, -log10 p "
            f"{m['significance']})"
        )
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("results") / "1022-diagnose")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if not PROFILE.is_file():
        print(f"the shared data are absent ({PROFILE})", file=sys.stderr)
        return 1
    r = run(args.out)
    if args.json:
        print(json.dumps(r, indent=2, default=str))
    else:
        print("\n".join(_summary(r)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
