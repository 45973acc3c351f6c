"""Whole-face tiling: tiles, Zarr output and dask workers reproduce one big sweep."""

from __future__ import annotations

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.errors import ConfigError
from servosurf.scale import IndexNoise, compute_tile, face_field, simulate_face

zarr = pytest.importorskip("zarr")

RADIUS = 0.3e-3  # m, a small face through the axis
FS = 50e3  # Hz, coarse sampling keeps the test fast


def small_face():
    spec = tp.ToolpathSpec(kind="facing",
                           path=tp.FacingToolpath(r_start=RADIUS, r_end=0.0,
                                                  spindle_speed=50.0,
                                                  feed_per_rev=4e-6))
    return spec, face_field(RADIUS, 3e-6)


def single_shot(spec, field, deviation):
    path = tp.sample(spec, fs=FS)
    path = path.add_z(deviation(path))
    x, y = field.coords()
    init = np.where(x[None, :] ** 2 + y[:, None] ** 2 > RADIUS**2, np.nan, 0.0)
    return tp.sweep(path, spec.tool, field, initial=init).z


def test_tiles_equal_single_shot():
    spec, field = small_face()
    dev = IndexNoise(rms=1e-9, seed=4)
    res = simulate_face(spec, zarr.storage.MemoryStore(), field=field,
                        face_radius=RADIUS, chunk=(64, 48), deviation=dev, fs=FS,
                        max_tile_samples=20_000)
    tiled = res.array[:]
    whole = single_shot(spec, field, dev)
    np.testing.assert_array_equal(tiled, whole)  # bit for bit, NaN off the face
    assert res.n_points == np.isfinite(whole).sum()
    assert res.n_tasks == 4 * 5
    assert np.nanmin(whole) < -5e-6


def test_deviation_beyond_margin_raises():
    spec, field = small_face()
    with pytest.raises(ConfigError, match="depth_margin"):
        compute_tile(spec, field, (90, 110), (90, 110), fs=FS,
                     deviation=IndexNoise(rms=3e-6), depth_margin=1e-7)


def test_index_noise_is_deterministic():
    spec, _ = small_face()
    p = tp.sample(spec, fs=FS)
    a = IndexNoise(rms=1e-9, seed=1)(p)
    b = IndexNoise(rms=1e-9, seed=1)(p.select(np.arange(p.n) % 3 == 0))
    np.testing.assert_array_equal(a[::3], b)
    assert np.std(a) == pytest.approx(1e-9, rel=0.02)
    assert not np.array_equal(a, IndexNoise(rms=1e-9, seed=2)(p))


def test_dask_workers_give_identical_results(tmp_path):
    distributed = pytest.importorskip("distributed")
    spec, field = small_face()
    dev = IndexNoise(rms=1e-9, seed=4)
    local = simulate_face(spec, tmp_path / "local.zarr", field=field,
                          face_radius=RADIUS, chunk=(64, 64), deviation=dev, fs=FS)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        res = simulate_face(spec, str(tmp_path / "dask.zarr"), field=field,
                            face_radius=RADIUS, chunk=(64, 64), deviation=dev, fs=FS,
                            client=client)
    np.testing.assert_array_equal(res.array[:], local.array[:])
    reread = zarr.open_array(str(tmp_path / "dask.zarr"), mode="r")
    np.testing.assert_array_equal(reread[:], local.array[:])
