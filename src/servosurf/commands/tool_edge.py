"""``servosurf tool-edge``: fit a measured tool-edge trace and show what a Tool gets."""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    """Register ``servosurf tool-edge`` and its flags on ``sub``."""
    p = sub.add_parser(
        "tool-edge",
        help="fit a measured tool-edge trace: nose radius, usable arc, spikes, "
        "edge deviation (figure, JSON, waviness CSV)",
        description="Read a tool-edge trace (laser-probe CSV with its header, or "
        "plain x,y,z / x,z rows, in mm unless --unit), fit the nose circle over "
        "the usable arc (flank bisector as the tool axis, +-45 degrees, 5 degrees "
        "clear of the flank tangent points), reject spikes (Hampel test, 4 robust "
        "standard deviations) and smooth the deviation (Gaussian, 25 um cut-off "
        "along the arc). Writes tool_edge.png, tool_edge.json (SI units) and "
        "edge_waviness.csv (angle_deg, deviation_m: usable as tool.edge-waviness). "
        "Text output in um and degrees.",
    )
    p.add_argument("trace", metavar="TRACE", help="tool-edge trace file")
    p.add_argument(
        "--unit",
        default="mm",
        help="length unit of the coordinates in the file (default mm)",
    )
    p.add_argument(
        "--mirror",
        action="store_true",
        help="the side of smaller x (first in-plane column) is outward (towards "
        "larger workpiece radius); default: larger x",
    )
    p.add_argument(
        "--half-angle-deg",
        metavar="DEG",
        type=float,
        help="largest contact angle of the usable arc on each side of the tool "
        "axis, in degree (default 45)",
    )
    p.add_argument(
        "--smoothing",
        metavar="M",
        type=float,
        help="cut-off wavelength of the Gaussian smoothing along the arc, in m "
        "(default 2.5e-5)",
    )
    p.add_argument(
        "--out", metavar="DIR", default="results/tool_edge", help="output directory"
    )
    p.add_argument("--json", action="store_true", help="print the JSON summary (SI)")
    return p


def run(args) -> int:
    """Fit the trace, write the figure, JSON and CSV; return the exit status."""
    import math

    from ..toolpath import EdgeSettings, read_tool_edge
    from ._common import atomic_write, out_dir, print_json, write_json

    kw = {}
    if args.half_angle_deg is not None:
        kw["half_angle"] = math.radians(args.half_angle_deg)
    if args.smoothing is not None:
        kw["smoothing"] = args.smoothing
    settings = EdgeSettings(mirror=args.mirror, **kw)
    edge = read_tool_edge(args.trace, unit=args.unit, settings=settings)
    d = out_dir(args.out)
    summary = edge.summary()
    rows = ["angle_deg,deviation_m"] + [
        f"{math.degrees(a):.6f},{w:.6e}"
        for a, w in zip(edge.waviness_angle, edge.waviness_deviation, strict=True)
    ]
    csv = "\n".join(rows) + "\n"
    files = {
        "png": str(edge.plot(d / "tool_edge.png")),
        "csv": str(atomic_write(d / "edge_waviness.csv", lambda p: p.write_text(csv))),
        "json": str(d / "tool_edge.json"),
    }
    summary["files"] = files
    write_json(d / "tool_edge.json", summary)
    if args.json:
        print_json(summary)
        return 0
    um, deg = 1e6, 180.0 / math.pi
    lo, hi = summary["arc_rad"]
    print(f"{args.trace}: {summary['points']} points ({args.unit}), in-plane "
          f"columns {summary['plane_columns']}")
    print(f"  nose radius    {summary['nose_radius_m'] * um:.3f} um")
    print(f"  centre         ({summary['centre_m'][0] * um:.3f}, "
          f"{summary['centre_m'][1] * um:.3f}) um")
    print(f"  tool axis      {summary['axis_angle_rad'] * deg:.2f} degree from +x")
    print(f"  usable arc     {lo * deg:.1f} .. {hi * deg:.1f} degree "
          f"({summary['points_used']} points used, {summary['spikes']} rejected)")
    print(f"  fit RMS        {summary['fit_rms_m'] * um:.3f} um, noise "
          f"{summary['noise_m'] * um:.3f} um")
    print(f"  deviation      PV {summary['deviation_pv_m'] * um:.3f} um, RMS "
          f"{summary['deviation_rms_m'] * um:.3f} um (smoothed)")
    for name, path in files.items():
        print(f"  {name:14} {path}")
    return 0
