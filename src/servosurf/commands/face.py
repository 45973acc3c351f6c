"""``servosurf face``: a whole face, tiled into a chunked Zarr array.

The tiles are computed in this process or, optionally, on dask.
"""

from __future__ import annotations

import argparse

import numpy as np

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
    p.add_argument("--bandwidth", metavar="HZ", type=float, default=1448.0,
                   help="crossover bandwidth in Hz (default 1448)")
    p.add_argument("--mass", metavar="KG", type=float, default=0.175,
                   help="moving mass in kg (default 0.175)")
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
    from ..scale._face import MAX_TILE_SAMPLES

    on_face = math.pi * args.radius**2 / args.pitch**2
    samples = spec.path.duration * 199.6e3 if not args.no_vibration else 0.0
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
    import dataclasses

    from .._progress import bar, stage
    from ..errors import ConfigError
    from ..scale import (
        MemmapDeviation,
        face_field,
        face_preview,
        simulate_face,
        write_vibration,
    )
    from ..servo import ServoLoop, load_machine
    from ..toolpath import load_toolpath
    from ..viz._surface_plots import plot_map
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
    spec = load_toolpath(args.toolpath)
    if spec.kind != "facing":
        raise ConfigError(
            f"{args.toolpath}: face needs a facing toolpath, got {spec.kind!r}"
        )
    field = face_field(args.radius, args.pitch)
    # the path runs from one arc half-width outside the face to the axis
    reach = spec.tool.chord_half_width(spec.path.depth_of_cut + 1e-6)
    path = dataclasses.replace(spec.path, r_start=args.radius + reach, r_end=0.0)
    spec = dataclasses.replace(spec, field=field, path=path)
    footprint = _check_footprint(args, spec, field)
    out = output_folder(args.out)  # swapped in place of --out at the end
    deviation = None
    summary: dict = {"toolpath": args.toolpath, "radius_m": args.radius,
                     "pitch_m": args.pitch, "grid": [field.ny, field.nx],
                     "vibration": not args.no_vibration, "seed": args.seed,
                     "estimate": footprint}
    if not args.no_vibration:
        machine = load_machine(args.machine).with_moving_mass(args.mass)
        loop = ServoLoop(machine.with_bandwidth(args.bandwidth))
        if not loop.is_stable():
            raise ConfigError(f"the loop is unstable at {args.bandwidth:g} Hz; lower "
                              "--bandwidth")
        n = int(np.ceil(spec.path.duration * loop.fs)) + 4
        vib = out / "vibration.npy"
        with stage(
            f"vibration realisation: {n} samples ({n / loop.fs:.0f} s of cutting)"
        ):
            write_vibration(loop, vib, n, seed=args.seed,
                            progress=lambda it: bar(it, desc="vibration"))
        deviation = MemmapDeviation(str(vib.resolve()))
        summary.update(bandwidth_hz=args.bandwidth, moving_mass_kg=args.mass,
                       vibration_record={
                           "file": str(vib), "unit": "m", "dtype": "float32",
                           "sample_rate_hz": loop.fs, "t0_s": 0.0,
                           "what": "tool-height deviation, sample k at t = k / "
                                   "sample_rate_hz from the start of the cut"})
    store = out / "face.zarr"
    if args.scheduler:
        summary["scheduler"] = args.scheduler
    with dask_client(args.scheduler, args.workers) as client, \
            stage(f"face {field.ny} x {field.nx} px in {args.chunk}-px tiles"):
        res = simulate_face(spec, str(store), field=field, face_radius=args.radius,
                            chunk=(args.chunk, args.chunk), deviation=deviation,
                            client=client)
    summary.update(seconds=res.seconds, points=res.n_points,
                   points_per_s=res.points_per_s, tasks=res.n_tasks,
                   path_samples=res.n_samples, zarr=str(store),
                   zarr_attributes=dict(res.array.attrs))
    with stage("area-averaged preview and statistics"):
        # about as many preview pixels as the PNG shows (dpi 150): no resampling
        z, step, stats = face_preview(res.array, max_pixels=560,
                                      window=max(args.chunk, 256))
        from ..metrology import Surface

        half = 0.5 * (step - 1)
        prev = Surface(z - stats["mean_m"], field.pitch_x * step, field.pitch_y * step,
                       x0=field.x0 + half * field.pitch_x,
                       y0=field.y0 + half * field.pitch_y)
        what = (f"{step} x {step}-pixel block means" if step > 1
                else "every pixel")
        plot_map(prev, out / "face.png", robust=0.5, dpi=150,
                 title=f"{2 * args.radius * 1e3:g} mm face at "
                 f"{args.pitch * 1e6:g} um pitch ({what}),\nheight about the "
                 f"face mean ({stats['mean_m'] * 1e9:.4g} nm)")
        summary.update(preview_step=step, preview_block_px=step,
                       face_mean_m=stats["mean_m"], face_sq_m=stats["sq_m"],
                       face_pv_m=stats["max_m"] - stats["min_m"],
                       face_statistics="every valid pixel, about the mean, "
                       "unfiltered (no levelling: the face is flat by construction)")
    write_json(out / "summary.json", summary)
    if args.json:
        print_json(summary)
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
