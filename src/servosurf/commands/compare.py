"""``servosurf compare``: a measured map against a simulated one."""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "compare",
        help="compare a measured map with a simulation (registration, residual)",
        description="Bring a measured and a simulated map onto one grid (the coarser "
        "pitch), register them with sub-pixel accuracy (lenslet by lenslet when the "
        "map holds a lenslet array), remove piston/tilt/sphere and report the "
        "residual, profile and spectra overlays and metrics (RMS and PV residual in "
        "m, fit %, correlation).",
    )
    p.add_argument(
        "measured", metavar="MEASURED", help="measured map (any readable format)"
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--simulated", metavar="FILE", help="simulated map file")
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
        "--no-register", action="store_true", help="do not register the maps"
    )
    p.add_argument(
        "--out", metavar="DIR", default="results/compare",
        help="output folder (default results/compare), replaced whole on success"
    )
    p.add_argument("--json", action="store_true", help="print the JSON summary")
    return p


def run(args) -> int:
    import numpy as np

    from .._progress import stage
    from ..io import read_surface
    from ..report._compare import compare_surfaces
    from ..viz._common import figure, save
    from ..viz._surface_plots import plot_map
    from ._common import check_flags, output_folder, print_json, write_json

    check_flags(args)  # --bandwidth, --mass: positive and plausible
    with stage("reading maps"):
        measured = read_surface(args.measured)
        if args.simulated:
            simulated = read_surface(args.simulated)
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
