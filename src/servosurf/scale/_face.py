"""Whole-workpiece simulation: tiles streamed to a chunked on-disk Zarr array.

Every chunk of the output array is one task. A task samples the toolpath only in the
time and angular windows that can cut its pixels (with a depth-based reach), adds the
deviation, runs the swept-arc kernel with the whole field's pixel coordinates and
writes its chunk. Tiles therefore reproduce a single whole-field run bit for bit.
Tasks run in this process or, one task per chunk, on a dask ``distributed.Client``.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._progress import bar
from .._validation import check_no_kwargs, check_positive
from ..errors import ConfigError
from ..toolpath._paths import ToolpathSpec
from ..toolpath._sample import SampledPath, count_samples, field_reach, sample
from ..toolpath._sweep import _threads, prepare_path, run_kernel
from ..toolpath._tool import Field
from ._memory import reuse_freed_memory

__all__ = ["face_field", "simulate_face", "compute_tile", "FaceResult", "chunk_slices",
           "IndexNoise", "face_preview", "grid_attributes"]

#: Split a tile until its windowed path has at most this many samples (memory).
MAX_TILE_SAMPLES = 4_000_000


def face_field(radius: float, pitch: float) -> Field:
    """A square field centred on the spindle axis that covers a face of ``radius``.

    Parameters
    ----------
    radius : float
        Face radius, in m.
    pitch : float
        Grid pitch, in m.

    Returns
    -------
    Field
        ``2 * ceil(radius / pitch) + 1`` pixels per side, pixel centres on multiples
        of ``pitch`` (the axis is a pixel centre).
    """
    radius = check_positive(radius, name="radius")
    pitch = check_positive(pitch, name="pitch")
    n = 2 * math.ceil(radius / pitch - 1e-9) + 1
    return Field(pitch_x=pitch, pitch_y=pitch, nx=n, ny=n, center_x=0.0, center_y=0.0)


def chunk_slices(shape: tuple[int, int], chunk: tuple[int, int]):
    """Half-open (rows, cols) ranges of the chunks of an array, row-major.

    Parameters
    ----------
    shape : tuple of int
        (ny, nx).
    chunk : tuple of int
        Chunk shape (rows, cols).

    Returns
    -------
    list of tuple
        ``((r0, r1), (c0, c1))`` per chunk.
    """
    ny, nx = shape
    cy, cx = chunk
    return [((r, min(r + cy, ny)), (c, min(c + cx, nx)))
            for r in range(0, ny, cy) for c in range(0, nx, cx)]


@dataclass(frozen=True)
class IndexNoise:
    """Deterministic white height noise keyed on the global sample number.

    A stand-in for a vibration realisation that tiles can evaluate independently:
    sample k always gets the same deviation, whichever window it was sampled in.

    Parameters
    ----------
    rms : float, default: 1e-9
        RMS deviation, in m (uniform distribution of width rms * sqrt(12)).
    seed : int, default: 0
        Seed mixed into the hash.

    Notes
    -----
    splitmix64 of (sample number + seed * golden ratio); not a PSD-shaped noise.
    """

    rms: float = 1e-9
    seed: int = 0

    def __call__(self, path: SampledPath) -> np.ndarray:
        """Deviation in m for every sample of ``path``, shape (path.n,)."""
        from ..kernels._paths import _index_noise

        key = np.uint64((int(self.seed) * 0x9E3779B97F4A7C15) % 2**64)
        out = np.empty(path.n)
        scale = float(self.rms) * math.sqrt(12.0)
        _index_noise(path.t, float(path.fs), key, scale, out)
        return out


def _initial_tile(field, rows, cols, initial, face_radius):
    shape = (rows[1] - rows[0], cols[1] - cols[0])
    if isinstance(initial, np.ndarray):
        out = np.array(initial[rows[0]:rows[1], cols[0]:cols[1]], dtype=np.float64)
    else:
        out = np.full(shape, float(initial))
    if face_radius is not None:
        x = field.x0 + (cols[0] + np.arange(shape[1])) * field.pitch_x
        y = field.y0 + (rows[0] + np.arange(shape[0])) * field.pitch_y
        out[(x[None, :] ** 2 + y[:, None] ** 2) > face_radius**2] = np.nan
    return out


def compute_tile(spec: ToolpathSpec, field: Field, rows: tuple[int, int],
                 cols: tuple[int, int], *, initial: float | np.ndarray = 0.0,
                 face_radius: float | None = None,
                 deviation: Callable[[SampledPath], np.ndarray] | None = None,
                 depth_margin: float = 1e-6, fs: float | None = None,
                 max_tile_samples: int = MAX_TILE_SAMPLES,
                 n_threads: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """Machined heights of one tile of ``field``.

    Parameters
    ----------
    spec : ToolpathSpec
        Toolpath, tool (the field of ``spec`` is ignored).
    field : Field
        The whole grid.
    rows, cols : tuple of int
        Half-open row and column ranges of the tile.
    initial : float or ndarray of shape field.shape, default: 0.0
        Pre-cut height, in m.
    face_radius : float, optional
        Pixels farther than this from the axis (m) are not workpiece: NaN.
    deviation : callable, optional
        ``deviation(path) -> dz`` (m, shape (path.n,)) added to the tool height. It
        must depend only on the sample times (``path.index``) so that every tile sees
        the same deviation at the same sample.
    depth_margin : float, default: 1e-6
        How far the deviation may push the tool below its commanded depth, in m. The
        reach of the sampled windows follows from the depth plus this margin; a
        deeper sample raises :class:`ConfigError`.
    fs : float, optional
        Sampling rate in Hz (default 199.6 kHz).
    max_tile_samples : int, default: 4_000_000
        Tiles whose windowed path would be longer are computed in several time
        windows, carrying the running minimum (near the axis every revolution
        crosses the tile at all angles).
    n_threads : int, optional
        Numba threads.

    Returns
    -------
    z : ndarray of shape (rows, cols)
        Heights in m.
    stats : dict
        ``n_samples`` (samples generated), ``n_points`` (pixels computed),
        ``n_subtiles`` (time windows).
    """
    from ..toolpath._sample import FS_DEFAULT

    fs = FS_DEFAULT if fs is None else fs
    out = _initial_tile(field, rows, cols, initial, face_radius)
    stats = {"n_samples": 0, "n_points": int(np.isfinite(out).sum()) if out.size else 0,
             "n_subtiles": 0}
    if not np.any(~np.isnan(out)):
        return out, stats
    tool = spec.tool
    top = float(np.nanmax(out))
    if not math.isfinite(top):
        reach = tool.half_width
        z_floor = -math.inf
    else:
        depth = top + spec.path.max_depth
        reach = field_reach(tool, depth, depth_margin=depth_margin)
        z_floor = -(spec.path.max_depth + depth_margin)
    sf = field.subfield(rows[0], rows[1], cols[0], cols[1])
    n = count_samples(spec, fs=fs, field=sf, reach=reach)
    windows: list[tuple[float, float] | None] = [None]
    if n > max_tile_samples:
        # Near the axis every revolution crosses the tile at all angles: sample the
        # tile's time span in pieces and carry the running minimum (the envelope is a
        # minimum, so this is exact; neighbouring pieces share their end samples).
        rmin, rmax = sf.radial_range()
        span = spec.path.time_span_for_radius(rmin - reach, rmax + reach)
        if span is not None:
            k = math.ceil(n / max_tile_samples)
            edges = np.linspace(span[0], span[1], k + 1)
            windows = [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:],
                                                           strict=True)]
    # every parallel stage of the tile (sampling, interleave, kernel) uses n_threads
    with _threads(n_threads):
        for win in windows:
            cap = max(2 * max_tile_samples, n if win is None else 0, 1)
            path = sample(spec, fs=fs, field=sf, reach=reach, t_window=win,
                          max_samples=cap)
            stats["n_samples"] += path.n
            stats["n_subtiles"] += 1
            if path.n < 2:
                continue
            if deviation is not None:
                path = path.add_z(deviation(path))
            if path.z.min() < z_floor - 1e-15:
                below = -(path.z.min() - z_floor)
                raise ConfigError(
                    f"the deviation takes the tool {below:.3g} m below the commanded "
                    f"depth plus the {depth_margin:g} m margin: a vibration that "
                    "large is implausible (servosurf face: check --bandwidth and "
                    "--mass, or --no-vibration; Python: raise depth_margin)"
                )
            prep = prepare_path(path, tool, field, rows=rows, cols=cols, crop=False)
            if prep is None:
                continue
            run_kernel(prep, tool, field, out, n_threads=n_threads, row0=rows[0],
                       col0=cols[0])
    return out, stats


def _open_array(store, shape, chunk, mode):
    import zarr
    from zarr.codecs import BloscCodec

    if mode == "w":
        # Blosc lz4 with byte shuffle: 20x faster than zarr's default zstd on height
        # maps and a better ratio (about 0.7 on nm-rough facing).
        comp = [BloscCodec(cname="lz4", clevel=1, shuffle="shuffle")]
        return zarr.create_array(store=store, shape=shape, chunks=chunk, dtype="f8",
                                 fill_value=np.nan, overwrite=True, compressors=comp,
                                 dimension_names=("y", "x"))
    return zarr.open_array(store=store, mode=mode)


def _write(arr, rows, cols, z) -> None:
    arr[rows[0]:rows[1], cols[0]:cols[1]] = z


def _chunk_task(spec, field, rows, cols, store, kwargs):
    """Dask task: compute one chunk and write it into the Zarr store at ``store``."""
    reuse_freed_memory()
    t0 = time.perf_counter()
    z, stats = compute_tile(spec, field, rows, cols, **kwargs)
    arr = _open_array(store, None, None, "r+")
    arr[rows[0]:rows[1], cols[0]:cols[1]] = z
    stats["seconds"] = time.perf_counter() - t0
    return stats


@dataclass(frozen=True)
class FaceResult:
    """Outcome of :func:`simulate_face`.

    Parameters
    ----------
    array : zarr.Array
        Heights in m, shape ``field.shape`` (rows = y, columns = x), NaN off the face.
    field : Field
        The grid (pitch in m; pixel (i, j) at x0 + j dx, y0 + i dy).
    seconds : float
        Wall time, in s.
    n_points : int
        Pixels computed (on the face).
    n_samples : int
        Path samples generated over all tiles.
    n_tasks : int
        Chunks (tasks).
    """

    array: Any
    field: Field
    seconds: float
    n_points: int
    n_samples: int
    n_tasks: int

    @property
    def points_per_s(self) -> float:
        """Throughput in pixels per second."""
        return self.n_points / self.seconds if self.seconds > 0 else math.inf


def simulate_face(spec: ToolpathSpec, store: Any, *, field: Field | None = None,
                  face_radius: float | None = None,
                  chunk: tuple[int, int] = (1024, 1024),
                  initial: float | np.ndarray = 0.0,
                  deviation: Callable[[SampledPath], np.ndarray] | None = None,
                  depth_margin: float = 1e-6, fs: float | None = None,
                  client: Any = None, n_threads: int | None = None,
                  max_tile_samples: int = MAX_TILE_SAMPLES, **kwargs) -> FaceResult:
    """Simulate a whole face tile by tile into a chunked Zarr array.

    Parameters
    ----------
    spec : ToolpathSpec
        Toolpath and tool.
    store : str, Path or zarr store
        Where the array goes: a directory (``.zarr``) or any zarr store (for example
        ``zarr.storage.MemoryStore()``). With a dask client it must be a directory
        that the workers can reach.
    field : Field, optional
        The grid; default ``spec.field``. See :func:`face_field` for a whole face.
    face_radius : float, optional
        Workpiece radius in m; pixels outside stay NaN and are not computed.
    chunk : tuple of int, default: (1024, 1024)
        Chunk (= task) shape, rows x columns.
    initial : float or ndarray of shape field.shape, default: 0.0
        Pre-cut height in m.
    deviation : callable, optional
        ``deviation(path) -> dz`` in m, a function of the sample times only (see
        :func:`compute_tile`). Must be picklable with a dask client.
    depth_margin : float, default: 1e-6
        Bound on how far the deviation lowers the tool, in m.
    fs : float, optional
        Sampling rate, in Hz (default 199.6 kHz).
    client : distributed.Client or str, optional
        Run one task per chunk on this dask client (or scheduler address).
    n_threads : int, optional
        Numba threads per task, in process and on the dask workers (default:
        numba's default, all cores of the process's machine).
    max_tile_samples : int, default: 4_000_000
        Memory bound per (sub-)tile path.

    Returns
    -------
    FaceResult
        The array and run statistics.

    Raises
    ------
    ConfigError
        On bad arguments.
    TypeError
        On unknown keyword arguments.

    Notes
    -----
    Peak memory is one chunk of output plus one windowed path (at most
    ``max_tile_samples`` samples, about 50 bytes each while sampling) per worker.
    The run calls :func:`reuse_freed_memory` (glibc heap thresholds) in each process
    so that tile buffers are reused instead of page-faulted in again.
    """
    check_no_kwargs(kwargs, name="simulate_face")
    if not isinstance(spec, ToolpathSpec):
        raise ConfigError(f"spec must be a ToolpathSpec, got {type(spec).__name__}")
    field = spec.field if field is None else field
    if isinstance(initial, np.ndarray) and initial.shape != field.shape:
        raise ConfigError(f"initial must have shape {field.shape}, got {initial.shape}")
    chunk = (int(chunk[0]), int(chunk[1]))
    if min(chunk) < 1:
        raise ConfigError(f"chunk must be positive, got {chunk}")
    if isinstance(store, Path):
        store = str(store)
    t0 = time.perf_counter()
    reuse_freed_memory()
    arr = _open_array(store, field.shape, chunk, "w")
    arr.attrs.update(grid_attributes(field, face_radius=face_radius, kind=spec.kind))
    tasks = chunk_slices(field.shape, chunk)
    kw = dict(initial=initial, face_radius=face_radius, deviation=deviation,
              depth_margin=depth_margin, fs=fs, max_tile_samples=max_tile_samples)
    n_points = n_samples = 0
    if client is None:
        # One writer thread compresses and stores chunk k while chunk k + 1 is
        # computed (the kernels release the GIL); at most two chunks wait.
        pending: deque = deque()
        with ThreadPoolExecutor(max_workers=1) as writer:
            for rows, cols in bar(tasks, total=len(tasks), desc="tiles"):
                z, stats = compute_tile(spec, field, rows, cols, n_threads=n_threads,
                                        **kw)
                if stats["n_points"]:
                    while len(pending) >= 2:
                        pending.popleft().result()
                    pending.append(writer.submit(_write, arr, rows, cols, z))
                n_points += stats["n_points"]
                n_samples += stats["n_samples"]
            while pending:
                pending.popleft().result()
    else:
        if not isinstance(store, str):
            raise ConfigError("with a dask client, store must be a directory path")
        from distributed import Client, as_completed

        own = isinstance(client, str)
        cl = Client(client) if own else client
        try:
            kw_task = dict(kw, n_threads=n_threads)
            futs = [cl.submit(_chunk_task, spec, field, rows, cols, store, kw_task,
                              pure=False) for rows, cols in tasks]
            for fut in bar(as_completed(futs), total=len(futs), desc="tiles"):
                stats = fut.result()
                n_points += stats["n_points"]
                n_samples += stats["n_samples"]
        finally:
            if own:
                cl.close()
    return FaceResult(array=arr, field=field, seconds=time.perf_counter() - t0,
                      n_points=n_points, n_samples=n_samples, n_tasks=len(tasks))


def grid_attributes(field: Field, *, face_radius: float | None = None,
                    kind: str = "") -> dict[str, Any]:
    """Metadata stored with a height array: unit, pixel size, origin, axes.

    Parameters
    ----------
    field : Field
        The grid of the array.
    face_radius : float, optional
        Face radius in m (pixels beyond it are NaN).
    kind : str, optional
        Toolpath kind.

    Returns
    -------
    dict
        JSON-ready attributes, every length in m: ``unit`` ("m", the heights),
        ``dx_m``/``dy_m`` (pixel size along columns/rows), ``x0_m``/``y0_m`` (centre
        of pixel (0, 0) in the workpiece frame, spindle axis at (0, 0)), ``axes``
        (rows are y, columns are x) and ``invalid`` (NaN: not cut or off the face).
    """
    attrs: dict[str, Any] = {
        "unit": "m",
        "dx_m": float(field.pitch_x),
        "dy_m": float(field.pitch_y),
        "x0_m": float(field.x0),
        "y0_m": float(field.y0),
        "axes": ["y", "x"],
        "origin": "x0_m, y0_m: centre of pixel (0, 0); pixel (i, j) at "
                  "(x0_m + j dx_m, y0_m + i dy_m); the spindle axis is at (0, 0)",
        "invalid": "NaN (not cut, or off the face)",
        "writer": "servosurf",
    }
    if face_radius is not None:
        attrs["face_radius_m"] = float(face_radius)
    if kind:
        attrs["toolpath_kind"] = kind
    return attrs


def face_preview(array: Any, *, max_pixels: int = 1000,
                 window: int = 1024) -> tuple[np.ndarray, int, dict[str, float]]:
    """Area-averaged preview of a (chunked) height array and its statistics.

    Each preview pixel is the mean of the valid heights of a ``step`` x ``step``
    block (NaN when fewer than half of the block's pixels are valid), so the
    preview shows the surface instead of a moire of every ``step``-th pixel. The
    array is read in windows of about ``window`` x ``window`` pixels (bounded
    memory); the same pass gives the statistics of every valid pixel.

    Parameters
    ----------
    array : array-like of shape (ny, nx)
        Heights in m (a zarr array, or any array sliced as ``a[r0:r1, c0:c1]``).
    max_pixels : int, default: 1000
        Largest preview side, in pixels.
    window : int, default: 1024
        Read window side, in pixels (rounded to a multiple of ``step``).

    Returns
    -------
    preview : ndarray of shape (ceil(ny / step), ceil(nx / step))
        Block means in m. Block (I, J) covers pixels ``I*step .. I*step+step-1``
        (rows) and the same for columns: its centre lies (step - 1) / 2 pixels
        beyond the first pixel's.
    step : int
        Block side, ``ceil(max(ny, nx) / max_pixels)``.
    stats : dict
        ``valid_points``, ``mean_m``, ``sq_m`` (RMS about the mean), ``min_m``,
        ``max_m`` over every valid pixel (m; NaN without valid pixels).
    """
    ny, nx = (int(v) for v in array.shape)
    step = max(1, math.ceil(max(ny, nx) / int(max_pixels)))
    win = step * max(1, int(window) // step)
    out = np.full((math.ceil(ny / step), math.ceil(nx / step)), np.nan)
    ref = None
    n, s1, s2 = 0, 0.0, 0.0
    zmin, zmax = math.inf, -math.inf
    for r0 in range(0, ny, win):
        for c0 in range(0, nx, win):
            z = np.asarray(array[r0:r0 + win, c0:c0 + win], dtype=float)
            ok = np.isfinite(z)
            if not ok.any():
                continue
            v = z[ok]
            if ref is None:
                ref = float(v[0])  # sums about it: no cancellation on a deep face
            d = v - ref
            n += v.size
            s1 += float(d.sum())
            s2 += float(np.dot(d, d))
            zmin, zmax = min(zmin, float(v.min())), max(zmax, float(v.max()))
            hy, hx = z.shape
            by, bx = math.ceil(hy / step), math.ceil(hx / step)
            pad = ((0, by * step - hy), (0, bx * step - hx))
            total = np.pad(np.where(ok, z, 0.0), pad).reshape(by, step, bx, step)
            count = np.pad(ok, pad).reshape(by, step, bx, step).sum(axis=(1, 3))
            area = np.pad(np.ones_like(ok), pad).reshape(by, step, bx, step)
            area = area.sum(axis=(1, 3))
            block = total.sum(axis=(1, 3)) / np.maximum(count, 1)
            i0, j0 = r0 // step, c0 // step
            out[i0:i0 + by, j0:j0 + bx] = np.where(2 * count >= area, block, np.nan)
    if n:
        mean = s1 / n
        stats = {"valid_points": n, "mean_m": ref + mean,
                 "sq_m": math.sqrt(max(s2 / n - mean * mean, 0.0)),
                 "min_m": zmin, "max_m": zmax}
    else:
        stats = {"valid_points": 0, "mean_m": math.nan, "sq_m": math.nan,
                 "min_m": math.nan, "max_m": math.nan}
    return out, step, stats
