"""Speed and memory of ``servosurf.metrology.areal_parameters`` (ISO 25178-2).

Usage::

    python benchmarks/areal.py           # 480 x 640 and 2048 x 2048 maps, a table
    python benchmarks/areal.py --json    # one JSON document on stdout

Each case times the whole call (best wall and best process CPU time of 3 after a
warm-up; imports excluded), reports the tracemalloc peak of one call (numpy
buffers are traced) and, when surfalize is installed, the CPU time surfalize 0.19
takes for the same parameters on the same array (Sa..Sku, Sdq, Sdr, Sal, Str, Sk,
Spk, Svk, Smr1, Smr2) divided by ours. On a shared machine the CPU times are the
steadier figures.
"""

from __future__ import annotations

import argparse
import json
import time
import tracemalloc
import warnings

import numpy as np
from scipy.ndimage import gaussian_filter

from servosurf.metrology import Surface, areal_parameters


def _surface(ny: int, nx: int) -> Surface:
    rng = np.random.default_rng(0)  # fixed seed: a random rough surface
    z = gaussian_filter(rng.normal(size=(ny, nx)), (3, 6), mode="wrap")
    return Surface(20e-9 * z / z.std(), 0.5e-6, 0.5e-6)


def _best(fn, repeat: int = 3) -> tuple[float, float]:
    """Best wall time and best process CPU time of ``repeat`` calls, in s."""
    fn()
    wall, cpu = [], []
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return min(wall), min(cpu)


def _surfalize(s: Surface):
    try:
        import surfalize
    except ImportError:
        return None

    def run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sf = surfalize.Surface(s.z * 1e6, s.dx * 1e6, s.dy * 1e6)
            for name in (
                "Sa Sq Sp Sv Sz Ssk Sku Sdq Sdr Sal Str Sk Spk Svk Smr1 Smr2".split()
            ):
                getattr(sf, name)()

    return run


def run_case(ny: int, nx: int) -> dict:
    s = _surface(ny, nx)
    seconds, cpu = _best(lambda: areal_parameters(s))
    tracemalloc.start()
    areal_parameters(s)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    out = {
        "shape": [ny, nx],
        "seconds": seconds,
        "cpu_seconds": cpu,
        "pixels_per_cpu_s": ny * nx / cpu,
        "peak_memory_bytes": peak,
        "surfalize_seconds": None,
        "speedup_vs_surfalize": None,
    }
    ref = _surfalize(s)
    if ref is not None:
        out["surfalize_seconds"], ref_cpu = _best(ref, repeat=1)
        out["speedup_vs_surfalize"] = ref_cpu / cpu  # CPU time: steadier when shared
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="JSON on stdout")
    args = ap.parse_args()
    results = [run_case(480, 640), run_case(2048, 2048)]
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(
        f"{'map':>11} {'wall s':>7} {'CPU s':>7} {'Mpx/CPU s':>9} {'peak MB':>8} "
        f"{'x surfalize':>11}"
    )
    for r in results:
        ratio = r["speedup_vs_surfalize"]
        print(
            f"{r['shape'][0]:>5}x{r['shape'][1]:<5} {r['seconds']:7.3f} "
            f"{r['cpu_seconds']:7.3f} {r['pixels_per_cpu_s'] / 1e6:9.2f} "
            f"{r['peak_memory_bytes'] / 1e6:8.1f} "
            f"{'' if ratio is None else format(ratio, '.1f'):>11}"
        )


if __name__ == "__main__":
    main()
