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
    from .._progress import bar, stage
    from ..noise import noise_study
    from ..run import preset
    from ..servo import load_machine
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
    # default: the paper's two masses (bare carrier, and with the added mass)
    masses = args.mass or [preset("paper-optimum-light").mass,
                           preset("paper-cutting").mass]
    out = output_folder(args.out)  # swapped in place of --out at the end
    with dask_client(args.scheduler, args.workers) as client:
        result = noise_study(
            machine, masses, args.bandwidth, args.bandwidths, client=client,
            progress=lambda it, total=None: bar(it, total=total, desc="masses"))
    summary = result.to_dict()
    if args.scheduler:
        summary["scheduler"] = args.scheduler
    with stage("figures"):
        summary["figures"] = result.plot(out)
    write_json(out / "summary.json", summary)
    if args.json:
        print_json(summary)
    _print_result(args, summary, result.study, summary["bandwidth_hz"], out)
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
