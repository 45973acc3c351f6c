"""``servosurf noise``: the positioning-error study (paper sections 3.3 and 5.2)."""

from __future__ import annotations

import argparse

from ._common import add_scheduler_args


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "noise",
        help="positioning-error study: FRFs, CAS, RMS vs bandwidth, spectra",
        description="Synthesise real and following positioning errors from the "
        "disturbance PSDs (seed paper Eqs 8-12) for one or more moving masses; write "
        "PNG figures and a JSON summary. Bandwidths are open-loop crossover "
        "frequencies.",
    )
    p.add_argument(
        "--machine",
        metavar="FILE",
        help="machine TOML or built-in name (default: seed-prototype)",
    )
    p.add_argument(
        "--mass",
        metavar="KG",
        type=float,
        action="append",
        help="moving mass m1+m2 in kg (repeatable; default 0.075 and 0.175)",
    )
    p.add_argument(
        "--bandwidth",
        metavar="HZ",
        type=float,
        help="crossover bandwidth in Hz for FRFs, CAS and spectra "
        "(default: the machine's)",
    )
    p.add_argument(
        "--bandwidths",
        metavar="HZ",
        type=float,
        nargs="+",
        help="bandwidth grid in Hz for the RMS-vs-bandwidth study "
        "(default 200..1800 Hz)",
    )
    p.add_argument(
        "--disturbances",
        metavar="NAME",
        help="disturbance calibration name (see `servosurf machines`)",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        default="results/noise",
        help="output directory (default results/noise)",
    )
    add_scheduler_args(p, "the design study (one task per mass)")
    p.add_argument(
        "--json", action="store_true", help="print the JSON summary on stdout"
    )
    return p


def run(args) -> int:
    import numpy as np

    from .._progress import bar, stage
    from ..errors import ConfigError
    from ..noise import design_study, frequency_grid, synthesize
    from ..servo import ServoLoop, load_machine
    from ..viz import _servo_plots as vz
    from ._common import (
        check_flags,
        dask_client,
        output_folder,
        print_json,
        write_json,
    )

    machine = load_machine(args.machine)
    if args.disturbances:
        machine = machine.with_disturbances(args.disturbances)
    check_flags(args)  # --mass, --bandwidth(s): positive and plausible
    masses = args.mass or [0.075, 0.175]
    bw = args.bandwidth if args.bandwidth is not None else machine.controller.bandwidth
    if not (bw > 0 and np.isfinite(bw)):
        raise ConfigError(f"--bandwidth must be a positive frequency in Hz, got {bw!r}")
    grid = np.array(args.bandwidths if args.bandwidths else np.geomspace(200, 1800, 17))
    if np.any(~np.isfinite(grid)) or np.any(grid <= 0):
        raise ConfigError("--bandwidths must be positive frequencies in Hz")
    out = output_folder(args.out)  # swapped in place of --out at the end
    fs = machine.controller.sample_rate
    freq = frequency_grid(fs)
    summary: dict = {
        "machine": machine.name,
        "disturbances": machine.disturbances.name,
        "bandwidth_hz": bw,
        "bandwidth_definition": "open-loop crossover",
        "masses": [],
    }
    frfs, budgets = {}, {}
    with stage(f"closed loops at {bw:g} Hz"):
        for m in masses:
            mm = machine.with_moving_mass(m).with_bandwidth(bw)
            loop = ServoLoop(mm)
            stable = loop.is_stable()
            label = f"{m:g} kg"
            entry = {
                "mass_kg": m,
                "stable": stable,
                "margins": loop.margins(),
                "pidf": {
                    "kp": loop.pidf.kp,
                    "ki_per_s": loop.pidf.ki,
                    "kd_s": loop.pidf.kd,
                    "tf_s": loop.pidf.tf,
                },
            }
            if stable:
                frfs[label] = loop.frf(freq)
                b = synthesize(loop, freq=freq)
                budgets[label] = b
                entry.update(
                    rms_real_m=b.rms_real(),
                    rms_following_m=b.rms_following(),
                    power_shares=b.power_shares(),
                    real_peaks_hz=b.peaks(),
                )
            summary["masses"].append(entry)
    with dask_client(args.scheduler, args.workers) as client, \
            stage("RMS against bandwidth (design study)"):
        study = design_study(
            machine,
            masses,
            grid,
            progress=lambda it, total=None: bar(it, total=total, desc="masses"),
            client=client,
        )
    if args.scheduler:
        summary["scheduler"] = args.scheduler
    summary["study"] = study.to_dict()
    shares_bw = {"sensor_noise": [], "current_noise": [], "base_vibration": []}
    with stage("power shares against bandwidth"):
        heavy = machine.with_moving_mass(masses[-1])
        for b in grid:
            try:
                loop = ServoLoop(heavy.with_bandwidth(float(b)))
                ok = loop.is_stable()
            except Exception:
                ok = False
            sh = synthesize(loop, freq=freq).power_shares() if ok else None
            for k in shares_bw:
                shares_bw[k].append(sh[k] if sh else float("nan"))
    summary["power_shares_vs_bandwidth"] = {
        "mass_kg": masses[-1],
        "bandwidths_hz": grid,
        **shares_bw,
    }
    with stage("figures"):
        figs = {}
        if frfs:
            margins = {f"{e['mass_kg']:g} kg": e["margins"]
                       for e in summary["masses"]}
            figs["loop_bode"] = vz.plot_loop_bode(frfs, out / "loop_bode.png",
                                                  margins)
            figs["tool_frfs"] = vz.plot_tool_frfs(frfs, out / "tool_frfs.png")
            figs["disturbance_frfs"] = vz.plot_disturbance_frfs(
                frfs, out / "disturbance_frfs.png"
            )
            figs["cas"] = vz.plot_cas(budgets, out / "cas.png")
            figs["error_spectra"] = vz.plot_error_spectra(
                budgets, out / "error_spectra.png"
            )
        figs["rms_vs_bandwidth"] = vz.plot_rms_vs_bandwidth(
            study, out / "rms_vs_bandwidth.png"
        )
        figs["power_shares"] = vz.plot_power_shares(
            grid,
            shares_bw,
            out / "power_shares.png",
            title=f"Real-error power share per source, {masses[-1]:g} kg (cf. Fig. 15)",
        )
        summary["figures"] = {k: str(v) for k, v in figs.items()}
    write_json(out / "summary.json", summary)
    if args.json:
        print_json(summary)
    _print_result(args, summary, study, bw, out)
    return 0


def _print_result(args, summary, study, bw, out) -> None:
    """Per mass: stability, margins and RMS errors at the bandwidth, the optimum."""
    import math

    from ._common import print_summary

    rows = []
    for i, e in enumerate(summary["masses"]):
        m = e["mass_kg"]
        if not e["stable"]:
            rows.append((f"{m:g} kg", f"unstable at {bw:g} Hz"))
            continue
        g = e["margins"]
        rows.append((f"{m:g} kg at {bw:g} Hz",
                     f"real {e['rms_real_m'] * 1e9:.3g} nm RMS, following "
                     f"{e['rms_following_m'] * 1e9:.3g} nm RMS; phase margin "
                     f"{g['phase_margin_deg']:.1f} deg, gain margin "
                     f"{g['gain_margin_db']:.1f} dB"))
        opt = float(study.optimal_bandwidth[i])
        if math.isfinite(opt):
            rows.append((f"{m:g} kg optimum",
                         f"{opt:.0f} Hz: real {study.optimal_rms[i] * 1e9:.3g} nm "
                         f"RMS (stable up to {study.stability_limit[i]:.0f} Hz)"))
    print_summary(args, f"noise: {summary['machine']}, disturbances "
                  f"{summary['disturbances']}, bandwidths are open-loop crossovers",
                  rows, wrote=out)
