"""``servosurf info``: format, size, pixel size, height statistics, metadata."""

from __future__ import annotations

import argparse
from typing import Any


def add_parser(sub) -> argparse.ArgumentParser:
    """Register ``servosurf info`` and its flags on ``sub``."""
    p = sub.add_parser(
        "info",
        help="describe a surface or profile file (size, pixel size, Sa, Sq)",
        description="Read a surface or profile file (MetroPro .dat/.asc, ZYGO .xyz, Mx "
        ".datx, .x3p, .npz, Mx profile .csv) and report its format, shape, pixel "
        "size, invalid fraction, height range, Sa and Sq over the valid pixels (about "
        "the mean, no levelling), Sq after a least-squares plane, the ISO 25178-2 "
        "areal parameters (Sp Sv Sz Ssk Sku Sdq Sdr Sal Str Sk Spk Svk Smr1 Smr2, "
        "mean removed, no levelling or filter) and its metadata. Text output "
        "uses um and nm; --json gives SI values (m; Sdr, Smr1, Smr2 in %).",
    )
    p.add_argument("file", metavar="FILE", help="file to describe")
    p.add_argument(
        "--format",
        metavar="FMT",
        help="format name or suffix (default: detect from content and suffix)",
    )
    p.add_argument(
        "--json", action="store_true", help="JSON output on stdout (SI units, m)"
    )
    return p


def describe(obj: Any, fmt: str) -> dict[str, Any]:
    """Summary of a Surface or Profile as a JSON-ready dict (lengths in m)."""
    import numpy as np

    from ..metrology import Profile, areal_parameters

    valid = np.isfinite(obj.z)
    v = obj.z[valid]
    out: dict[str, Any] = {"format": fmt}
    if isinstance(obj, Profile):
        c = v - v.mean()
        out.update(
            {
                "kind": "profile",
                "points": int(obj.z.size),
                "dx_m": obj.dx,
                "length_m": obj.z.size * obj.dx,
                "x0_m": obj.x0,
                "invalid_fraction": float(1.0 - valid.mean()),
                "z_min_m": float(v.min()),
                "z_max_m": float(v.max()),
                "pa_m": float(np.mean(np.abs(c))),
                "pq_m": float(np.sqrt(np.mean(c**2))),
            }
        )
    else:
        ny, nx = obj.shape
        out.update(
            {
                "kind": "surface",
                "rows": ny,
                "cols": nx,
                "dx_m": obj.dx,
                "dy_m": obj.dy,
                "x0_m": obj.x0,
                "y0_m": obj.y0,
                "invalid_fraction": obj.invalid_fraction,
                "z_min_m": float(v.min()),
                "z_max_m": float(v.max()),
                "sa_m": obj.sa(),
                "sq_m": obj.sq(),
                "sq_plane_m": obj.level().sq(),
                "areal": areal_parameters(obj),
            }
        )
    out["metadata"] = dict(obj.metadata)
    return out


def _text(info: dict[str, Any], path: str) -> str:
    um, nm = 1e6, 1e9
    lines = [f"{path}: {info['format']} ({info['kind']})"]
    if info["kind"] == "surface":
        px = (
            f"{info['dx_m'] * um:.6g} x {info['dy_m'] * um:.6g} um"
            if info["dx_m"] and info["dy_m"]
            else "uncalibrated"
        )
        lines.append(
            f"  size           {info['rows']} rows x {info['cols']} cols, pixel {px}"
        )
    else:
        lines.append(
            f"  size           {info['points']} points, step "
            f"{info['dx_m'] * um:.6g} um, length {info['length_m'] * um:.6g} um"
        )
    lines.append(f"  invalid        {info['invalid_fraction'] * 100:.2f} %")
    lines.append(
        f"  height range   {info['z_min_m'] * um:.6g} .. {info['z_max_m'] * um:.6g} um"
    )
    if info["kind"] == "surface":
        lines.append(
            f"  Sa / Sq        {info['sa_m'] * nm:.4f} / {info['sq_m'] * nm:.4f} nm "
            "(about the mean, no levelling)"
        )
        lines.append(f"  Sq after plane {info['sq_plane_m'] * nm:.4f} nm")
        a = info["areal"]

        def q(key: str, scale: float = 1.0, fmt: str = ".4g") -> str:
            v = a[key]
            return "undefined" if v is None or v != v else format(v * scale, fmt)

        lines.append(
            f"  Sp / Sv / Sz   {q('sp_m', nm, '.4f')} / {q('sv_m', nm, '.4f')} / "
            f"{q('sz_m', nm, '.4f')} nm; Ssk {q('ssk')}, Sku {q('sku')}"
        )
        lines.append(
            f"  Sdq / Sdr      {q('sdq')} / {q('sdr_percent')} %; "
            f"Sal {q('sal_m', um)} um, Str {q('str')} (ACF threshold 0.2)"
        )
        lines.append(
            f"  Sk / Spk / Svk {q('sk_m', nm, '.4f')} / {q('spk_m', nm, '.4f')} / "
            f"{q('svk_m', nm, '.4f')} nm; Smr1 {q('smr1_percent')} %, "
            f"Smr2 {q('smr2_percent')} %"
        )
    else:
        lines.append(
            f"  Pa / Pq        {info['pa_m'] * nm:.4f} / {info['pq_m'] * nm:.4f} nm "
            "(primary profile about the mean, unfiltered)"
        )
    flat = {k: v for k, v in info["metadata"].items() if not isinstance(v, dict)}
    width = max([14, *(len(k) for k in flat)])
    for k, v in flat.items():
        lines.append(f"  {k:<{width}} {v}")
    return "\n".join(lines)


def run(args) -> int:
    """Describe the file on stdout; return the exit status."""
    from ..io import read_any
    from ._common import print_json

    obj, fmt = read_any(args.file, format=args.format)
    info = describe(obj, fmt)
    if args.json:
        print_json(info)
    else:
        print(_text(info, args.file))
    return 0
