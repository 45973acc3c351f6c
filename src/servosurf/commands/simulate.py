"""``servosurf simulate``: the machined surface as an interferometer would see it."""

from __future__ import annotations

import argparse
import math

from .._parts import ALL_PARTS
from ._common import add_scheduler_args

FORMATS = ("datx", "dat", "x3p", "xyz", "npz")


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "simulate",
        help="simulate the surface an FTS cuts (height map, figures, summary)",
        description="Sweep the round-nose tool along the toolpath with the servo "
        "tracking, cutting-force and vibration deviations; write the height map, "
        "summary.json and PNG figures. Bandwidths are open-loop crossover frequencies.",
    )
    p.add_argument(
        "toolpath",
        metavar="TOOLPATH|PROGRAM",
        help="toolpath TOML file or built-in name (servosurf toolpaths), or an NC "
        "program: G-code (.nc, .txt, ...), a DIFFSYS .pgm job or a c_deg,x_m,z_m "
        ".csv",
    )
    p.add_argument(
        "--workpiece",
        metavar="W",
        help="workpiece TOML file or built-in name (default: electroless NiP, flat)",
    )
    p.add_argument("--machine", metavar="M.toml", help="machine TOML or built-in name")
    p.add_argument(
        "--bandwidth",
        metavar="HZ",
        type=float,
        help="crossover bandwidth in Hz (default 1448 Hz, the paper's cutting set-up)",
    )
    p.add_argument(
        "--mass",
        metavar="KG",
        type=float,
        help="moving mass m1+m2 in kg (default 0.175 kg, the paper's cutting set-up)",
    )
    p.add_argument(
        "--seed",
        metavar="N",
        type=int,
        default=0,
        help="seed of the vibration realisation and instrument noise (default 0)",
    )
    p.add_argument(
        "--parts",
        metavar="PART",
        nargs="+",
        choices=(*ALL_PARTS, "kinematic"),
        default=None,
        help="model parts to include (default: tracking force vibration, the servo "
        "loop, on the FTS; tracking on a second-order machine axis). Beyond the "
        "loop: out-of-loop (frame motion that bypasses the loop when the "
        "machine's sensor.target is fts-base), spindle (asynchronous spindle axial "
        "error, machine [spindle]), ploughing (minimum chip thickness), side-flow "
        "(ridges at the cusps), recovery (elastic recovery by local chip "
        "thickness); the last three scale with the tool's edge-radius (m) and the "
        "workpiece's [material] ratios. Or kinematic alone: the commanded path "
        "without the loop (the default of NC programs, whose default machine has "
        "ideal axes)",
    )
    p.add_argument(
        "--instrument",
        metavar="NAME",
        default=None,
        help="interferometer model applied to the machined map: cp300-20x (default "
        "for TOML toolpaths, the paper's instrument), newview-20x/50x/100x, or none "
        "(default for NC programs)",
    )
    p.add_argument(
        "--format",
        choices=FORMATS,
        default=None,
        help="height-map file format (default datx)",
    )
    p.add_argument(
        "--mesh",
        metavar="EXT",
        choices=("stl", "ply"),
        help="also write a triangle mesh of the map (m)",
    )
    p.add_argument("--no-render", action="store_true", help="skip the 3-D render PNG")
    p.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        help="output directory (default results/<toolpath name>)",
    )
    p.add_argument(
        "--realisations",
        metavar="K",
        type=int,
        default=1,
        help="K > 1: simulate seeds SEED..SEED+K-1 of the vibration realisation and "
        "write realisations.json (per-seed metrics in SI and their statistics) and "
        "realisations.png instead of one map (default 1)",
    )
    add_scheduler_args(p, "the realisations (one task per seed)")
    p.add_argument("--json", action="store_true", help="print summary.json on stdout")
    p.add_argument("--force", action="store_true",
                   help="run even when the memory or disk estimate exceeds what this "
                   "machine has")
    _add_nc_args(p)
    return p


def _add_nc_args(p) -> None:
    """Flags of NC programs (and the tool of any toolpath)."""
    g = p.add_argument_group(
        "NC programs", "time base and conventions of an NC program (a PROGRAM given "
        "directly, or a TOML of kind nc whose [nc] values these replace)")
    tb = g.add_mutually_exclusive_group()
    tb.add_argument("--spindle-rpm", metavar="N", type=float, default=None,
                    help="spindle speed in rev/min: C turns at this constant speed")
    tb.add_argument("--block-time", metavar="S", type=float, default=None,
                    help="duration of every cutting block, in s")
    g.add_argument("--feed-per-rev", metavar="M", type=float, default=None,
                   help="two-axis programs (DIFFSYS .pgm): path length per "
                   "revolution in m (with --spindle-rpm)")
    g.add_argument("--reference", choices=("tip", "centre"), default=None,
                   help="the program's Z is the tool tip (front point) or the nose "
                   "centre (default: what the program states, else tip)")
    g.add_argument("--rotation", choices=("ccw", "cw"), default=None,
                   help="sense in which the tool moves over the part, seen from the "
                   "tool side, as C increases (default ccw: theta = +C)")
    g.add_argument("--units", choices=("mm", "inch"), default=None,
                   help="units of a program that sets none (default mm)")
    g.add_argument("--profile-length", metavar="M", type=float, default=None,
                   help="length in m of the centre profile evaluated for roughness, "
                   "centred on the axis (default: the whole band); give the "
                   "measuring instrument's profile length to compare like with like")
    tool = p.add_argument_group("tool", "the cutting tool (replaces the file's)")
    edge = tool.add_mutually_exclusive_group()
    edge.add_argument("--tool-radius", metavar="M", type=float, default=None,
                      help="tool nose radius in m (e.g. 189.36e-6)")
    edge.add_argument(
        "--tool", metavar="EDGE",
        help="measured tool-edge trace (laser-probe CSV, or x,[y,]z rows in mm): "
        "its fitted nose radius (m), usable arc and edge deviation replace the "
        "toolpath's tool; writes tool_edge.png")
    tool.add_argument(
        "--edge-compensated", action="store_true",
        help="with --tool: the radius-only model, a round nose of the trace's "
        "fitted radius without the edge's shape. Not needed for a program that "
        "compensates the edge: the compensation is in the program's Z and the "
        "cusps are still imprints of the edge's shape, which --tool sweeps by "
        "default (evidence: benchmarks/real_cut_1022.py)")


def _check_cli_values(args) -> None:
    """Refuse physically absurd flag values early, naming the likely unit slip."""
    from ..errors import ConfigError

    r = args.tool_radius
    if r is not None:
        if not (math.isfinite(r) and r > 0):
            raise ConfigError(
                f"--tool-radius must be a positive radius in m, got {r!r}")
        if r > 0.02:
            raise ConfigError(
                f"--tool-radius {r:g} m is not a diamond tool's nose radius (at most "
                f"0.02 m): a value in um or mm? {r:g} um = {r * 1e-6:g} m, "
                f"{r:g} mm = {r * 1e-3:g} m")
        if r < 1e-6:
            raise ConfigError(f"--tool-radius {r:g} m is below 1 um: a value in m is "
                              "expected (e.g. 189.36e-6)")
    n = args.spindle_rpm
    if n is not None and not (math.isfinite(n) and 0 < n <= 20000):
        raise ConfigError(f"--spindle-rpm must be in (0, 20000] rev/min, got {n!r}")
    b = args.block_time
    if b is not None and not (math.isfinite(b) and 0 < b <= 60):
        raise ConfigError(f"--block-time must be in (0, 60] s per block, got {b!r} "
                          "(a value in ms?)" if (b is not None and b > 60) else
                          f"--block-time must be in (0, 60] s per block, got {b!r}")
    f = args.feed_per_rev
    if f is not None and not (math.isfinite(f) and 0 < f <= 1e-3):
        raise ConfigError(f"--feed-per-rev must be in (0, 1e-3] m, got {f!r} (a value "
                          "in um or mm?)")
    L = args.profile_length
    if L is not None and not (math.isfinite(L) and 0 < L <= 1.0):
        raise ConfigError(f"--profile-length must be in (0, 1] m, got {L!r} (a value "
                          "in mm?)")


def _nc_overrides(args) -> dict:
    """NCSettings fields given on the command line (None: not given)."""
    return {
        "spindle_speed": None if args.spindle_rpm is None else args.spindle_rpm / 60.0,
        "block_time": args.block_time,
        "feed_per_rev": args.feed_per_rev,
        "reference": args.reference,
        "rotation": args.rotation,
        "units": args.units,
    }


def load_spec(args, edge=None):
    """The toolpath spec of the positional argument (TOML or NC program).

    ``edge``: the measured tool edge of ``--tool`` (its fitted radius stands in for
    ``--tool-radius``; the simulation hook then swaps the whole edge in).
    """
    import dataclasses
    from pathlib import Path

    from .._builtins import resolve_file
    from ..errors import ConfigError
    from ..toolpath import Tool, load_toolpath, nc_spec

    tp = Path(args.toolpath)
    if not tp.is_file():
        tp = resolve_file(args.toolpath, kind="toolpath")  # a built-in name
    nc = _nc_overrides(args)
    radius = args.tool_radius if edge is None else edge.radius
    if tp.suffix.lower() == ".toml":
        spec = load_toolpath(tp, nose_radius=radius, nc_overrides=nc)
        if spec.kind != "nc":
            given = [f"--{k.replace('_', '-')}" for k in
                     ("spindle_rpm", "block_time", "feed_per_rev", "reference",
                      "rotation", "units", "profile_length")
                     if getattr(args, k) is not None]
            if given:
                raise ConfigError(f"{given[0]} applies to NC programs; {tp} is a "
                                  f"{spec.kind} toolpath")
            if args.tool_radius is not None:
                spec = dataclasses.replace(
                    spec, tool=dataclasses.replace(spec.tool,
                                                   nose_radius=args.tool_radius))
        return spec
    tool = None if radius is None else Tool(nose_radius=radius)
    return nc_spec(tp, tool=tool, **{k: v for k, v in nc.items() if v is not None})


def _write_map(surface, path, fmt):
    """Write the height map with the io writers (atomic), settings as metadata."""
    from ..io import write_surface

    write_surface(surface, path, format=fmt)
    return path


def _check_footprint(args, spec, tp, out) -> None:
    """Estimate memory and disk before allocating; refuse above the machine's."""
    from .._resources import SIM_BYTES_PER_PIXEL, SIM_BYTES_PER_SAMPLE, check_resources
    from ..servo import load_machine
    from ..simulation import SETTLE_TIME, cutting_span

    fs = load_machine(args.machine).controller.sample_rate
    t0, t1 = cutting_span(spec, spec.tool)
    samples = (t1 - t0 + SETTLE_TIME) * fs
    f = spec.field
    pixels = float(f.nx) * float(f.ny)
    memory = pixels * SIM_BYTES_PER_PIXEL + samples * SIM_BYTES_PER_SAMPLE
    # map file, PNGs and an optional mesh (binary STL: 2 triangles of 50 B per pixel)
    disk = pixels * (8 + (100 if args.mesh else 0)) + 5e6
    check_resources(
        f"{tp.stem}'s {f.ny} x {f.nx} px field with {samples:.3g} controller samples",
        memory=memory, disk=disk, where=out, force=args.force,
        remedy="lower field.nx/field.ny or raise field.pitch-x/pitch-y",
    )


def run(args) -> int:
    from pathlib import Path

    from .._progress import stage
    from ..errors import ConfigError
    from ..report import analyse
    from ..run import DEFAULT_PRESET, preset
    from ..simulation import simulate
    from ._common import check_flags, output_folder, print_json, write_json

    check_flags(args)  # --bandwidth, --mass: positive and plausible
    _check_cli_values(args)
    if args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    if args.realisations < 1:
        raise ConfigError(f"--realisations must be >= 1, got {args.realisations}")
    tp = Path(args.toolpath)
    edge = _measured_edge(args)
    spec = load_spec(args, edge)
    fmt = args.format or "datx"
    # the paper's cutting set-up unless given; NC programs: no instrument model
    run_cfg = preset(DEFAULT_PRESET).with_overrides(
        machine=args.machine, workpiece=args.workpiece, bandwidth=args.bandwidth,
        mass=args.mass, seed=args.seed,
        parts=None if args.parts is None else tuple(args.parts),
        instrument=args.instrument or ("none" if spec.kind == "nc" else None))
    hooks = ()
    if edge is not None:
        from ..toolpath import MeasuredEdge

        hooks = (MeasuredEdge(edge, compensated=args.edge_compensated),)
    dest = args.out or Path("results") / tp.stem
    if spec.kind != "nc":
        _check_footprint(args, spec, tp, dest)
    out = output_folder(dest)  # swapped in place of --out at the end
    if args.realisations > 1:
        return _run_realisations(args, spec, tp, out, run_cfg, hooks)
    res = simulate(spec, run_cfg, hooks=hooks)
    if spec.kind == "nc":
        return _finish_nc(args, res, tp, fmt, out, edge)
    with stage("analysis"):
        analysis = analyse(res)
    summary = analysis.to_dict()
    surf = res.measured if res.measured is not None else res.surface
    files = {}
    with stage("writing map and figures"):
        files["map"] = str(_write_map(surf, out / f"surface.{fmt}", fmt))
        files.update(analysis.plot(out, name=tp.stem, render=not args.no_render))
        if args.mesh:
            from ..viz import write_mesh

            files["mesh"] = str(write_mesh(surf, out / f"surface.{args.mesh}"))
        manifest = _write_manifest(args, res, surf, files["map"], out)
        if manifest is not None:
            files["manifest"] = str(manifest)
        if edge is not None:
            files["tool_edge_png"] = str(edge.plot(out / "tool_edge.png"))
            summary["tool_edge"] = {
                **edge.summary(),
                "compensated": bool(args.edge_compensated),
            }
    summary.update(
        settings=res.settings,
        files=files,
        toolpath=str(tp),
        field={
            "nx": res.spec.field.nx,
            "ny": res.spec.field.ny,
            "pitch_x_m": res.spec.field.pitch_x,
            "pitch_y_m": res.spec.field.pitch_y,
        },
    )
    write_json(out / "summary.json", summary)
    if args.json:
        print_json(summary)
    _print_result(args, tp, res, summary, out)
    return 0


def _write_manifest(args, res, surf, map_file, out):
    """``manifest.toml`` beside the map: ``servosurf diagnose`` on it is the null
    test, and a measured map put in its place is diagnosed against this case.

    Written for the toolpath kinds the diagnosis models, when the toolpath file
    describes the run (no ``--tool``/``--tool-radius`` override) and the tool
    height comes from the FTS loop (not a kinematic run, not another Z axis);
    None otherwise.
    """
    from pathlib import Path

    from .._builtins import resolve_file
    from ..diagnose import DIAGNOSABLE_TOOLPATHS, simulation_manifest
    from ..simulation import DEFAULT_PARTS, KINEMATIC

    if res.spec.kind not in DIAGNOSABLE_TOOLPATHS or args.tool or (
            args.tool_radius is not None):
        return None
    if res.machine.axis.model != "fts" or KINEMATIC in res.settings.get("parts", ()):
        return None  # the diagnosis models the FTS loop
    tp = Path(args.toolpath)  # a file given: its absolute path; a built-in: its name
    tp = str(tp.resolve()) if tp.is_file() else resolve_file(
        args.toolpath, kind="toolpath").stem

    def where(v):  # a file given on the command line, absolute; a built-in name
        return None if v is None else (str(Path(v).resolve()) if Path(v).is_file()
                                       else str(v))

    st = res.settings
    parts = tuple(st.get("parts", DEFAULT_PARTS))
    # an NC program on the FTS: tracking and vibration (no chip force)
    modelled = (("tracking", "vibration") if res.spec.kind == "nc"
                else tuple(DEFAULT_PARTS))
    note = "" if parts == modelled else (
        f"simulated with parts {', '.join(parts)}; the diagnosis models "
        f"{', '.join(modelled)}")
    machine = where(args.machine)
    text = simulation_manifest(
        toolpath=str(tp), recording=Path(map_file).name, machine=machine,
        bandwidth=st.get("bandwidth_hz"), moving_mass=st.get("moving_mass_kg"),
        workpiece=where(args.workpiece), x0=surf.x0, y0=surf.y0, note=note)
    path = out / "manifest.toml"
    path.write_text(text)
    return path


def _print_result(args, tp, res, summary, out) -> None:
    """The numbers a user came for, with units, and where they were written."""
    from ._common import fmt_length, print_summary

    s, f = summary, res.spec.field
    rows = []
    if s.get("form_error_pv_m") is not None:  # design surface
        rows.append(("form error vs design", f"PV {fmt_length(s['form_error_pv_m'])}, "
                     f"RMS {fmt_length(s['form_error_rms_m'])} (after piston and "
                     "tilt)"))
        if s.get("form_error_pv_bfs_m") is not None:
            rows.append(("after best-fit sphere",
                         f"PV {fmt_length(s['form_error_pv_bfs_m'])}, RMS "
                         f"{fmt_length(s['form_error_rms_bfs_m'])}"))
    elif s.get("form_error_max_m") is not None:
        lag = s.get("form_error_lag_m")
        rows.append(("max form error", fmt_length(s["form_error_max_m"])
                     + (f" ({fmt_length(lag, 'um')} after the deepest point)"
                        if lag is not None else "")))
    if s.get("form_error_rms_m") is not None and s.get("form_error_pv_m") is None:
        rows.append(("form error RMS", fmt_length(s["form_error_rms_m"])))
    rough = [(k, s.get(f"{k.lower()}_m")) for k in ("Ra", "Sa", "Sq")]
    rough = [(k, v) for k, v in rough if v is not None]
    if rough:
        rows.append((" / ".join(k for k, _ in rough),
                     " / ".join(f"{v * 1e9:.3g}" for _, v in rough) + " nm"))
    peaks = s.get("spectrum_peaks_per_m") or []
    if peaks:
        rows.append(("spectral peaks", ", ".join(f"{p * 1e-3:.0f}" for p in peaks[:5])
                     + " mm^-1 (strongest first)"))
    if s.get("deviation_max_m") is not None:
        rows.append(("max tool deviation", fmt_length(s["deviation_max_m"])
                     + f" (cutting force up to {s.get('force_max_n', 0):.3g} N)"))
    title = (f"simulate {tp.stem}: {f.ny} x {f.nx} px at "
             f"{f.pitch_x * 1e6:.3g} um, {res.machine.controller.bandwidth:g} Hz "
             f"crossover, {res.machine.mechanics.moving_mass:g} kg, seed {args.seed}")
    print_summary(args, title, rows, wrote=out)


def _measured_edge(args):
    """``--tool EDGE``: the fitted trace (None without --tool)."""
    from ..errors import ConfigError

    if not args.tool:
        if args.edge_compensated:
            raise ConfigError("--edge-compensated needs --tool EDGE (a measured edge)")
        return None
    from ..toolpath import read_tool_edge

    return read_tool_edge(args.tool)


def _finish_nc(args, res, tp, fmt, out, edge=None) -> int:
    """Analysis, map, figures and summary of an NC-program run."""

    from .._progress import stage
    from ..report import analyse_nc
    from ._common import fmt_length, print_json, print_summary, write_json

    with stage("analysis of the centre profile"):
        analysis = analyse_nc(res, profile_length=args.profile_length)
    summary = analysis.to_dict()
    surf = res.measured if res.measured is not None else res.surface
    files = {}
    with stage("writing map and figures"):
        files["map"] = str(_write_map(surf, out / f"surface.{fmt}", fmt))
        files.update(analysis.plot(out, name=tp.stem))
        if args.mesh:
            from ..viz import write_mesh

            files["mesh"] = str(write_mesh(surf, out / f"surface.{args.mesh}"))
        if edge is not None:
            files["tool_edge_png"] = str(edge.plot(out / "tool_edge.png"))
            summary["tool_edge"] = {**edge.summary(),
                                    "compensated": bool(args.edge_compensated)}
        if tp.suffix.lower() == ".toml":  # the NC TOML describes the whole run
            manifest = _write_manifest(args, res, surf, files["map"], out)
            if manifest is not None:
                files["manifest"] = str(manifest)
    summary.update(settings=res.settings, files=files, input_file=str(tp))
    write_json(out / "summary.json", summary)
    if args.json:
        print_json(summary)
    rough = summary["roughness"]
    if rough["ra_m"] is None:
        rows = [("roughness", f"not evaluated ({rough['not_evaluated']})")]
    else:
        rows = [
            ("Ra / Rq / Rz", f"{rough['ra_m'] * 1e9:.1f} / {rough['rq_m'] * 1e9:.1f} / "
             f"{rough['rz_m'] * 1e9:.1f} nm"),
            ("RSm", fmt_length(rough["rsm_m"], "um")),
            ("cut-off / evaluation", f"{rough['cutoff_m'] * 1e3:g} mm / "
             f"{rough['evaluation_length_m'] * 1e3:.3g} mm"),
        ]
    print_summary(args, f"simulate {tp.name}: centre profile", rows, wrote=out)
    return 0


def _run_realisations(args, spec, tp, out, run_cfg, hooks=()) -> int:
    """``--realisations K``: one simulation per seed, metrics and their spread.

    ``run_cfg`` is the run's :class:`~servosurf.run.RunConfig` (its seed is the
    first of the K seeds).
    """
    from .._progress import bar, stage
    from ..report import realisation_study
    from ._common import dask_client, print_json, write_json

    seeds = list(range(args.seed, args.seed + args.realisations))
    with dask_client(args.scheduler, args.workers) as client, \
            stage(f"{len(seeds)} realisations (seeds {seeds[0]}..{seeds[-1]})"):
        study = realisation_study(
            spec,
            run_cfg,
            seeds=seeds,
            client=client,
            progress=lambda it, total=None: bar(it, total=total, desc="realisations"),
            hooks=hooks,
        )
    summary = study.to_dict()
    summary.update(toolpath=str(tp), scheduler=args.scheduler,
                   bandwidth_hz=run_cfg.bandwidth,
                   moving_mass_kg=run_cfg.mass,
                   parts=None if args.parts is None else list(args.parts),
                   instrument=run_cfg.instrument or "none")
    with stage("writing realisations.json and realisations.png"):
        png = study.plot(out / "realisations.png")
        summary["files"] = {"png": str(png)}
        write_json(out / "realisations.json", summary)
    if args.json:
        print_json(summary)
    _print_realisations(args, tp, study, out)
    return 0


def _print_realisations(args, tp, study, out) -> None:
    """Mean and 5-95 % range of the headline metrics over the realisations."""
    from ._common import print_summary

    stats = study.statistics()
    rows = []
    for key, label, scale, unit in (
        ("form_error_max_m", "max form error", 1e9, "nm"),
        ("ra_m", "Ra", 1e9, "nm"),
        ("sa_m", "Sa", 1e9, "nm"),
        ("peak1_per_m", "strongest spectral line", 1e-3, "mm^-1"),
    ):
        st = stats.get(key)
        if st:
            rows.append((label, f"mean {st['mean'] * scale:.4g} {unit}, 5-95 % "
                         f"{st['p5'] * scale:.4g}..{st['p95'] * scale:.4g} {unit}"))
    print_summary(args, f"simulate {tp.stem}: {study.seeds.size} vibration "
                  f"realisations (seeds {study.seeds[0]}..{study.seeds[-1]})", rows,
                  wrote=out)
