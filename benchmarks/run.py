"""Speed and scale benchmarks of the swept-arc surface kernels.

Usage::

    python benchmarks/run.py            # full cases, a table on stdout
    python benchmarks/run.py --quick    # smaller cases (about a minute)
    python benchmarks/run.py --json     # one JSON document on stdout
    python benchmarks/run.py --case facing_1024 --case flops_ceiling

Cases live in the ``CASES`` registry (name -> function(quick) -> dict); add a case by
decorating a function with ``@case("name")``. Every case reports at least
``points_per_s``, ``speedup_vs_reference``, ``speedup_vs_exhaustive`` and
``peak_memory_bytes`` (None where it does not apply).

Measurement rules
-----------------
* Times are the best of several runs (25 for the 1024 x 1024 fields, whose median is
  reported as ``points_per_s_median``) after a warm-up call (JIT compilation and the
  on-disk cache load are excluded; ``compile_s`` reports the first call). They are
  whole ``sweep()`` calls: path checks, cropping and bucket statistics included.
  ``kernel_points_per_s`` and ``prepare_seconds`` split a call into its two parts
  (the kernel on an already prepared path, and the preparation alone).
* ``points_per_cpu_s_1_thread`` divides by process CPU time of a one-thread call: on a
  shared machine it is the steadiest measure of the kernel's own cost.
* Slow peers (plain-numpy reference, exhaustive kernel) run on a sub-field of the same
  case and are compared per grid point.
* ``peak_memory_bytes`` is the tracemalloc peak of the timed call (numpy buffers are
  traced) for in-process cases, and the child's ``ru_maxrss`` (resource module) for
  the whole-face case, which runs in a subprocess.
* The process calls ``servosurf.scale.reuse_freed_memory()`` so repeated runs reuse
  freed buffers instead of page-faulting them in again (a large cost on VMs).
* The machine's load average is reported: on a shared machine the two cores may not
  both be free, and then 2-thread numbers approach 1-thread numbers.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # tests/reference/naive.py

import servosurf.toolpath as tp  # noqa: E402
from servosurf.scale import (  # noqa: E402
    IndexNoise,
    face_field,
    reuse_freed_memory,
    simulate_face,
)
from servosurf.toolpath import prepare_path, run_kernel  # noqa: E402

CASES: dict[str, Callable[[bool], dict]] = {}


def case(name: str):
    """Register a benchmark case ``fn(quick: bool) -> dict``."""
    def deco(fn):
        CASES[name] = fn
        return fn
    return deco


def best_time(fn, repeat=3):
    """Best wall time of ``repeat`` calls, in s."""
    return time_stats(fn, repeat)[0]


def time_stats(fn, repeat=3):
    """(best, median) wall time of ``repeat`` calls, in s."""
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return min(ts), float(np.median(ts))


def best_cpu_time(fn, repeat=3):
    """Best process CPU time of ``repeat`` calls, in s (robust on a shared machine
    for single-threaded calls: time spent waiting for a core is not counted)."""
    best = math.inf
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def traced_peak(fn):
    """tracemalloc peak (bytes) of one call."""
    tracemalloc.start()
    tracemalloc.reset_peak()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def naive_rate(path, tool, field, rows, cols):
    """Plain-numpy reference on a sub-field: (points per s, seconds)."""
    from reference import naive

    x, y = field.coords()
    xs, ys = x[cols[0]:cols[1]], y[rows[0]:rows[1]]
    init = np.zeros((ys.size, xs.size))
    t0 = time.perf_counter()
    naive.sweep(path.t, path.theta, path.r, path.z, path.fs, xs, ys,
                tool.nose_radius, tool.half_width, init)
    dt = time.perf_counter() - t0
    return xs.size * ys.size / dt, dt


def sweep_case(spec, field, path, *, exhaustive_rows, reference_rows, quick):
    """Time pruned, exhaustive and reference sweeps of one field."""
    tool = spec.tool
    n = field.nx * field.ny
    t0 = time.perf_counter()
    z = tp.sweep(path, tool, field).z  # compiles or loads from cache
    compile_s = time.perf_counter() - t0
    # 25 calls (about 0.5 s on facing): a neighbour VM that takes a core for a
    # moment does not set the figure; the median is reported beside it
    t_pruned, t_median = time_stats(lambda: tp.sweep(path, tool, field),
                                    5 if quick else 25)
    t1 = best_time(lambda: tp.sweep(path, tool, field, n_threads=1), 2 if quick else 3)
    c1 = best_cpu_time(lambda: tp.sweep(path, tool, field, n_threads=1),
                       3 if quick else 5)
    peak = traced_peak(lambda: tp.sweep(path, tool, field))
    # the two parts of a sweep() call: path preparation (checks, clearance,
    # crop decision, bucket statistics) and the kernel on the prepared path
    t_prep = best_time(lambda: prepare_path(path, tool, field, check=True),
                       3 if quick else 7)
    prep = prepare_path(path, tool, field, check=True)
    buf = np.empty(field.shape)
    t_kernel = best_time(lambda: run_kernel(prep, tool, field, buf, fill=0.0),
                         3 if quick else 7)
    # exhaustive kernel on a band of rows, per point
    rows = (field.ny // 2, field.ny // 2 + exhaustive_rows)
    ze = tp.sweep(path, tool, field, rows=rows, method="exhaustive").z
    t_ex = best_time(lambda: tp.sweep(path, tool, field, rows=rows,
                                      method="exhaustive"), 1)
    exh_rate = ze.size / t_ex
    same = bool(np.array_equal(ze, z[rows[0]:rows[1]]))
    # plain-numpy reference on a small square, per point
    c = field.nx // 2
    rr = (field.ny // 2, field.ny // 2 + reference_rows)
    ref_rate, ref_s = naive_rate(path, tool, field, rr, (c, c + reference_rows))
    # passes: revolutions within reach of the field, crossings per point
    pruned_rate = n / t_pruned
    return {
        "grid": [field.ny, field.nx],
        "pitch_m": [field.pitch_y, field.pitch_x],
        "n_samples": path.n,
        "points_per_s": pruned_rate,
        "points_per_s_median": n / t_median,
        "points_per_s_1_thread": n / t1,
        "points_per_cpu_s_1_thread": n / c1,
        "kernel_points_per_s": n / t_kernel,
        "kernel_identical": bool(np.array_equal(buf, z, equal_nan=True)),
        "prepare_seconds": t_prep,
        "seconds": t_pruned,
        "compile_s": compile_s,
        "exhaustive_points_per_s": exh_rate,
        "reference_points_per_s": ref_rate,
        "reference_seconds": ref_s,
        "speedup_vs_exhaustive": pruned_rate / exh_rate,
        "speedup_vs_reference": pruned_rate / ref_rate,
        "exhaustive_identical": same,
        "peak_memory_bytes": peak,
        "peak_memory_kind": "tracemalloc peak of one sweep() call",
        "z_range_m": [float(np.nanmin(z)), float(np.nanmax(z))],
    }


@case("facing_1024")
def facing_1024(quick: bool) -> dict:
    """1024 x 1024 flat-facing field, 0.5 um pitch, 2 um/rev, 1 nm RMS vibration."""
    spec = tp.load_toolpath(ROOT / "toolpaths" / "flat_facing.toml")
    n = 512 if quick else 1024
    field = tp.Field(pitch_x=0.5e-6, pitch_y=0.5e-6, nx=n, ny=n, center_x=5e-3)
    path = tp.sample(spec, field=field)
    path = path.add_z(IndexNoise(rms=1e-9, seed=1)(path))  # seeded stand-in vibration
    res = sweep_case(spec, field, path, exhaustive_rows=2 if quick else 4,
                     reference_rows=6 if quick else 10, quick=quick)
    reach_passes = 2 * spec.tool.chord_half_width(5e-6) / spec.path.feed_per_rev
    res["passes_reaching_each_point"] = reach_passes
    res["passes_per_s"] = res["points_per_s"] * reach_passes
    res["vibration"] = "IndexNoise(rms=1e-9, seed=1): uniform white, 1 nm RMS"
    return res


@case("ordered_facing")
def ordered_facing(quick: bool) -> dict:
    """The time-ordered sweep (material rules) on the seed paper's 480 x 640 flat
    field, 2 um/rev, 1 nm RMS vibration, against the envelope sweep and the
    plain-numpy ordered reference."""
    from reference import naive

    spec = tp.load_toolpath(ROOT / "toolpaths" / "flat_facing.toml")
    field = spec.field
    if quick:
        field = tp.Field(pitch_x=field.pitch_x, pitch_y=field.pitch_y, nx=320, ny=240,
                         center_x=field.center_x)
    tool = spec.tool
    path = tp.sample(spec, field=field, reach=tp.field_reach(tool, 5e-6))
    path = path.add_z(IndexNoise(rms=1e-9, seed=1)(path))
    rules = tp.CuttingRules(min_chip_thickness=5e-9, side_flow_height=1e-9,
                            side_flow_width=0.2e-6, recovery_height=2e-9,
                            recovery_decay=20e-9)
    n = field.nx * field.ny
    t0 = time.perf_counter()
    z = tp.sweep_ordered(path, tool, field, rules=rules).z
    compile_s = time.perf_counter() - t0
    t_ord, t_med = time_stats(lambda: tp.sweep_ordered(path, tool, field,
                                                       rules=rules), 3 if quick else 5)
    t_env = best_time(lambda: tp.sweep(path, tool, field), 3 if quick else 5)
    c1 = best_cpu_time(lambda: tp.sweep_ordered(path, tool, field, rules=rules,
                                                n_threads=1), 2)
    peak = traced_peak(lambda: tp.sweep_ordered(path, tool, field, rules=rules))
    # plain-numpy reference on a small square, per point
    k = 3 if quick else 4
    x, y = field.coords()
    r0, c0 = field.ny // 2, field.nx // 2
    t0 = time.perf_counter()
    ref = naive.ordered_sweep(path.t, path.theta, path.r, path.z, path.fs,
                              x[c0:c0 + k], y[r0:r0 + k], tool.nose_radius,
                              tool.half_width, np.zeros((k, k)), rules.as_array())
    ref_rate = k * k / (time.perf_counter() - t0)
    return {
        "grid": [field.ny, field.nx],
        "n_samples": path.n,
        "rules_m": rules.to_dict(),
        "seconds": t_ord,
        "points_per_s": n / t_ord,
        "points_per_s_median": n / t_med,
        "points_per_cpu_s_1_thread": n / c1,
        "compile_s": compile_s,
        "envelope_seconds": t_env,
        "slowdown_vs_envelope": t_ord / t_env,
        "reference_points_per_s": ref_rate,
        "speedup_vs_reference": n / t_ord / ref_rate,
        "reference_max_abs_diff_m": float(np.abs(ref - z[r0:r0 + k,
                                                         c0:c0 + k]).max()),
        "speedup_vs_exhaustive": None,
        "peak_memory_bytes": peak,
        "peak_memory_kind": "tracemalloc peak of one sweep_ordered() call",
    }


@case("lenslet_1024")
def lenslet_1024(quick: bool) -> dict:
    """1024 x 1024 field at 0.5 um over 5 um lenslets (3 rings), no deviation."""
    spec = tp.load_toolpath(ROOT / "toolpaths" / "lenslet_5um.toml")
    n = 512 if quick else 1024
    field = tp.Field(pitch_x=0.5e-6, pitch_y=0.5e-6, nx=n, ny=n,
                     center_x=spec.field.center_x)
    path = tp.sample(spec, field=field)
    res = sweep_case(spec, field, path, exhaustive_rows=8 if quick else 16,
                     reference_rows=6 if quick else 10, quick=quick)
    res["passes_reaching_each_point"] = float(spec.path.ring_count)
    res["passes_per_s"] = res["points_per_s"] * spec.path.ring_count
    return res


_OCL_SCRIPT = textwrap.dedent("""
    import sys, time, numpy as np, opencamlib as ocl
    d = np.load(sys.argv[1])
    X, Y, Z, R = d["x"], d["y"], d["z"], float(d["R"])
    s = ocl.STLSurf()
    ny, nx = Z.shape
    P = [[ocl.Point(float(X[i, j]), float(Y[i, j]), float(-Z[i, j])) for j in range(nx)]
         for i in range(ny)]
    for i in range(ny - 1):
        for j in range(nx - 1):
            s.addTriangle(ocl.Triangle(P[i][j], P[i + 1][j], P[i][j + 1]))
            s.addTriangle(ocl.Triangle(P[i + 1][j], P[i + 1][j + 1], P[i][j + 1]))
    cutter = ocl.BallCutter(2 * R, 10 * R)
    pdc = ocl.BatchDropCutter()
    pdc.setSTL(s)
    pdc.setCutter(cutter)
    for x in d["gx"]:
        for y in d["gy"]:
            pdc.appendPoint(ocl.CLPoint(float(x), float(y), -1.0))
    t0 = time.perf_counter()
    pdc.run()
    dt = time.perf_counter() - t0
    print(len(d["gx"]) * len(d["gy"]) / dt, s.size())
""")


def _ocl_python() -> str | None:
    """Python of a /tmp venv with opencamlib, created on first use (None: skip)."""
    venv = Path(tempfile.gettempdir()) / "servosurf-ocl-venv"
    py = venv / "bin" / "python"
    if not py.exists():
        try:
            subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True,
                           capture_output=True, timeout=300)
            subprocess.run([str(py), "-m", "pip", "install", "-q", "opencamlib",
                            "numpy"], check=True, capture_output=True, timeout=600)
        except (subprocess.SubprocessError, OSError):
            return None
    ok = subprocess.run([str(py), "-c", "import opencamlib"], capture_output=True)
    return str(py) if ok.returncode == 0 else None


@case("opencamlib_peer")
def opencamlib_peer(quick: bool) -> dict:
    """OpenCAMLib BatchDropCutter (sphere tool) vs the pruned kernel, same points.

    The machined height of a sphere-tool sweep is minus the drop-cutter height of a
    ball dropped onto the negated tool-centre surface (a triangulated spiral of tool
    tips). This is a sphere, not the planar arc, so only speeds are compared.
    """
    py = _ocl_python()
    if py is None:
        return {"skipped": "opencamlib did not install in a /tmp venv", "points_per_s":
                None, "speedup_vs_reference": None, "speedup_vs_exhaustive": None,
                "peak_memory_bytes": None}
    spec = tp.load_toolpath(ROOT / "toolpaths" / "flat_facing.toml")
    field = tp.Field(pitch_x=0.5e-6, pitch_y=0.5e-6, nx=64, ny=64, center_x=5e-3)
    # tool-tip surface on a polar grid covering the field plus the 71 um reach
    ang = np.linspace(-0.03, 0.03, 120)
    revs = np.arange(spec.path.r_start - 5.12e-3, spec.path.r_start - 4.88e-3, 2e-6)
    r = spec.path.r_start - revs
    th = ang[None, :] + 0 * r[:, None]
    rr = r[:, None] - spec.path.feed_per_rev * th / (2 * np.pi)
    x, y = rr * np.cos(th), rr * np.sin(th)
    z = np.full_like(x, -spec.path.depth_of_cut)
    gx, gy = field.coords()
    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / "ocl.npz"
        np.savez(f, x=x, y=y, z=z, R=spec.tool.nose_radius, gx=gx, gy=gy)
        res = subprocess.run([py, "-c", _OCL_SCRIPT, str(f)], capture_output=True,
                             text=True, timeout=1200)
    if res.returncode != 0:
        return {"skipped": f"opencamlib run failed: {res.stderr[-300:]}",
                "points_per_s": None, "speedup_vs_reference": None,
                "speedup_vs_exhaustive": None, "peak_memory_bytes": None}
    ocl_rate, n_tri = res.stdout.split()
    path = tp.sample(spec, field=field)
    tp.sweep(path, spec.tool, field)
    t = best_time(lambda: tp.sweep(path, spec.tool, field), 5)
    rate = field.nx * field.ny / t
    return {"points_per_s": rate, "opencamlib_points_per_s": float(ocl_rate),
            "opencamlib_triangles": int(n_tri),
            "speedup_vs_opencamlib": rate / float(ocl_rate),
            "speedup_vs_reference": None, "speedup_vs_exhaustive": None,
            "peak_memory_bytes": None,
            "note": "64 x 64 points; OCL on a 2-D triangulated tip surface"}


_FACE_SCRIPT = textwrap.dedent("""
    import json, resource, sys, time
    import servosurf.toolpath as tp
    from servosurf._progress import set_quiet
    from servosurf.scale import IndexNoise, face_field, simulate_face
    radius, pitch = float(sys.argv[1]), float(sys.argv[2])
    store, quiet = sys.argv[3], sys.argv[4]
    set_quiet(quiet == "1")
    spec = tp.ToolpathSpec(kind="facing",
                           path=tp.FacingToolpath(r_start=radius, r_end=0.0))
    warm = face_field(20e-6, pitch)
    simulate_face(spec, store + ".warm", field=warm, face_radius=20e-6)  # JIT/cache
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    res = simulate_face(spec, store, field=face_field(radius, pitch),
                        face_radius=radius,
                        deviation=IndexNoise(rms=1e-9, seed=1))
    dt = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({"seconds": dt, "n_points": res.n_points,
                      "n_samples": res.n_samples, "n_tasks": res.n_tasks,
                      "rss_before_kb": rss0, "rss_peak_kb": peak}))
""")


@case("whole_face")
def whole_face(quick: bool) -> dict:
    """20 mm diameter face at 1 um pitch to a Zarr directory (subprocess, peak RSS)."""
    radius = 2e-3 if quick else 10e-3
    with tempfile.TemporaryDirectory() as d:
        store = str(Path(d) / "face.zarr")
        res = subprocess.run([sys.executable, "-c", _FACE_SCRIPT, str(radius), "1e-6",
                              store, "1"], capture_output=True, text=True,
                             timeout=3600)
        if res.returncode != 0:
            raise RuntimeError(res.stderr[-2000:])
        out = json.loads(res.stdout.strip().splitlines()[-1])
        size = sum(f.stat().st_size for f in Path(store).rglob("*") if f.is_file())
    return {
        "face_diameter_m": 2 * radius,
        "pitch_m": 1e-6,
        "seconds": out["seconds"],
        "n_points": out["n_points"],
        "n_samples": out["n_samples"],
        "n_tasks": out["n_tasks"],
        "points_per_s": out["n_points"] / out["seconds"],
        "peak_memory_bytes": out["rss_peak_kb"] * 1024,
        "peak_memory_kind": "ru_maxrss of the child process (resource), whole run",
        "zarr_bytes_on_disk": size,
        "speedup_vs_reference": None,
        "speedup_vs_exhaustive": None,
    }


def _warm_worker() -> None:
    """Load every kernel in a dask worker (one numba thread) before timing."""
    import numba
    import zarr  # noqa: F401

    from servosurf.scale import compute_tile

    numba.set_num_threads(1)
    spec = tp.ToolpathSpec(kind="facing",
                           path=tp.FacingToolpath(r_start=20e-6, r_end=0.0))
    f = face_field(20e-6, 1e-6)
    compute_tile(spec, f, (0, f.ny), (0, f.nx), face_radius=20e-6,
                 deviation=IndexNoise(rms=1e-9, seed=1))


@case("whole_face_dask")
def whole_face_dask(quick: bool) -> dict:
    """Dask LocalCluster (2 worker processes x 1 thread) vs one process, same face.

    Both sides use one numba thread per process, so the speed-up measures task
    parallelism; on a machine whose cores are shared it stays below 2.
    """
    import distributed

    from servosurf._progress import set_quiet

    set_quiet(True)
    radius = 1e-3 if quick else 3e-3
    spec = tp.ToolpathSpec(kind="facing",
                           path=tp.FacingToolpath(r_start=radius, r_end=0.0))
    field = face_field(radius, 1e-6)
    dev = IndexNoise(rms=1e-9, seed=1)
    d = tempfile.mkdtemp()
    try:
        simulate_face(spec, d + "/warm.zarr", field=face_field(20e-6, 1e-6),
                      face_radius=20e-6)
        local = simulate_face(spec, d + "/local.zarr", field=field, face_radius=radius,
                              chunk=(512, 512), deviation=dev, n_threads=1)
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1,
                                      processes=True, dashboard_address=None) as cl, \
                distributed.Client(cl) as client:
            client.run(_warm_worker)  # kernels loaded in both workers
            dres = simulate_face(spec, d + "/dask.zarr", field=field,
                                 face_radius=radius, chunk=(512, 512), deviation=dev,
                                 client=client, n_threads=1)
        same = bool(np.array_equal(local.array[:], dres.array[:], equal_nan=True))
    finally:
        shutil.rmtree(d, ignore_errors=True)
    return {
        "face_diameter_m": 2 * radius,
        "local_1_thread_seconds": local.seconds,
        "dask_2_workers_seconds": dres.seconds,
        "dask_speedup": local.seconds / dres.seconds,
        "identical": same,
        "points_per_s": dres.points_per_s,
        "speedup_vs_reference": None,
        "speedup_vs_exhaustive": None,
        "peak_memory_bytes": None,
    }


def _warm_realisation() -> None:
    """Load the simulation kernels in a dask worker (one numba thread)."""
    import numba

    from servosurf.report import realisation_study
    from servosurf.run import RunConfig

    numba.set_num_threads(1)
    realisation_study(ROOT / "toolpaths" / "lenslet_5um.toml",
                      RunConfig(instrument=None, n_threads=1), seeds=[0])


@case("realisations_dask")
def realisations_dask(quick: bool) -> dict:
    """Vibration realisations of the 5 um lenslet: LocalCluster (2 worker processes
    x 1 thread) against one process x 1 thread, one task per seed."""
    import distributed

    from servosurf._progress import set_quiet
    from servosurf.report import realisation_study
    from servosurf.run import RunConfig

    set_quiet(True)
    seeds = list(range(4 if quick else 8))
    toolpath = ROOT / "toolpaths" / "lenslet_5um.toml"
    # the machine's own set-up, no instrument model, one numba thread per task
    run = RunConfig(instrument=None, n_threads=1)
    realisation_study(toolpath, run, seeds=[0])  # warm
    t0 = time.perf_counter()
    local = realisation_study(toolpath, run, seeds=seeds)
    t_local = time.perf_counter() - t0
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cl, \
            distributed.Client(cl) as client:
        client.run(_warm_realisation)
        t0 = time.perf_counter()
        dres = realisation_study(toolpath, run, seeds=seeds, client=client)
        t_dask = time.perf_counter() - t0
    same = all(np.array_equal(local.metrics[k], dres.metrics[k], equal_nan=True)
               for k in local.metrics)
    return {
        "realisations": len(seeds),
        "local_1_thread_seconds": t_local,
        "dask_2_workers_seconds": t_dask,
        "dask_speedup": t_local / t_dask,
        "identical": same,
        "points_per_s": None,
        "speedup_vs_reference": None,
        "speedup_vs_exhaustive": None,
        "peak_memory_bytes": None,
    }


@case("memory_bandwidth")
def memory_bandwidth(quick: bool) -> dict:
    """Streaming triad a = b + s c over 3 x 128 MB, 1 and 2 threads (GB/s).

    The path stage of a tile (sampling, interleaving, bucket bounds: ~6 samples of
    ~100 bytes per pixel on a whole face) streams memory; this is its ceiling.
    """
    import numba
    from numba import njit, prange

    @njit(parallel=True)
    def triad(a, b, c, s):
        for i in prange(a.size):
            a[i] = b[i] + s * c[i]

    n = (4 if quick else 16) * 1024 * 1024
    a, b, c = np.zeros(n), np.ones(n), np.full(n, 2.0)
    triad(a, b, c, 3.0)
    out = {}
    old = numba.get_num_threads()
    try:
        for nt in (1, 2):
            numba.set_num_threads(nt)
            t = best_time(lambda: triad(a, b, c, 3.0), 5)
            out[f"bytes_per_s_{nt}_thread{'s' if nt > 1 else ''}"] = 3 * 8 * n / t
    finally:
        numba.set_num_threads(old)
    out["thread_scaling"] = out["bytes_per_s_2_threads"] / out["bytes_per_s_1_thread"]
    out.update(points_per_s=None, speedup_vs_reference=None,
               speedup_vs_exhaustive=None, peak_memory_bytes=3 * 8 * n)
    return out


@case("flops_ceiling")
def flops_ceiling(quick: bool) -> dict:
    """sqrt + fma rates on all threads: one dependent chain and independent lanes."""
    import numba
    from numba import njit, prange

    from servosurf.kernels import FASTMATH

    @njit(parallel=True, fastmath=FASTMATH)
    def ceiling(n, out):
        for k in prange(out.size):
            acc = 0.0
            x = 1.0 + k
            for i in range(n):
                x = x * 0.9999999 + 1e-7  # fma
                acc += np.sqrt(x)  # sqrt + add
            out[k] = acc

    @njit(parallel=True, fastmath=FASTMATH)
    def throughput(reps, buf, out):
        # independent lanes over an L1-resident block: the loop vectorises, so this
        # is the sqrt + fma issue rate rather than the latency of one chain
        for k in prange(out.size):
            b = buf[k]
            acc = 0.0
            for _ in range(reps):
                for i in range(b.size):
                    acc += np.sqrt(b[i] * 0.9999999 + 1e-7)
            out[k] = acc

    nt = numba.get_num_threads()
    out = np.zeros(nt * 8)
    ceiling(10, out)
    n = 2_000_000 if quick else 10_000_000
    t = best_time(lambda: ceiling(n, out), 3)
    sqrt_per_s = out.size * n / t
    lanes = 512  # 4 KB per thread block: L1-resident
    buf = 1.0 + np.random.default_rng(0).random((nt * 8, lanes))
    throughput(1, buf, out)
    reps = n // lanes
    t2 = best_time(lambda: throughput(reps, buf, out), 3)
    return {"threads": nt, "sqrt_fma_per_s": sqrt_per_s,
            "sqrt_fma_per_s_kind": "one dependent chain per thread (latency bound)",
            "sqrt_fma_throughput_per_s": out.size * reps * lanes / t2,
            "sqrt_fma_throughput_kind": "independent vectorised lanes (issue bound)",
            "points_per_s": None, "speedup_vs_reference": None,
            "speedup_vs_exhaustive": None, "peak_memory_bytes": None}


@case("realisation_whole_part")
def realisation_whole_part(quick: bool) -> dict:
    """Vibration realisations: one-shot FFT (a field's span) and the block stream."""
    import tempfile

    from servosurf.noise import VibrationStream, realise
    from servosurf.run import preset
    from servosurf.servo import ServoLoop

    loop = ServoLoop(preset("paper-cutting").machine_model())
    n_fft = 2_000_000 if quick else 12_000_000  # 60 s of cutting at 199.6 kHz
    realise(loop, 4096, seed=0)  # warm-up
    t_fft = best_time(lambda: realise(loop, n_fft, seed=1), repeat=1)
    stream = VibrationStream(loop, seed=1)
    # a whole 20 mm face at 250 rpm and 2 um/rev: 5000 revolutions, 1200 s
    n_face = int(1200 * loop.fs)
    n_stream = 4_000_000 if quick else 40_000_000
    with tempfile.TemporaryDirectory() as d:
        t_stream = best_time(lambda: stream.to_memmap(f"{d}/v.npy", n_stream), repeat=1)
        t_stream1 = best_time(
            lambda: stream.to_memmap(f"{d}/v1.npy", n_stream, workers=1), repeat=1)
    peak = traced_peak(lambda: stream.segment(0, 1 << 22))
    return {
        "fft_samples": n_fft, "fft_samples_per_s": n_fft / t_fft,
        "stream_samples": n_stream, "stream_samples_per_s": n_stream / t_stream,
        "stream_samples_per_s_1_thread": n_stream / t_stream1,
        "whole_face_samples": n_face,
        "whole_face_stream_estimate_s": n_face / (n_stream / t_stream),
        "points_per_s": n_stream / t_stream,
        "peak_memory_bytes": peak,
    }


@case("bandwidth_mass_sweep")
def bandwidth_mass_sweep(quick: bool) -> dict:
    """RMS errors on a (mass x bandwidth) grid with optimum and stability limit."""
    import numpy as np

    from servosurf.noise import design_study
    from servosurf.servo import load_machine

    masses = [0.075, 0.175] if quick else [0.075, 0.125, 0.175, 0.225]
    bws = np.geomspace(200, 1800, 9 if quick else 17)
    m = load_machine()
    t0 = time.perf_counter()
    st = design_study(m, masses, bws)
    dt = time.perf_counter() - t0
    return {"masses_kg": masses, "bandwidths": len(bws), "wall_s_sweep": dt,
            "points_per_s": len(masses) * len(bws) / dt,
            "optimal_bandwidth_hz": st.optimal_bandwidth.tolist(),
            "stability_limit_hz": st.stability_limit.tolist(),
            "peak_memory_bytes": None}


@case("simulate_cases")
def simulate_cases(quick: bool) -> dict:
    """End-to-end simulate() of the shipped toolpaths (model map, no figures)."""
    from servosurf._progress import set_quiet
    from servosurf.simulation import simulate

    set_quiet(True)
    out = {}
    names = ["lenslet_5um"] if quick else ["lenslet_5um", "lenslet_10um", "flat_facing"]
    for name in names:
        path = ROOT / "toolpaths" / f"{name}.toml"
        simulate(path, seed=0)  # warm the JIT cache
        t0 = time.perf_counter()
        r = simulate(path, seed=0)
        dt = time.perf_counter() - t0
        out[name] = {"wall_s": dt, "grid": list(r.surface.shape),
                     "controller_samples": int(r.t.size),
                     "points_per_s": r.surface.z.size / dt}
    out["points_per_s"] = min(v["points_per_s"] for v in out.values())
    out["peak_memory_bytes"] = None
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller cases")
    parser.add_argument("--json", action="store_true", help="JSON on stdout")
    parser.add_argument("--case", action="append", choices=sorted(CASES),
                        help="run only this case (repeatable)")
    args = parser.parse_args(argv)
    reuse_freed_memory()
    import numba

    results: dict[str, dict] = {
        "_machine": {"cpus": os.cpu_count(), "numba_threads": numba.get_num_threads(),
                     "load_average_start": os.getloadavg(), "quick": args.quick}}
    for name in args.case or list(CASES):
        t0 = time.perf_counter()
        try:
            results[name] = CASES[name](args.quick)
        except Exception as exc:  # a failing case must not hide the others
            results[name] = {"error": f"{type(exc).__name__}: {exc}"}
        results[name]["wall_s"] = time.perf_counter() - t0
        if not args.json:
            print(f"[{name}] done in {results[name]['wall_s']:.1f} s", file=sys.stderr)
    # kernel against the machine ceiling
    ceil = results.get("flops_ceiling", {}).get("sqrt_fma_per_s")
    peak = results.get("flops_ceiling", {}).get("sqrt_fma_throughput_per_s")
    for name in ("facing_1024", "lenslet_1024"):
        r = results.get(name, {})
        if ceil and r.get("points_per_s"):
            r["ns_per_point"] = 1e9 / r["points_per_s"]
            # per point: how many dependent (latency) / independent (throughput)
            # sqrt + fma the same time would buy
            r["sqrt_fma_per_point_at_ceiling"] = ceil / r["points_per_s"]
            if peak:
                r["sqrt_fma_per_point_at_throughput"] = peak / r["points_per_s"]
    results["_machine"]["load_average_end"] = os.getloadavg()
    if args.json:
        print(json.dumps(results, indent=2, default=float))
        return 0
    for name, r in results.items():
        print(f"\n== {name}")
        for k, v in r.items():
            if isinstance(v, float):
                v = f"{v:.4g}"
            print(f"  {k:34s} {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
