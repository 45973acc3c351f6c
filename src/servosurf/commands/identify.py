"""``servosurf identify``: grey-box fit of machine parameters to a measured FRF."""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "identify",
        help="fit machine parameters to a measured open-loop FRF",
        description="Grey-box identification (paper section 3.1): fit masses, "
        "stiffnesses and dampings to an open-loop FRF (DAC volts -> sensor volts) in "
        "a CSV 'frequency_hz,real,imag'. Reports MATLAB's fit percent and writes "
        "fitted-machine.toml.",
    )
    p.add_argument("frf", metavar="FRF.csv", help="measured FRF (Hz, V/V)")
    p.add_argument(
        "--machine", metavar="FILE", help="starting machine (default seed-prototype)"
    )
    p.add_argument(
        "--param",
        metavar="KEY",
        action="append",
        help="dotted parameter to fit, SI (repeatable; default m1 m2 k1 c1 k2 c2)",
    )
    p.add_argument(
        "--analogue",
        action="store_true",
        help="the sweep bypassed the DSP (no ZOH and delay in the model)",
    )
    p.add_argument(
        "--out", metavar="DIR", default="results/identify", help="output directory"
    )
    p.add_argument("--json", action="store_true", help="print the JSON summary")
    return p


def run(args) -> int:

    from .._progress import stage
    from ..io import read_frf_csv
    from ..servo import (
        DEFAULT_IDENT_PARAMS,
        identify,
        load_machine,
        open_loop_frf,
    )
    from ..viz import plot_frf_fit
    from ._common import atomic_write, output_folder, print_json, write_json

    machine = load_machine(args.machine)
    f, y = read_frf_csv(args.frf)
    params = tuple(args.param) if args.param else DEFAULT_IDENT_PARAMS
    with stage("grey-box fit"):
        res = identify(machine, f, y, params=params, digital=not args.analogue)
    out = output_folder(args.out)  # swapped in place of --out at the end
    text = res.machine.to_toml(
        header=f"fitted by servosurf identify to {args.frf}\n"
        f"fit {res.fit_percent_after:.2f} % (before "
        f"{res.fit_percent_before:.2f} %)"
    )
    atomic_write(out / "fitted-machine.toml", lambda p: p.write_text(text))
    digital = not args.analogue
    plot_frf_fit(f, y, open_loop_frf(machine, f, digital=digital),
                 open_loop_frf(res.machine, f, digital=digital), out / "identify.png",
                 title=f"fit {res.fit_percent_before:.1f} % -> "
                 f"{res.fit_percent_after:.1f} %")
    summary = {
        "parameters": res.parameters,
        "initial": res.initial,
        "fit_percent_before": res.fit_percent_before,
        "fit_percent_after": res.fit_percent_after,
        "fitted_machine": str(out / "fitted-machine.toml"),
    }
    write_json(out / "summary.json", summary)
    if args.json:
        print_json(summary)
    _print_result(args, res, out)
    return 0


def _print_result(args, res, out) -> None:
    """Fit before and after, and each fitted parameter against its start."""
    from ..servo import describe_machine
    from ._common import print_summary

    units = {r["key"]: r["unit"] for r in describe_machine()}
    rows = [("fit", f"{res.fit_percent_before:.2f} % -> {res.fit_percent_after:.2f} "
             "% (MATLAB's normalised fit)")]
    for key, value in res.parameters.items():
        start = res.initial.get(key)
        unit = units.get(key, "")
        was = f" (start {start:.4g})" if isinstance(start, float | int) else ""
        rows.append((key, f"{value:.4g} {unit}{was}".replace("  ", " ")))
    print_summary(args, f"identify {args.frf}: grey-box fit", rows, wrote=out)
