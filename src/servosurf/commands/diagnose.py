"""``servosurf diagnose``: locate, explain and refit model-data mismatch."""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "diagnose",
        help="find what the model leaves out: locate, explain, refit",
        description="Compare the recordings a manifest lists (following error, FRFs, "
        "cuts, surface maps, profiles) with the simulator; locate where they differ "
        "and how surely; rank a catalogue of left-out physics by how well each "
        "signature matches; fit and select with a BIC-like criterion; say "
        "'unexplained' when nothing in the catalogue accounts for the mismatch. "
        "Writes fitted-machine.toml, fitted-effects.toml, before/after PNGs and "
        "summary.json.",
    )
    p.add_argument(
        "manifest",
        nargs="?",
        metavar="MANIFEST.toml",
        help="the case and its recordings (see servosurf.diagnose)",
    )
    p.add_argument(
        "--list",
        action="store_true",
        help="print the catalogue of effects with their parameters and "
        "units, then exit",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        default="results/diagnose",
        help="output directory (default results/diagnose)",
    )
    p.add_argument("--json", action="store_true", help="print the JSON summary")
    return p


def _print_catalogue(as_json: bool) -> None:
    from ..diagnose import catalogue_table
    from ._common import print_json

    table = catalogue_table()
    if as_json:
        print_json({"catalogue": table})
        return
    for e in table:
        tag = " (recalibration, not physics)" if e["recalibration"] else ""
        print(f"{e['effect']}{tag}: {e['title']}")
        for q in e["parameters"]:
            unit = q["unit"] if q["unit"] != "1" else "-"
            print(f"    {q['name']} [{unit}]  {q['doc']}")
        print(f"    visible in: {', '.join(e['visible_in'])}")
        print(f"    signature: {e['signature']}")
        print(f"    confused with: {e['confused_with']}")


def run(args) -> int:
    from ..errors import ConfigError

    if args.list:
        _print_catalogue(args.json)
        return 0
    if not args.manifest:
        raise ConfigError("give a MANIFEST.toml (or --list for the catalogue)")
    import sys

    from .._progress import is_quiet, stage
    from ..diagnose import (
        diagnose,
        fitted_effects_toml,
        fitted_machine_toml,
        write_figures,
    )
    from ._common import atomic_write, output_folder, print_json, write_json

    def progress(msg: str) -> None:
        if not is_quiet():
            print(f"[servosurf]   {msg}", file=sys.stderr, flush=True)

    with stage("diagnosis (locate, rank, fit, select)"):
        d = diagnose(args.manifest, progress=progress)
    out = output_folder(args.out)  # swapped in place of --out at the end
    with stage("fitted machine and pictures"):
        text = fitted_machine_toml(d)
        atomic_write(out / "fitted-machine.toml", lambda p: p.write_text(text))
        eff = fitted_effects_toml(d)
        atomic_write(out / "fitted-effects.toml", lambda p: p.write_text(eff))
        figs = write_figures(d, out)
    summary = d.to_dict()
    summary["files"] = {
        "fitted_machine": str(out / "fitted-machine.toml"),
        "fitted_effects": str(out / "fitted-effects.toml"),
        "figures": {k: str(v) for k, v in figs.items()},
    }
    write_json(out / "summary.json", summary)
    if args.json:
        print_json(summary)
    elif not args.quiet:
        print(f"verdict: {d.verdict}")
        for e in d.explanations:
            pars = ", ".join(f"{k} = {v:.4g}" for k, v in e["parameters"].items())
            sig = e.get("signature") or {}
            size = (f", signature ENR {sig['signature_enr']:.3g} on {sig['recording']}"
                    if sig.get("recording") else "")
            print(f"  {e['effect']} (delta BIC {e['delta_bic']:.1f}{size}): {pars}")
            alts = e.get("indistinguishable_from") or []
            if alts:
                names = ", ".join(f"{a['effect']} (dD {a['delta_deviance']:.1f})"
                                  for a in alts)
                print(f"    as good a fit (dD {e['delta_deviance']:.1f}): {names}; "
                      f"these recordings cannot tell them apart. Told apart by: "
                      f"{e.get('told_apart_by', '')}")
        if not d.explanations and d.refused:
            r = d.refused[0]
            print(f"  closest candidate refused: {r['effect']}: {r['reason']}")
        for m in (d.remainder if d.verdict != "consistent" else [])[:5]:
            print(f"  left: {m.recording}: {m.where} (-log10 p {m.significance:.1f})")
        from ._common import _final

        print(
            f"fit {d.fit_before_percent:.2f} % -> {d.fit_after_percent:.2f} %; "
            f"written to {_final(out)}"
        )
    return 0
