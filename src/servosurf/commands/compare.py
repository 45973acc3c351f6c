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
        "--toolpath", metavar="T.toml", help="simulate this toolpath first"
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
        "--out", metavar="DIR", default="results/compare", help="output directory"
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
    from ._common import out_dir, print_json, write_json

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
    d = out_dir(args.out)
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
    return 0
