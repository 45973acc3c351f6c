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
    p.add_argument("toolpath", metavar="TOOLPATH.toml", help="a facing toolpath")
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
                   help="output directory")
    p.add_argument("--json", action="store_true", help="print the JSON summary")
    return p


def run(args) -> int:
    import dataclasses
    import shutil

    import numpy as np

    from .._progress import bar, stage
    from ..errors import ConfigError
    from ..scale import MemmapDeviation, face_field, simulate_face, write_vibration
    from ..servo import ServoLoop, load_machine
    from ..toolpath import load_toolpath
    from ..viz._surface_plots import plot_map
    from ._common import dask_client, out_dir, print_json, write_json

    for name in ("radius", "pitch"):
        v = getattr(args, name)
        if not (np.isfinite(v) and v > 0):
            raise ConfigError(f"--{name} must be a positive length in m, got {v!r}")
    if args.chunk < 16:
        raise ConfigError(f"--chunk must be at least 16 pixels, got {args.chunk}")
    spec = load_toolpath(args.toolpath)
    if spec.kind != "facing":
        raise ConfigError(
            f"{args.toolpath}: face needs a facing toolpath, got {spec.kind!r}"
        )
    out = out_dir(args.out)
    field = face_field(args.radius, args.pitch)
    # the path runs from one arc half-width outside the face to the axis
    reach = spec.tool.chord_half_width(spec.path.depth_of_cut + 1e-6)
    path = dataclasses.replace(spec.path, r_start=args.radius + reach, r_end=0.0)
    spec = dataclasses.replace(spec, field=field, path=path)
    deviation = None
    summary: dict = {"toolpath": args.toolpath, "radius_m": args.radius,
                     "pitch_m": args.pitch, "grid": [field.ny, field.nx],
                     "vibration": not args.no_vibration, "seed": args.seed}
    if not args.no_vibration:
        machine = load_machine(args.machine).with_moving_mass(args.mass)
        loop = ServoLoop(machine.with_bandwidth(args.bandwidth))
        if not loop.is_stable():
            raise ConfigError(f"the loop is unstable at {args.bandwidth:g} Hz")
        n = int(np.ceil(spec.path.duration * loop.fs)) + 4
        vib = out / "vibration.npy"
        with stage(
            f"vibration realisation: {n} samples ({n / loop.fs:.0f} s of cutting)"
        ):
            write_vibration(loop, vib, n, seed=args.seed,
                            progress=lambda it: bar(it, desc="vibration"))
        deviation = MemmapDeviation(str(vib.resolve()))
        summary.update(bandwidth_hz=args.bandwidth, moving_mass_kg=args.mass)
    store = out / "face.zarr"
    if store.exists():
        shutil.rmtree(store)
    if args.scheduler:
        summary["scheduler"] = args.scheduler
    with dask_client(args.scheduler, args.workers) as client, \
            stage(f"face {field.ny} x {field.nx} px in {args.chunk}-px tiles"):
        res = simulate_face(spec, str(store), field=field, face_radius=args.radius,
                            chunk=(args.chunk, args.chunk), deviation=deviation,
                            client=client)
    summary.update(seconds=res.seconds, points=res.n_points,
                   points_per_s=res.points_per_s, tasks=res.n_tasks,
                   path_samples=res.n_samples, zarr=str(store))
    with stage("decimated preview"):
        step = max(1, int(np.ceil(max(field.shape) / 1000)))
        z = np.asarray(res.array[::step, ::step])
        from ..metrology import Surface

        prev = Surface(z, field.pitch_x * step, field.pitch_y * step,
                       x0=field.x0, y0=field.y0)
        plot_map(prev, out / "face.png", title=f"face, every {step}th pixel")
        v = z[np.isfinite(z)]
        summary.update(preview_step=step,
                       preview_sq_m=float(np.std(v)) if v.size else None)
    write_json(out / "summary.json", summary)
    if args.json:
        print_json(summary)
    return 0
