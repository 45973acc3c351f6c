"""``servosurf profile``: Ra, Rq, Rz of a profile (ISO 16610-21 Gaussian filter)."""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    """Register ``servosurf profile`` and its flags on ``sub``."""
    p = sub.add_parser(
        "profile",
        help="Ra, Rq, Rz of a profile file (ISO 16610-21 Gaussian filter)",
        description="Read a profile (Mx profile .csv, or a one-row surface file) and "
        "report the ISO 4287 roughness parameters Ra, Rq, Rz of the roughness profile "
        "(profile minus its ISO 16610-21 Gaussian mean line). The cut-off is chosen by "
        "the ISO 4288 procedure unless --cutoff is given. By default one cut-off "
        "length is trimmed at each end (where the Gaussian kernel, truncated at "
        "+-cutoff, does not fit). Text output in nm; --json in m.",
    )
    p.add_argument("file", metavar="FILE", help="profile file")
    p.add_argument(
        "--cutoff",
        metavar="M",
        type=float,
        help="cut-off wavelength lambda_c in m (e.g. 8e-5 for 80 um); "
        "default: ISO 4288 choice (0.08, 0.25, 0.8, 2.5 or 8 mm)",
    )
    p.add_argument(
        "--keep-ends",
        action="store_true",
        help="evaluate the whole profile (end-corrected filter) instead of "
        "trimming one cut-off length at each end",
    )
    p.add_argument(
        "--x-range",
        metavar=("MIN", "MAX"),
        type=float,
        nargs=2,
        help="evaluate only MIN <= x <= MAX, in m in the file's own coordinates "
        "(e.g. -0.00099 0.00099 for the cut zone of a stylus contour that also "
        "holds the part's flanks; a negative MIN in plain decimals)",
    )
    p.add_argument(
        "--format",
        metavar="FMT",
        help="format name or suffix (default: detect from content and suffix)",
    )
    p.add_argument("--json", action="store_true", help="JSON output on stdout (m)")
    return p


def run(args) -> int:
    """Print the roughness of the profile file; return the exit status."""
    from .._validation import check_positive
    from ..io import read_profile
    from ..metrology import profile_roughness
    from ._common import print_json

    cutoff = (
        None if args.cutoff is None else check_positive(args.cutoff, name="--cutoff")
    )
    prof = read_profile(args.file, format=args.format)
    if args.x_range is not None:
        from ..metrology import crop_profile

        prof = crop_profile(prof, *args.x_range)
    res = profile_roughness(prof, cutoff=cutoff, trim_ends=not args.keep_ends)
    out = {
        "file": args.file,
        "points": int(prof.z.size),
        "dx_m": prof.dx,
        "length_m": prof.z.size * prof.dx,
        "x_range_m": None if args.x_range is None else list(args.x_range),
        **res,
    }
    if args.json:
        print_json(out)
        return 0
    nm, um = 1e9, 1e6
    ends = (
        f"ends trimmed by {res['trim_length_m'] * um:g} um each"
        if res["ends_trimmed"]
        else "ends kept"
    )
    print(
        f"{args.file}: {out['points']} points, step {prof.dx * um:.6g} um, "
        f"length {out['length_m'] * um:.6g} um"
    )
    print(
        f"  cut-off        {res['cutoff_m'] * um:g} um ({res['cutoff_rule']}), {ends}"
    )
    print(f"  evaluation     {res['evaluation_length_m'] * um:.6g} um")
    print(f"  Ra             {res['ra_m'] * nm:.3f} nm")
    print(f"  Rq             {res['rq_m'] * nm:.3f} nm")
    print(
        f"  Rz             {res['rz_m'] * nm:.3f} nm "
        f"(mean of {res['rz_sampling_lengths']} sampling length(s))"
    )
    return 0
