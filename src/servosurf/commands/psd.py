"""``servosurf psd``: estimate a disturbance PSD from recorded time series (Welch)."""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "psd",
        help="estimate a PSD from recorded time series (Welch), write frequency_hz,psd",
        description="Estimate a one-sided PSD by Welch averaging, as the paper did "
        "(records of 4096 samples at 199.6 kHz, 32 repeats), from a CSV 'time_s,value' "
        "(one long record cut into segments) or an NPZ with 'records' "
        "(records x samples) and 'fs_hz'. Values in SI (m for sensor noise and base "
        "vibration, A for current noise); the PSD is in unit^2/Hz. The CSV it writes "
        "is what a machine file's [disturbances.*] csv = ... expects.",
    )
    p.add_argument("record", metavar="FILE",
                   help="CSV time_s,value or NPZ records/fs_hz")
    p.add_argument("--nperseg", type=int, default=4096,
                   help="samples per Welch segment (default 4096)")
    p.add_argument("--out", metavar="PSD.csv", required=True, help="output CSV")
    p.add_argument("--json", action="store_true", help="print a summary (RMS in SI)")
    return p


def _read_records(path):
    import numpy as np

    from ..errors import ConfigError

    path = str(path)
    if path.endswith(".npz"):
        try:
            with np.load(path) as d:
                if "records" not in d or "fs_hz" not in d:
                    raise ConfigError(f"{path}: NPZ needs arrays 'records' and 'fs_hz'")
                return np.asarray(d["records"], float), float(d["fs_hz"])
        except (OSError, ValueError) as exc:
            raise ConfigError(f"{path}: cannot read NPZ: {exc}") from None
    try:
        with open(path) as fh:
            header = fh.readline().strip().lower().split(",")
            if header[:2] != ["time_s", "value"]:
                raise ConfigError(f"{path}: expected a header 'time_s,value'")
            data = np.loadtxt(fh, delimiter=",", ndmin=2)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: cannot read CSV: {exc}") from None
    t = data[:, 0]
    if t.size < 3 or not np.all(np.diff(t) > 0):
        raise ConfigError(f"{path}: time_s must increase and hold at least 3 samples")
    dt = np.diff(t)
    if np.ptp(dt) > 1e-6 * dt.mean():
        raise ConfigError(f"{path}: time_s must be evenly sampled")
    return data[:, 1], 1.0 / dt.mean()


def run(args) -> int:
    import numpy as np

    from ..noise import cas, welch_psd, write_psd_csv
    from ._common import print_json

    x, fs = _read_records(args.record)
    f, p = welch_psd(x, fs, nperseg=args.nperseg)
    write_psd_csv(args.out, f, p)
    summary = {"fs_hz": fs, "bins": int(f.size), "df_hz": float(f[1] - f[0]),
               "rms_from_psd": float(cas(f, p)[-1]),
               "rms_of_record": float(np.std(x)), "out": str(args.out)}
    if args.json:
        print_json(summary)
    from ._common import print_summary

    print_summary(args, f"psd {args.record}: Welch, {args.nperseg} samples per "
                  f"segment at {fs:g} Hz", [
                      ("bins", f"{f.size} from 0 to {f[-1]:g} Hz, df {f[1] - f[0]:.4g} "
                       "Hz"),
                      ("RMS", f"{summary['rms_from_psd']:.4g} from the PSD, "
                       f"{summary['rms_of_record']:.4g} of the record (record unit: m "
                       "or A)"),
                  ], wrote=args.out)
    return 0
