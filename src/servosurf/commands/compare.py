"""``servosurf compare``: a measured map or profile against a simulated one.

Two maps are compared as maps (registration, residual, spectra). When either side
is a profile (a profile file, or a one-row or one-column map), or with
``--profile``, both become profiles (a map gives its line along ``--line``
through ``--at``) and are compared as profiles: 1-D registration, Ra/Rq/Rz/RSm
side by side with the same cut-off and end trimming
(:func:`servosurf.report.compare_profiles`).
"""

from __future__ import annotations

import argparse

#: Below this correlation after registration the text output adds a hint.
LOW_CORRELATION = 0.5


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "compare",
        help="compare a measured map with a simulation (registration, residual)",
        description="Maps: bring a measured and a simulated map onto one grid (the "
        "coarser pitch), register them with sub-pixel accuracy (lenslet by lenslet "
        "when the map holds a lenslet array), remove piston/tilt/sphere and report "
        "the residual, profile and spectra overlays and metrics (RMS and PV "
        "residual in m, fit %, correlation). Profiles (either file a profile, a "
        "one-row map, or --profile): take the line through a map (--line, --at), "
        "crop the measured profile (--x-range), register the simulated profile "
        "along it (shift, and a mirror x -> -x if it correlates better), mask "
        "invalid ends, and report Ra, Rq, Rz, RSm of both with the same ISO 4288 "
        "cut-off, form removal and end trimming, the correlation after "
        "registration, and overlay, roughness-table and spectrum figures; a "
        "profile through the centre of a turned part against the band of an NC "
        "run is registered half by half either side of the spindle axis. Text "
        "output in nm/um, --json in SI units (m).",
    )
    p.add_argument(
        "measured",
        metavar="MEASURED",
        help="measured map or profile (any readable format: Mx profile .csv, "
        "Formtracer .dat, x3p, ...)",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--simulated", metavar="FILE", help="simulated map or profile file"
    )
    src.add_argument(
        "--toolpath", metavar="T", help="simulate this toolpath first (TOML file or "
        "built-in name)"
    )
    p.add_argument("--machine", metavar="M.toml", help="machine for --toolpath")
    p.add_argument("--workpiece", metavar="W.toml", help="workpiece for --toolpath")
    p.add_argument(
        "--bandwidth",
        metavar="HZ",
        type=float,
        default=1448.0,
        help="crossover bandwidth in Hz for --toolpath (default 1448)",
    )
    p.add_argument(
        "--mass",
        metavar="KG",
        type=float,
        default=0.175,
        help="moving mass in kg for --toolpath (default 0.175)",
    )
    p.add_argument(
        "--seed", metavar="N", type=int, default=0, help="seed for --toolpath"
    )
    p.add_argument(
        "--remove",
        metavar="TERM",
        nargs="*",
        default=["piston", "tilt"],
        choices=("piston", "tilt", "sphere"),
        help="form terms removed from the residual (default piston tilt)",
    )
    p.add_argument(
        "--axis",
        choices=("x", "y"),
        default="y",
        help="cutting direction for the spectra: y (along columns, the "
        "simulated-lenslet convention) or x (default y)",
    )
    p.add_argument(
        "--no-register",
        action="store_true",
        help="do not register the maps or profiles",
    )
    prof = p.add_argument_group("profile comparison")
    prof.add_argument(
        "--profile",
        action="store_true",
        help="compare profiles even when both files are maps (their lines along "
        "--line through --at)",
    )
    prof.add_argument(
        "--line",
        choices=("x", "y"),
        default="x",
        help="direction of the line taken through a map: x (a row) or y (a "
        "column) (default x)",
    )
    prof.add_argument(
        "--at",
        metavar="M",
        type=float,
        help="position of that line across it in m (y of the row for --line x); "
        "default: the map's centre line",
    )
    prof.add_argument(
        "--x-range",
        metavar=("MIN", "MAX"),
        type=float,
        nargs=2,
        help="crop the measured profile to MIN <= x <= MAX, in m in the file's own "
        "coordinates, e.g. -0.00099 0.00099 for the cut zone of a stylus contour "
        "that also holds the part's flanks (write a negative MIN in plain decimals: "
        "argparse takes -9.9e-4 for an option)",
    )
    prof.add_argument(
        "--cutoff",
        metavar="M",
        type=float,
        help="cut-off wavelength lambda_c in m for both profiles (e.g. 2.5e-4); "
        "default: the ISO 4288 choice on the measured profile",
    )
    prof.add_argument(
        "--keep-ends",
        action="store_true",
        help="evaluate the whole common span instead of trimming one cut-off "
        "length at each end of both profiles",
    )
    prof.add_argument(
        "--mirror",
        choices=("auto", "yes", "no"),
        default="auto",
        help="mirror the simulated profile x -> -x before registering: auto (when "
        "it correlates better), yes or no (default auto)",
    )
    prof.add_argument(
        "--split",
        choices=("auto", "yes", "no"),
        default="auto",
        help="register the halves of the measured profile on either side of the "
        "spindle axis separately (a spiral's grooves shift in opposite directions "
        "on the two sides of a profile through the centre): auto (when the "
        "simulated map is a servosurf simulation whose line crosses the axis, "
        "e.g. the band of an NC run), yes or no (default auto)",
    )
    prof.add_argument(
        "--max-shift",
        metavar="M",
        type=float,
        help="largest registration shift from centre-on-centre, in m (default: any "
        "shift leaving 90 %% overlap)",
    )
    prof.add_argument(
        "--form",
        choices=("none", "line", "quadratic"),
        default="quadratic",
        help="least-squares polynomial removed from both profiles before the "
        "Gaussian filter (default quadratic: a part's sag)",
    )
    prof.add_argument(
        "--labels",
        metavar=("MEASURED", "SIMULATED"),
        nargs=2,
        default=("measured", "simulated"),
        help="names of the two sides in the figures (e.g. 'WLI' 'Formtracer' when "
        "both are measurements)",
    )
    p.add_argument(
        "--out", metavar="DIR", default="results/compare",
        help="output folder (default results/compare), replaced whole on success"
    )
    p.add_argument("--json", action="store_true", help="print the JSON summary")
    return p


def run(args) -> int:
    from .._progress import stage
    from ..io import read_any
    from ..report._profile_compare import as_profile_or_none
    from ._common import check_flags

    check_flags(args)  # --bandwidth, --mass: positive and plausible
    with stage("reading"):
        measured, _ = read_any(args.measured)
        if args.simulated:
            simulated, _ = read_any(args.simulated)
        else:
            from ..simulation import simulate

            res = simulate(
                args.toolpath,
                machine=args.machine,
                workpiece=args.workpiece,
                bandwidth=args.bandwidth,
                mass=args.mass,
                seed=args.seed,
            )
            simulated = res.measured if res.measured is not None else res.surface
    profiles = (
        args.profile
        or as_profile_or_none(measured) is not None
        or as_profile_or_none(simulated) is not None
    )
    if profiles:
        return _run_profiles(args, measured, simulated)
    _reject_profile_flags(args)
    return _run_maps(args, measured, simulated)


def _reject_profile_flags(args) -> None:
    """Profile-only flags given for two maps: a one-line error naming them."""
    from ..errors import ConfigError

    given = [
        flag
        for flag, value in (
            ("--x-range", args.x_range),
            ("--cutoff", args.cutoff),
            ("--at", args.at),
            ("--max-shift", args.max_shift),
            ("--split", None if args.split == "auto" else args.split),
        )
        if value is not None
    ]
    if given:
        raise ConfigError(
            f"{', '.join(given)} apply to profiles, but both inputs are maps; add "
            "--profile to compare their lines"
        )


def _run_profiles(args, measured, simulated) -> int:
    """Profile comparison: registration, roughness side by side, figures, JSON."""
    from .._progress import stage
    from .._validation import check_positive
    from ..report._profile_compare import compare_profiles
    from ._common import output_folder, print_json, write_json

    cutoff = None if args.cutoff is None else check_positive(
        args.cutoff, name="--cutoff")
    max_shift = None if args.max_shift is None else check_positive(
        args.max_shift, name="--max-shift")
    with stage("profile registration and roughness"):
        res = compare_profiles(
            measured,
            simulated,
            line_axis=args.line,
            line_at=args.at,
            x_range=None if args.x_range is None else tuple(args.x_range),
            cutoff=cutoff,
            trim_ends=not args.keep_ends,
            register=not args.no_register,
            mirror={"auto": "auto", "yes": True, "no": False}[args.mirror],
            max_shift=max_shift,
            form=args.form,
            labels=tuple(args.labels),
            split={"auto": "auto", "yes": True, "no": False}[args.split],
        )
    d = output_folder(args.out)  # swapped in place of --out at the end
    with stage("figures"):
        files = res.plot(d)
    out = res.to_dict()
    out["measured_file"] = str(args.measured)
    out["simulated_file"] = str(args.simulated or args.toolpath)
    out["files"] = {k: str(v) for k, v in files.items()}
    out["files"]["json"] = str(d / "compare.json")
    write_json(d / "compare.json", out)
    if args.json:
        print_json(out)
    elif not args.quiet:
        _print_profiles(out)
    return 0


def _print_profiles(out: dict) -> None:
    """The profile comparison on stdout, heights in nm and lengths in um."""
    um, nm = 1e6, 1e9
    lm, ls = out["labels"]
    print(f"compare profiles: {out['measured_file']} ({lm}) vs "
          f"{out['simulated_file']} ({ls})")
    if out["registered"]:
        how = "mirrored (x -> -x), " if out["mirrored"] else "not mirrored, "
        print(f"  registration   {how}shift {out['shift_m'] * um:.2f} um "
              f"(x_{lm} = {'-' if out['mirrored'] else ''}x_{ls} + shift)")
    else:
        print("  registration   none (positions taken as they are)")
    if out.get("split_at_axis"):
        sb, sa = (out["half_shifts_m"][k] * um for k in ("below", "above"))
        cb, ca = (out["half_correlations"][k] for k in ("below", "above"))
        fc = " / ".join("n/a" if c is None else f"{c:.3f}" for c in (cb, ca))
        print(f"  split at axis  axis at {out['axis_position_m'] * um:.2f} um of the "
              f"{lm} profile; half shifts {sb:.2f} / {sa:.2f} um, correlations "
              f"{fc} (below / above the axis)")
    elif out.get("split_skipped"):
        print(f"  split at axis  not split: {out['split_skipped']}")
    ends = (f"ends trimmed by {out['trim_length_m'] * um:g} um each"
            if out["ends_trimmed"] else "ends kept")
    print(f"  cut-off        {out['cutoff_m'] * um:g} um ({out['cutoff_rule']}), "
          f"{ends}, form removed: {out['form_removed']}")
    x0, x1 = out["measured_x_m"]
    print(f"  evaluation     {out['evaluation_length_m'] * um:.1f} um of the "
          f"common span {x0 * um:.1f} .. {x1 * um:.1f} um ({lm} x)")
    print(f"  {'':14} {lm:>12} {ls:>12}")
    for key, label, scale, unit in (
        ("ra_m", "Ra", nm, "nm"),
        ("rq_m", "Rq", nm, "nm"),
        ("rz_m", "Rz", nm, "nm"),
        ("rsm_m", "RSm", um, "um"),
    ):
        a, b = out[f"measured_{key}"], out[f"simulated_{key}"]
        fa = "n/a" if a is None else f"{a * scale:.2f}"
        fb = "n/a" if b is None else f"{b * scale:.2f}"
        print(f"  {label + ' [' + unit + ']':14} {fa:>12} {fb:>12}")
    corr = out["correlation"]
    print(f"  correlation    {'n/a' if corr is None else format(corr, '.3f')} "
          "(roughness profiles over the evaluation length)")
    if corr is not None and out["registered"] and corr < LOW_CORRELATION:
        print(f"  note           correlation below {LOW_CORRELATION:g}: check that "
              "both profiles hold the same cut zone (a stylus contour that also "
              "holds the part's flanks needs --x-range)")
    for name, path in out["files"].items():
        print(f"  {name:14} {path}")


def _run_maps(args, measured, simulated) -> int:
    """Map comparison (unchanged behaviour): registration, residual, spectra."""
    import numpy as np

    from .._progress import stage
    from ..report._compare import compare_surfaces
    from ..viz._common import figure, save
    from ..viz._surface_plots import plot_map
    from ._common import output_folder, print_json, write_json

    with stage("registration and residual"):
        out = compare_surfaces(
            measured,
            simulated,
            remove=tuple(args.remove),
            axis=0 if args.axis == "y" else 1,
            register=not args.no_register,
        )
    plots = out.pop("_plots")
    d = output_folder(args.out)  # swapped in place of --out at the end
    with stage("figures"):
        plot_map(
            plots["residual"],
            d / "residual.png",
            title=f"residual (measured - simulated), RMS "
            f"{out['rms_residual_m'] * 1e9:.2f} nm",
        )
        fm, pm, fs_, ps = plots["spectra"]
        fig, ax = figure(figsize=(8, 4.5))
        ax.semilogy(fm / 1e3, pm * 1e21, label="measured")
        ax.semilogy(fs_ / 1e3, ps * 1e21, label="simulated", alpha=0.8)
        for a, b in out["peaks_matched_per_m"]:
            ax.axvline(a / 1e3, color="k", ls=":", lw=0.8)
        ax.set_xlabel("spatial frequency [1/mm]")
        ax.set_ylabel("PSD [nm^2 mm]")
        ax.set_title("Spectra along the cutting direction (dotted: matched peaks)")
        ax.legend()
        save(fig, d / "spectra.png")
        m, s = plots["measured"], plots["simulated"]
        fig, ax = figure(figsize=(8, 4))
        if args.axis == "y":
            j = m.shape[1] // 2
            x = m.y0 + m.dy * np.arange(m.shape[0])
            ax.plot(x * 1e6, m.z[:, j] * 1e9, label="measured")
            ax.plot(x * 1e6, s.z[:, j] * 1e9, label="simulated")
        else:
            i = m.shape[0] // 2
            x = m.x0 + m.dx * np.arange(m.shape[1])
            ax.plot(x * 1e6, m.z[i] * 1e9, label="measured")
            ax.plot(x * 1e6, s.z[i] * 1e9, label="simulated")
        ax.set_xlabel(f"{args.axis} [um]")
        ax.set_ylabel("height [nm]")
        ax.set_title("Profile through the map centre along the cutting direction")
        ax.legend()
        save(fig, d / "profiles.png")
    out["files"] = {k: str(d / f"{k}.png") for k in ("residual", "spectra", "profiles")}
    write_json(d / "compare.json", out)
    if args.json:
        print_json(out)
    _print_result(args, out, d)
    return 0


def _print_result(args, out, d) -> None:
    """Residual, fit and correlation, the registration shift, matched peaks."""
    from ._common import fmt_length, print_summary

    rows = [
        ("RMS / PV residual", f"{fmt_length(out['rms_residual_m'])} / "
         f"{fmt_length(out['pv_residual_m'])} (after removing "
         f"{', '.join(args.remove) or 'nothing'})"),
        ("fit / correlation", f"{out['fit_percent']:.1f} % / "
         f"{out['correlation']:.3f}"),
    ]
    shift = out.get("shift_m")
    if shift:
        rows.append(("registration shift", f"{shift[0] * 1e6:.3g} um in y, "
                     f"{shift[1] * 1e6:.3g} um in x"))
    matched = out.get("peaks_matched_per_m") or []
    if matched:
        rows.append(("matched peaks", ", ".join(
            f"{a * 1e-3:.0f}/{b * 1e-3:.0f}" for a, b in matched)
            + " mm^-1 (measured/simulated)"))
    source = args.simulated or args.toolpath
    print_summary(args, f"compare {args.measured} with {source}", rows, wrote=d)
