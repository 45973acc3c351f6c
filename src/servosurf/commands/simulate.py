"""``servosurf simulate``: the machined surface as an interferometer would see it."""

from __future__ import annotations

import argparse

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
    p.add_argument("toolpath", metavar="TOOLPATH",
                   help="toolpath TOML file or built-in name (servosurf toolpaths)")
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
        choices=("tracking", "force", "vibration"),
        default=["tracking", "force", "vibration"],
        help="deviation parts to include (default: all)",
    )
    p.add_argument(
        "--instrument",
        metavar="NAME",
        default="cp300-20x",
        help="interferometer model applied to the machined map: cp300-20x (default, "
        "the paper's instrument), newview-20x/50x/100x, or none",
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
    p.add_argument("--force", action="store_true",
                   help="run even when the memory or disk estimate exceeds what this "
                   "machine has")
    p.add_argument("--json", action="store_true", help="print summary.json on stdout")
    return p


def _check_footprint(args, tp, out) -> None:
    """Estimate memory and disk before allocating; refuse above the machine's."""
    from .._resources import SIM_BYTES_PER_PIXEL, SIM_BYTES_PER_SAMPLE, check_resources
    from ..servo import load_machine
    from ..simulation import SETTLE_TIME, _span
    from ..toolpath import load_toolpath

    spec = load_toolpath(tp)
    fs = load_machine(args.machine).controller.sample_rate
    t0, t1 = _span(spec, spec.tool)
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


def _write_map(surface, path, fmt):
    """Write the height map with the io writers (atomic), settings as metadata."""
    from ..io import write_surface

    write_surface(surface, path, format=fmt)
    return path


def run(args) -> int:
    from pathlib import Path

    from .._builtins import resolve_file
    from .._progress import stage
    from ..errors import ConfigError
    from ..report._simulation import analyse
    from ..simulation import simulate
    from ..viz import _surface_plots as sp
    from ._common import check_flags, output_folder, print_json, write_json

    check_flags(args)  # --bandwidth, --mass: positive and plausible
    if args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    tp = resolve_file(args.toolpath, kind="toolpath")  # a path or a built-in name
    if args.realisations < 1:
        raise ConfigError(f"--realisations must be >= 1, got {args.realisations}")
    fmt = args.format or "datx"
    _check_footprint(args, tp, args.out or Path("results") / tp.stem)
    out = output_folder(args.out or Path("results") / tp.stem)  # swapped in at the end
    settings = {  # the paper's cutting set-up unless given
        "machine": args.machine,
        "workpiece": args.workpiece,
        "bandwidth": 1448.0 if args.bandwidth is None else args.bandwidth,
        "mass": 0.175 if args.mass is None else args.mass,
        "parts": tuple(args.parts),
        "instrument": None if args.instrument == "none" else args.instrument,
    }
    if args.realisations > 1:
        return _run_realisations(args, tp, out, settings)
    res = simulate(tp, seed=args.seed, **settings)
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
        files["highpass_png"] = str(_highpass_figure(plots, out / "highpass.png"))
        files["spectrum_png"] = str(
            _spectrum_figure(res, summary, plots, out / "spectrum.png"))
        if "profile" in plots:
            files["profile_png"] = str(
                _profile_figure(res, plots, out / "profile.png"))
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


def _highpass_figure(plots, path):
    """The 80 mm^-1 high-pass map, its filter-end rim masked, colours by percentile.

    The Gaussian filter has no data beyond the map's edge (the lenslet's rim or the
    field's border): within half a cut-off of it the high-pass holds the filter's
    end effect, tens of times the texture, so that band is masked and the colour
    scale spans the 0.5-99.5 percentiles of the rest.
    """
    import numpy as np
    from scipy import ndimage

    from ..report._simulation import HIGH_PASS_CUTOFF
    from ..viz import _surface_plots as sp

    hp = plots["highpass"]
    valid = np.pad(np.isfinite(hp.z), 1, constant_values=False)
    dist = ndimage.distance_transform_edt(valid, sampling=(hp.dy, hp.dx))[1:-1, 1:-1]
    rim = 0.5 * HIGH_PASS_CUTOFF
    shown = hp.replace(z=np.where(dist > rim, hp.z, np.nan))
    what = " of the form error" if "profile" in plots else ""
    return sp.plot_map(
        shown, path, robust=0.5,
        title=f"{1e-3 / HIGH_PASS_CUTOFF:g} mm^-1 high-pass{what}\n"
        f"(a {rim * 1e6:.3g} um rim masked: filter end effect)")


def _spectrum_figure(res, summary, plots, path):
    """The PSD along the cut with every detected peak labelled (in mm^-1 and kHz).

    ``summary.json`` lists the peaks above the high-pass cut-off; peaks below it
    (attenuated by the filter, e.g. a tool mode on a slow facing cut) are found
    the same way and drawn in grey in the shaded band.
    """
    import math

    from ..metrology import find_peaks_spectrum
    from ..report._simulation import PEAK_FMIN
    from ..viz import _surface_plots as sp

    freq, psd, peaks = plots["spectrum"]
    speed = summary.get("surface_speed_m_per_s")
    if speed is None and hasattr(res.spec.path, "angular_speed"):
        f = res.spec.field
        speed = res.spec.path.angular_speed * math.hypot(f.center_x, f.center_y)
    low = [q for q in find_peaks_spectrum(freq, psd, n=5, fmax=PEAK_FMIN)
           if q["freq_per_m"] < PEAK_FMIN]
    return sp.plot_spectrum(
        freq, psd, [*peaks, *low], path, speed=speed or None, fmin=PEAK_FMIN,
        title="PSD along the cutting direction (y), peaks labelled")


def _profile_figure(res, plots, path):
    """The lenslet's centre profile along the cut (y) with the form error."""
    from ..viz import _surface_plots as sp

    y, z, fe = plots["profile"]
    which = "simulated, as measured" if res.measured is not None else "simulated"
    return sp.plot_profile_with_form_error(
        y, z, fe["reference"], fe["error"], path,
        xlabel="y, along the cut through the lenslet centre (\u00b5m)",
        label=which, nominal_label="nominal at the air-cut amplitude",
        title="Lenslet profile along the cutting direction and its form error")


def _print_result(args, tp, res, summary, out) -> None:
    """The numbers a user came for, with units, and where they were written."""
    from ._common import fmt_length, print_summary

    s, f = summary, res.spec.field
    rows = []
    if s.get("form_error_max_m") is not None:
        lag = s.get("form_error_lag_m")
        rows.append(("max form error", fmt_length(s["form_error_max_m"])
                     + (f" ({fmt_length(lag, 'um')} after the deepest point)"
                        if lag is not None else "")))
    if s.get("form_error_rms_m") is not None:
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


def _run_realisations(args, tp, out, settings) -> int:
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
            tp,
            seeds=seeds,
            client=client,
            progress=lambda it, total=None: bar(it, total=total, desc="realisations"),
            **settings,
        )
    summary = study.to_dict()
    summary.update(toolpath=str(tp), scheduler=args.scheduler,
                   bandwidth_hz=settings["bandwidth"],
                   moving_mass_kg=settings["mass"],
                   parts=list(args.parts), instrument=args.instrument)
    with stage("writing realisations.json and realisations.png"):
        png = _plot_realisations(study, out / "realisations.png")
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


def _plot_realisations(study, path):
    """Per-seed metrics as strip plots with their mean and 5-95 % band."""
    import numpy as np

    from ..viz._common import figure, save

    shown = [
        ("form_error_max_m", "max form error [nm]", 1e9),
        ("ra_m", "Ra [nm]", 1e9),
        ("sa_m", "Sa [nm]", 1e9),
        ("peak1_per_m", "strongest spectral line (matched\nby frequency) [1/mm]", 1e-3),
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
