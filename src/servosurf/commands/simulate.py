"""``servosurf simulate``: the machined surface as an interferometer would see it."""

from __future__ import annotations

import argparse
import math

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
        metavar="TOOLPATH.toml|PROGRAM",
        help="toolpath definition (TOML), or an NC program: G-code (.nc, .txt, "
        "...), a DIFFSYS .pgm job or a c_deg,x_m,z_m .csv",
    )
    p.add_argument(
        "--workpiece",
        metavar="W.toml",
        help="workpiece/material definition (default: electroless NiP, flat)",
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
        choices=("tracking", "force", "vibration", "kinematic"),
        default=None,
        help="deviation parts to include: tracking, force, vibration (default: all "
        "of them on the FTS, tracking on a second-order machine axis), or kinematic "
        "alone: the commanded path without the loop (the default of NC programs, "
        "whose default machine has ideal axes)",
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

    from ..errors import ConfigError
    from ..toolpath import Tool, load_toolpath, nc_spec

    tp = Path(args.toolpath)
    if not tp.is_file():
        raise ConfigError(f"{tp}: toolpath file not found")
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


def run(args) -> int:
    from pathlib import Path

    import numpy as np

    from .._progress import stage
    from ..errors import ConfigError
    from ..report._simulation import analyse
    from ..simulation import simulate
    from ..viz import _surface_plots as sp
    from ._common import out_dir, print_json, write_json

    _check_cli_values(args)

    if args.bandwidth is not None and not (
        np.isfinite(args.bandwidth) and args.bandwidth > 0
    ):
        raise ConfigError(
            f"--bandwidth must be a positive frequency in Hz, got {args.bandwidth!r}"
        )
    if args.mass is not None and not (np.isfinite(args.mass) and args.mass > 0):
        raise ConfigError(f"--mass must be a positive mass in kg, got {args.mass!r}")
    if args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    if args.realisations < 1:
        raise ConfigError(f"--realisations must be >= 1, got {args.realisations}")
    tp = Path(args.toolpath)
    edge = _measured_edge(args)
    spec = load_spec(args, edge)
    fmt = args.format or "datx"
    instrument = args.instrument or ("none" if spec.kind == "nc" else "cp300-20x")
    settings = {  # the paper's cutting set-up unless given
        "machine": args.machine,
        "workpiece": args.workpiece,
        "bandwidth": 1448.0 if args.bandwidth is None else args.bandwidth,
        "mass": 0.175 if args.mass is None else args.mass,
        "parts": None if args.parts is None else tuple(args.parts),
        "instrument": None if instrument == "none" else instrument,
    }
    if edge is not None:
        from ..toolpath import MeasuredEdge

        settings["hooks"] = (MeasuredEdge(edge, compensated=args.edge_compensated),)
    if args.realisations > 1:
        out = out_dir(args.out or Path("results") / tp.stem)
        return _run_realisations(args, spec, tp, out, settings)
    res = simulate(spec, seed=args.seed, **settings)
    if spec.kind == "nc":
        return _finish_nc(args, res, tp, fmt, edge)
    out = out_dir(args.out or Path("results") / tp.stem)
    with stage("analysis"):
        summary = analyse(res)
    plots = summary.pop("_plots")
    surf = res.measured if res.measured is not None else res.surface
    files = {}
    with stage("writing map and figures"):
        files["map"] = str(_write_map(surf, out / f"surface.{fmt}", fmt))
        files["map_png"] = str(
            sp.plot_map(surf, out / "map.png", title=f"{tp.stem}: simulated height map")
        )
        files["highpass_png"] = str(
            sp.plot_map(
                plots["highpass"],
                out / "highpass.png",
                title="80 mm^-1 high-pass"
                + (" of the form error" if "profile" in plots else ""),
            )
        )
        if "form_error" in plots:  # design surface: error map against the design
            from ..viz._form_plots import plot_design_feed, plot_form_error

            files["form_error_png"] = str(plot_form_error(
                plots["form_error"], out / "form_error.png",
                title=f"{tp.stem}: form error against the design"))
            fld = res.spec.field
            files["toolpath_png"] = str(plot_design_feed(
                res.spec.path, out / "toolpath.png",
                theta=float(np.arctan2(fld.center_y, fld.center_x))))
        freq, psd, peaks = plots["spectrum"]
        speed = summary.get("surface_speed_m_per_s")
        files["spectrum_png"] = str(
            sp.plot_spectrum(freq, psd, peaks, out / "spectrum.png", speed=speed)
        )
        if "profile" in plots:
            y, z, fe = plots["profile"]
            files["profile_png"] = str(
                sp.plot_profile_with_form_error(
                    y, z, fe["reference"], fe["error"], out / "profile.png"
                )
            )
        if res.t.size:
            _plot_deviation(res, out / "deviation.png")
            files["deviation_png"] = str(out / "deviation.png")
        if not args.no_render:
            from ..viz._render import render_surface

            files["render_png"] = str(
                render_surface(surf, out / "render.png", title=f"{tp.stem} (simulated)")
            )
        if args.mesh:
            from ..viz._mesh import write_mesh

            files["mesh"] = str(write_mesh(surf, out / f"surface.{args.mesh}"))
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
    elif "form_error_pv_m" in summary:
        nm = {k: summary[k] * 1e9 for k in ("form_error_pv_m", "form_error_rms_m",
                                            "form_error_pv_bfs_m",
                                            "form_error_rms_bfs_m")}
        print(f"form error against the design: PV {nm['form_error_pv_m']:.2f} nm, "
              f"RMS {nm['form_error_rms_m']:.2f} nm (after piston and tilt); after "
              f"the best-fit sphere: PV {nm['form_error_pv_bfs_m']:.2f} nm, RMS "
              f"{nm['form_error_rms_bfs_m']:.2f} nm")
    return 0


def _measured_edge(args):
    """``--tool EDGE``: the fitted trace (None without --tool)."""
    from ..errors import ConfigError

    if not args.tool:
        if args.edge_compensated:
            raise ConfigError("--edge-compensated needs --tool EDGE (a measured edge)")
        return None
    from ..toolpath import read_tool_edge

    return read_tool_edge(args.tool)


def _finish_nc(args, res, tp, fmt, edge=None) -> int:
    """Analysis, map, figures and summary of an NC-program run."""
    from pathlib import Path

    from .._progress import stage
    from ..report import analyse_nc
    from ..viz._nc_plots import nc_figures
    from ._common import out_dir, print_json, write_json

    with stage("analysis of the centre profile"):
        summary = analyse_nc(res, profile_length=args.profile_length)
    plots = summary.pop("_plots")
    out = out_dir(args.out or Path("results") / tp.stem)
    surf = res.measured if res.measured is not None else res.surface
    files = {}
    with stage("writing map and figures"):
        files["map"] = str(_write_map(surf, out / f"surface.{fmt}", fmt))
        files.update(nc_figures(res, plots, out, name=tp.stem))
        if args.mesh:
            from ..viz._mesh import write_mesh

            files["mesh"] = str(write_mesh(surf, out / f"surface.{args.mesh}"))
        if edge is not None:
            files["tool_edge_png"] = str(edge.plot(out / "tool_edge.png"))
            summary["tool_edge"] = {**edge.summary(),
                                    "compensated": bool(args.edge_compensated)}
    summary.update(settings=res.settings, files=files, input_file=str(tp))
    write_json(out / "summary.json", summary)
    if args.json:
        print_json(summary)
    else:
        rough = summary["roughness"]
        if rough["ra_m"] is None:
            print(f"centre profile: roughness not evaluated "
                  f"({rough['not_evaluated']}); written to {out}")
            return 0
        print(f"centre profile: Ra {rough['ra_m'] * 1e9:.1f} nm, Rq "
              f"{rough['rq_m'] * 1e9:.1f} nm, Rz {rough['rz_m'] * 1e9:.1f} nm, RSm "
              f"{rough['rsm_m'] * 1e6:.2f} um (cut-off {rough['cutoff_m'] * 1e3:g} "
              f"mm, evaluation length {rough['evaluation_length_m'] * 1e3:.3g} mm); "
              f"written to {out}")
    return 0


def _run_realisations(args, spec, tp, out, settings) -> int:
    """``--realisations K``: one simulation per seed, metrics and their spread.

    ``settings`` are the :func:`~servosurf.simulation.simulate` keywords but the seed.
    """
    from .._progress import bar, stage
    from ..simulation import realisation_study
    from ._common import dask_client, print_json, write_json

    seeds = list(range(args.seed, args.seed + args.realisations))
    with dask_client(args.scheduler, args.workers) as client, \
            stage(f"{len(seeds)} realisations (seeds {seeds[0]}..{seeds[-1]})"):
        study = realisation_study(
            spec,
            seeds=seeds,
            client=client,
            progress=lambda it, total=None: bar(it, total=total, desc="realisations"),
            **settings,
        )
    summary = study.to_dict()
    summary.update(toolpath=str(tp), scheduler=args.scheduler,
                   bandwidth_hz=settings["bandwidth"],
                   moving_mass_kg=settings["mass"],
                   parts=None if args.parts is None else list(args.parts),
                   instrument=settings["instrument"] or "none")
    with stage("writing realisations.json and realisations.png"):
        png = _plot_realisations(study, out / "realisations.png")
        summary["files"] = {"png": str(png)}
        write_json(out / "realisations.json", summary)
    if args.json:
        print_json(summary)
    return 0


def _plot_realisations(study, path):
    """Per-seed metrics as strip plots with their mean and 5-95 % band."""
    import numpy as np

    from ..viz._common import figure, save

    shown = [
        ("form_error_max_m", "max form error [nm]", 1e9),
        ("ra_m", "Ra [nm]", 1e9),
        ("sa_m", "Sa [nm]", 1e9),
        ("peak1_per_m", "strongest spectral peak [1/mm]", 1e-3),
    ]
    shown = [s for s in shown if np.isfinite(study.metrics[s[0]]).any()]
    fig, axes = figure(1, len(shown), figsize=(3.2 * len(shown), 3.6), squeeze=False)
    for ax, (key, label, scale) in zip(axes[0], shown, strict=True):
        v = study.metrics[key] * scale
        v = v[np.isfinite(v)]
        x = np.random.default_rng(0).uniform(-0.15, 0.15, v.size)  # jitter only
        ax.plot(x, v, "o", ms=4, alpha=0.7)
        ax.axhline(v.mean(), color="C3", lw=1)
        ax.axhspan(np.percentile(v, 5), np.percentile(v, 95), color="C3", alpha=0.12)
        ax.set_xlim(-0.5, 0.5)
        ax.set_xticks([])
        ax.set_ylabel(label)
    fig.suptitle(f"{study.seeds.size} vibration realisations: mean (line), 5-95 % "
                 "(band)")
    fig.tight_layout()
    return save(fig, path)


def _plot_deviation(res, path):
    """Force, tool deviation and following error over the last cutting cycles."""
    import numpy as np

    from ..viz._common import figure, save

    fs = res.machine.controller.sample_rate
    n = min(res.t.size, int(0.035 * fs))
    sl = slice(res.t.size - n, res.t.size)
    t = (res.t[sl] - res.t[sl][0]) * 1e3
    fig, ax = figure(2, 1, figsize=(8, 5.5), sharex=True)
    ax[0].plot(t, res.force[sl], color="C3")
    ax[0].set_ylabel("thrust force [N]")
    for name, dev in res.deviation.items():
        if np.any(dev[sl]):
            ax[1].plot(t, dev[sl] * 1e9, label=name, lw=0.8)
    ax[1].plot(
        t,
        res.following_error[sl] * 1e9,
        "k",
        lw=0.5,
        alpha=0.6,
        label="following error",
    )
    ax[1].set_ylabel("tool deviation [nm]")
    ax[1].set_xlabel("time [ms]")
    ax[1].legend(fontsize=7)
    ax[0].set_title("Cutting force and tool deviation (cf. Fig. 17b)")
    save(fig, path)
