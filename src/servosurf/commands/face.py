"""``servosurf face``: a whole face, tiled into a chunked Zarr array.

The tiles are computed in this process or, optionally, on dask.
"""

from __future__ import annotations

import argparse

from ._common import add_scheduler_args


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "face",
        help="simulate a whole face tile by tile into Zarr (local or dask cluster)",
        description="Sweep the tool over a whole face at a given pitch, one task per "
        "chunk, streaming chunks to an on-disk Zarr array in bounded memory. Vibration "
        "is a seeded realisation of the real positioning error (block-seeded FIR, the "
        "same samples whatever the tiling). Tracking and force are left out: on a face "
        "the command is constant and the loop removes the static force. The facing "
        "path is run from the face edge (plus the tool's reach) to the axis with the "
        "file's feed, speed and depth.",
    )
    p.add_argument("toolpath", metavar="TOOLPATH",
                   help="a facing toolpath: TOML file or built-in name (flat_facing)")
    p.add_argument("--radius", metavar="M", type=float, required=True,
                   help="face radius to simulate, in m (e.g. 0.01 for a 20 mm face)")
    p.add_argument("--pitch", metavar="M", type=float, default=1e-6,
                   help="grid pitch in m (default 1e-6)")
    p.add_argument("--chunk", metavar="N", type=int, default=1024,
                   help="chunk (task) size in pixels per side (default 1024)")
    p.add_argument("--machine", metavar="M.toml", help="machine TOML or built-in name")
    p.add_argument("--bandwidth", metavar="HZ", type=float, default=None,
                   help="crossover bandwidth in Hz (default 1448, the paper's cutting "
                   "set-up: run preset paper-cutting)")
    p.add_argument("--mass", metavar="KG", type=float, default=None,
                   help="moving mass in kg (default 0.175, the paper's cutting "
                   "set-up: run preset paper-cutting)")
    p.add_argument("--seed", metavar="N", type=int, default=0, help="vibration seed")
    p.add_argument("--no-vibration", action="store_true", help="kinematic surface only")
    add_scheduler_args(p, "the tiles (one task per tile)")
    p.add_argument("--out", metavar="DIR", default="results/face",
                   help="output folder (default results/face), replaced whole when "
                   "the run succeeds")
    p.add_argument("--force", action="store_true",
                   help="run even when the disk or memory estimate exceeds what this "
                   "machine has")
    p.add_argument("--json", action="store_true", help="print the JSON summary")
    return p


def _check_zarr() -> None:
    """zarr writes the face's array: check it before any work is done."""
    try:
        import zarr  # noqa: F401
    except ImportError:
        from ..errors import ConfigError

        raise ConfigError(
            "servosurf face writes a Zarr array and needs zarr: pip install "
            "'zarr>=2.17' (or pip install 'servosurf[scale]' for dask as well)"
        ) from None


def _check_footprint(args, spec, field) -> dict:
    """Disk and memory before anything is written: the array, the vibration file."""
    import math

    from .._resources import check_resources
    from ..scale import MAX_TILE_SAMPLES
    from ..servo import load_machine

    on_face = math.pi * args.radius**2 / args.pitch**2
    fs = load_machine(args.machine).controller.sample_rate
    samples = spec.path.duration * fs if not args.no_vibration else 0.0
    # the array compresses to about 0.7 of 8 B per pixel; the vibration is float32
    disk = 8.0 * on_face + 4.0 * samples
    # per process: a chunk and its inputs, one windowed path, the preview window
    memory = 48.0 * args.chunk**2 + 60.0 * MAX_TILE_SAMPLES + 5e8
    return check_resources(
        f"a {2 * args.radius * 1e3:g} mm face at {args.pitch * 1e6:g} um "
        f"({field.ny} x {field.nx} px, {samples:.3g} vibration samples)",
        memory=memory, disk=disk, where=args.out, force=args.force,
        remedy="lower --radius or raise --pitch",
    )


def run(args) -> int:
    from .._progress import bar
    from ..errors import ConfigError
    from ..run import DEFAULT_PRESET, preset
    from ..scale import face_toolpath, simulate_face_run
    from ._common import (
        check_flags,
        dask_client,
        fmt_length,
        output_folder,
        print_json,
        print_summary,
        write_json,
    )

    check_flags(args)  # --radius, --pitch, --bandwidth, --mass: positive, plausible
    if args.pitch >= args.radius:
        raise ConfigError(f"--pitch {args.pitch:g} m must be below --radius "
                          f"{args.radius:g} m (a face of at least 3 x 3 pixels)")
    if args.chunk < 16:
        raise ConfigError(f"--chunk must be at least 16 pixels, got {args.chunk}")
    _check_zarr()
    # the paper's cutting set-up unless given
    run_cfg = preset(DEFAULT_PRESET).with_overrides(
        machine=args.machine, bandwidth=args.bandwidth, mass=args.mass, seed=args.seed)
    spec = face_toolpath(args.toolpath, args.radius, args.pitch)
    field = spec.field
    footprint = _check_footprint(args, spec, field)
    out = output_folder(args.out)  # swapped in place of --out at the end
    summary: dict = {"toolpath": args.toolpath, "radius_m": args.radius,
                     "pitch_m": args.pitch, "grid": [field.ny, field.nx],
                     "vibration": not args.no_vibration, "seed": args.seed,
                     "estimate": footprint}
    if args.scheduler:
        summary["scheduler"] = args.scheduler
    with dask_client(args.scheduler, args.workers) as client:
        face = simulate_face_run(
            spec, out, run_cfg, radius=args.radius, chunk=args.chunk,
            vibration=not args.no_vibration, client=client,
            progress=lambda it: bar(it, desc="vibration"))
    summary.update(face.to_dict())
    face.plot(out)
    write_json(out / "summary.json", summary)
    if args.json:
        print_json(summary)
    res, stats = face.face, face.stats
    print_summary(
        args,
        f"face {args.toolpath}: {2 * args.radius * 1e3:g} mm diameter, "
        f"{field.ny} x {field.nx} px at {args.pitch * 1e6:g} um"
        + (f", seed {args.seed}" if not args.no_vibration else ", no vibration"),
        [("Sq (whole face)", fmt_length(stats["sq_m"]) + " about the mean, "
          "unfiltered"),
         ("PV (whole face)", fmt_length(stats["max_m"] - stats["min_m"])),
         ("computed", f"{res.n_points:.4g} points in {res.seconds:.1f} s "
          f"({res.points_per_s / 1e6:.3g} M points/s, {res.n_tasks} tiles)")],
        wrote=out,
    )
    return 0
