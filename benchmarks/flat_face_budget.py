"""The seed paper's flat face: Ra by model part, and what each part needs to reach
the measured 1.2 nm (issue 18, item 6).

Usage::

    python benchmarks/flat_face_budget.py              # budget + scans, seed 0
    python benchmarks/flat_face_budget.py --seed 1 --json

1. The budget: :func:`servosurf.report.flat_face_budget` (each row a simulate run of
   the flat cut at 1448 Hz / 0.175 kg, the paper's cutting set-up, one part added
   per row, the shipped parameters; the sensor target on the FTS base for the
   out-of-loop row).
2. The scans: each part alone on top of today's model (the servo loop: tracking,
   force, vibration; sensor on the metrology frame), its parameter bisected until
   the flat-face Ra reaches 1.2 nm, on the machined map ("model") and on the
   interferometer model's map ("cp300-20x"). The deviations are computed once
   (:class:`servosurf.report.FlatFaceModel`); a scan point adds them to the
   sampled path and sweeps with :func:`servosurf._parts.machine_surface`, the
   function simulate uses (checked against a simulate run at the shipped value).

Parameters scanned (SI in the JSON, nm in the table):

* ploughing: the cutting-edge radius r_n at h_min / r_n = 0.25 (h_min reported);
* side-flow: the ridge height a at r_n = 20 nm, b = 10 r_n;
* recovery: d0 at h_d = r_n = 20 nm;
* spindle: the RMS of the asynchronous axial error (the shipped PSD scaled);
* out-of-loop: the amplitude factor on the base-vibration PSD's square root (the
  calibrated base PSD, 0.75 nm RMS above 48.7 Hz, is 1), sensor on the FTS base.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FLAT = ROOT / "toolpaths" / "flat_facing.toml"
TARGET = 1.2e-9  # m, the paper's measured Ra (no filter)


def bisect(fn, lo, hi, target, *, iters=14):
    """Root of fn(x) = target on [lo, hi] (fn increasing), geometric bisection;
    returns (x or None when [lo, hi] does not bracket it, fn(lo), fn(hi))."""
    flo, fhi = fn(lo), fn(hi)
    if not (flo <= target <= fhi):
        return None, flo, fhi
    for _ in range(iters):
        mid = math.sqrt(lo * hi)
        if fn(mid) < target:
            lo = mid
        else:
            hi = mid
    return math.sqrt(lo * hi), flo, fhi


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-budget", action="store_true")
    args = ap.parse_args(argv)

    from servosurf import _parts
    from servosurf._progress import set_quiet
    from servosurf.cutting import Material, Workpiece
    from servosurf.metrology import load_instrument, measure
    from servosurf.noise import realise
    from servosurf.report import FlatFaceModel, flat_face_budget, flat_face_ra
    from servosurf.run import preset
    from servosurf.servo import PSDModel, ServoLoop
    from servosurf.toolpath import field_reach, sample

    set_quiet(True)
    t_start = time.perf_counter()
    out: dict = {"seed": args.seed, "target_ra_m": TARGET}
    if not args.no_budget:
        budget = flat_face_budget(FLAT, seed=args.seed)
        out["budget"] = budget.to_dict()
        print(budget.table(), file=sys.stderr)

    model = FlatFaceModel(FLAT, sensor_target="fts-base", seed=args.seed)
    spec, fs = model.spec, model.machine.controller.sample_rate
    inst = load_instrument("cp300-20x")
    # base-only realisation with the same draw: the base part of "vibration"
    cut = preset("paper-cutting")  # the paper's cutting set-up
    m = model.machine.with_moving_mass(cut.mass).with_bandwidth(cut.bandwidth)
    d = dataclasses.replace(m.disturbances, sensor_noise=PSDModel(),
                            current_noise=PSDModel())
    base = realise(ServoLoop(dataclasses.replace(m, disturbances=d)),
                   int(model.t.size), seed=args.seed, sources=True,
                   out_of_loop=True)
    path0 = sample(spec, fs=fs, field=spec.field, tool=spec.tool,
                   reach=field_reach(spec.tool, spec.path.depth_of_cut))
    idx = path0.index - int(round(model.t[0] * fs))
    dev = model.deviation
    loop_dz = dev["tracking"] + dev["force"] + dev["vibration"]

    def ra_pair(dz, parts=(), tool=None, workpiece=None):
        tool = spec.tool if tool is None else tool
        path = path0.with_z(path0.z + dz[idx])
        surf = _parts.machine_surface(path, tool, spec.field, 0.0,
                                      workpiece or model.workpiece, parts)
        return flat_face_ra(surf), flat_face_ra(measure(surf, inst, seed=args.seed))

    # the fast path is simulate's: check it at the shipped values
    check = ra_pair(loop_dz, ("ploughing",))[0]
    sim = model.ra(_parts.LOOP_PARTS + ("ploughing",))
    assert abs(check - sim) <= 1e-9 * sim, (check, sim)
    today = ra_pair(loop_dz)
    out["today_ra_m"] = {"model": today[0], "cp300-20x": today[1]}

    def wp(**kw):
        return Workpiece(material=dataclasses.replace(Material(), **kw))

    scans = {
        "ploughing": dict(
            unit="m", what="edge radius r_n at h_min / r_n = 0.25", lo=1e-9, hi=200e-9,
            fn=lambda x, k: ra_pair(loop_dz, ("ploughing",),
                                    tool=dataclasses.replace(spec.tool,
                                                             edge_radius=x))[k]),
        "side-flow": dict(
            unit="m", what="ridge height a at r_n = 20 nm, b = 10 r_n", lo=0.02e-9,
            hi=20e-9,
            fn=lambda x, k: ra_pair(loop_dz, ("side-flow",),
                                    workpiece=wp(side_flow_height_ratio=x / 20e-9)
                                    )[k]),
        "recovery": dict(
            unit="m", what="recovery d0 at h_d = r_n = 20 nm", lo=0.02e-9, hi=20e-9,
            fn=lambda x, k: ra_pair(loop_dz, ("recovery",),
                                    workpiece=wp(recovery_ratio=x / 20e-9))[k]),
        "spindle": dict(
            unit="m", what="RMS of the asynchronous axial error", lo=0.05e-9,
            hi=20e-9,
            fn=lambda x, k: ra_pair(loop_dz + dev["spindle"] * (
                x / dev["spindle"].std()))[k]),
        "out-of-loop": dict(
            unit="", what="amplitude factor on the base vibration, sensor on the "
            "FTS base", lo=0.05, hi=30.0,
            fn=lambda x, k: ra_pair(loop_dz + (x - 1.0) * base.tool
                                    + x * base.out_of_loop)[k]),
    }
    out["spindle_shipped_rms_m"] = float(dev["spindle"].std())
    out["base_vibration_rms_m"] = float(base.sources["base_vibration"].std())
    res = {}
    for name, sc in scans.items():
        row = {"parameter": sc["what"], "unit": sc["unit"]}
        for k, label in ((0, "model"), (1, "cp300-20x")):
            x, flo, fhi = bisect(lambda v, k=k, sc=sc: sc["fn"](v, k), sc["lo"],
                                 sc["hi"], TARGET)
            row[label] = {"value_reaching_1.2nm": x, "ra_at_lo_m": flo,
                          "ra_at_hi_m": fhi, "lo": sc["lo"], "hi": sc["hi"]}
            if name == "ploughing" and x is not None:
                row[label]["h_min_m"] = 0.25 * x
        res[name] = row
        print(f"{name:12s} {sc['what']}: "
              + ", ".join(f"{lab} {row[lab]['value_reaching_1.2nm']}"
                          for lab in ("model", "cp300-20x")), file=sys.stderr)
    out["scans"] = res
    out["wall_s"] = time.perf_counter() - t_start
    if args.json:
        json.dump(out, sys.stdout, indent=1)
        print()
    else:
        print(json.dumps(out["scans"], indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
