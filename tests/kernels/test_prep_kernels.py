"""Path preparation kernels (checks, crop marks, slope, buckets) against plain numpy.

The kernels run in parallel chunks; every test uses chunk counts that put chunk
boundaries at awkward places (1, 3, 8, 64 chunks) and paths with gaps.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.errors import ConfigError
from servosurf.kernels._prep import _crop_mask_chunked, _scan_slope
from servosurf.kernels._sweep import N_STAT, _bucket_stats

try:  # tests/ on sys.path (rootdir-relative packages)
    from reference import naive
except ImportError:  # tests/ itself is a package
    from tests.reference import naive

CHUNKS = (1, 3, 8, 64)


def wandering_path(rng, n=5000, turns=9.0, fs=1000.0, gaps=True):
    """Irregular angle steps over several turns, radius crossing a band, gaps."""
    steps = rng.uniform(0.1, 1.9, n)
    theta = rng.uniform(-3, 3) + np.cumsum(steps) * (2 * np.pi * turns / steps.sum())
    r = 2e-3 + 4e-5 * np.sin(np.linspace(0, 7, n)) + rng.normal(0, 1e-7, n)
    z = 1e-6 * rng.standard_normal(n).cumsum() / math.sqrt(n)
    k = np.arange(n, dtype=float)
    if gaps:  # skip runs of samples: non-consecutive times
        k += np.repeat(rng.integers(0, 3, n // 50).cumsum() * 40, 50)[:n]
    return np.ascontiguousarray(k / fs), theta, r, z, fs


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("window", [None, (0.4, -0.05, 0.08), (3.1, -0.2, 0.0)])
def test_crop_mask_matches_reference(seed, window):
    rng = np.random.default_rng(seed)  # random path; results do not depend on it
    t, theta, r, z, fs = wandering_path(rng)
    rmin, rmax, reach = 1.99e-3, 2.01e-3, 5e-6
    want, count = naive.crop_mask(theta, r, rmin, rmax, reach, window)
    assert 0 < count < theta.size  # the case crops something and keeps something
    centre, lo, hi = (0.0, -math.pi, math.pi) if window is None else window
    for n_chunks in CHUNKS:
        keep = np.ones(theta.size, dtype=bool)
        got = _crop_mask_chunked(theta, r, rmin, rmax, reach, window is not None,
                                 centre, lo, hi, n_chunks, keep)
        np.testing.assert_array_equal(keep, want)
        assert got == count


def test_two_samples_with_more_chunks_than_samples():
    t = np.array([0.0, 1e-3])
    theta = np.array([0.0, 1e-3])
    r = np.array([2e-3, 2e-3])
    z = np.array([0.0, 1e-9])
    want = naive.max_slope(t, theta, r, z, 1000.0, 0.0)
    assert want[1] == 0
    for n_chunks in (1, 2, 8):
        bad, slope, k = _scan_slope(t, theta, r, z, 1000.0, 0.0, n_chunks,
                                    np.empty((n_chunks, 2)))
        assert not bad and (slope, k) == want
        keep = np.zeros(2, dtype=bool)
        got = _crop_mask_chunked(theta, r, 1.9e-3, 2.1e-3, 0.0, False, 0.0, -math.pi,
                                 math.pi, n_chunks, keep)
        assert got == 2 and keep.all()


@pytest.mark.parametrize("seed", [0, 1])
def test_scan_slope_matches_reference(seed):
    rng = np.random.default_rng(seed)
    t, theta, r, z, fs = wandering_path(rng)
    for r_skip in (0.0, 2.0e-3):  # 2 mm: skips about half of the intervals
        want = naive.max_slope(t, theta, r, z, fs, r_skip)
        for n_chunks in CHUNKS:
            bad, slope, k = _scan_slope(t, theta, r, z, fs, r_skip, n_chunks,
                                        np.empty((n_chunks, 2)))
            assert not bad
            assert (slope, k) == want


@pytest.mark.parametrize("where", ["first", "boundary", "last"])
@pytest.mark.parametrize("fault, message", [
    ("nan_t", "finite"), ("nan_theta", "finite"), ("inf_r", "finite"),
    ("nan_z", "finite"),
    ("repeat_theta", "strictly increasing"), ("negative_r", ">= 0 m"),
])
def test_path_faults_are_found_anywhere(where, fault, message):
    rng = np.random.default_rng(3)
    t, theta, r, z, fs = wandering_path(rng, n=40000, gaps=False)
    theta, r, z = theta.copy(), r.copy(), z.copy()
    n_chunks = 8
    step = (t.size + n_chunks - 1) // n_chunks
    i = {"first": 0, "boundary": 3 * step, "last": t.size - 1}[where]
    t = t.copy()
    if fault == "repeat_theta":
        i = max(i, 1)
    if fault == "nan_t":
        t[i] = np.nan
    elif fault == "nan_theta":
        theta[i] = np.nan
    elif fault == "inf_r":
        r[i] = np.inf
    elif fault == "nan_z":
        z[i] = np.nan
    elif fault == "repeat_theta":
        theta[i] = theta[i - 1]
    else:
        r[i] = -1e-9
    bad = _scan_slope(t, theta, r, z, fs, 0.0, n_chunks, np.empty((n_chunks, 2)))[0]
    assert bad
    path = tp.SampledPath(t, theta, r, z, fs)
    field = tp.Field(pitch_x=1e-6, pitch_y=1e-6, nx=3, ny=3, center_x=2e-3)
    with pytest.raises(ConfigError, match=message):
        tp.sweep(path, tp.Tool(), field)


def test_bucket_ranges_match_reference():
    rng = np.random.default_rng(4)
    t, theta, r, z, fs = wandering_path(rng)
    gap = np.zeros(theta.size, dtype=bool)
    gap[np.flatnonzero(np.diff(t) > 1.5 / fs)] = True
    theta_ref = theta[0] - 0.3
    nb = int(math.floor((theta[-1] - theta_ref) / (2 * math.pi))) + 1
    bidx = np.zeros((nb, 4), dtype=np.int64)
    bstat = np.zeros((nb, N_STAT))
    _bucket_stats(theta, r, z, gap, theta_ref, bidx, bstat)
    first, end = naive.bucket_ranges(theta, theta_ref, nb)
    n = theta.size
    np.testing.assert_array_equal(bidx[:, 0], np.maximum(first - 1, 0))
    np.testing.assert_array_equal(bidx[:, 1], np.minimum(end, n - 1))
    for j in range(nb):  # bounds cover every sample that can bracket a crossing
        lo, hi = bidx[j, 0], bidx[j, 1]
        seg_r, seg_z = r[lo:hi + 1], z[lo:hi + 1]
        assert bstat[j, 0] >= seg_r.min() and bstat[j, 1] <= seg_r.max()
        assert bstat[j, 2] >= seg_z.min()
        inner = slice(first[j], end[j])
        if end[j] > first[j]:
            assert bstat[j, 0] <= r[inner].min() and bstat[j, 1] >= r[inner].max()
            assert bstat[j, 2] <= z[inner].min()


def test_crop_mask_at_every_chunk_boundary_phase():
    # radii in, out, out, out, in, ...: sample 1 of each period is kept through the
    # interval before it, sample 3 through the one after it, sample 2 not at all;
    # the chunk boundaries (1667, 3334 for 3 chunks; multiples of 625 for 8, of 79
    # for 64) fall on every phase of the pattern
    n = 5000
    theta = np.linspace(0.0, 20.0, n)
    r = np.where(np.arange(n) % 4 == 0, 2e-3, 3e-3)
    want, count = naive.crop_mask(theta, r, 1.99e-3, 2.01e-3, 5e-6)
    assert 0 < count < n
    for n_chunks in CHUNKS:
        keep = np.zeros(n, dtype=bool)
        got = _crop_mask_chunked(theta, r, 1.99e-3, 2.01e-3, 5e-6, False, 0.0,
                                 -math.pi, math.pi, n_chunks, keep)
        np.testing.assert_array_equal(keep, want)
        assert got == count


@pytest.mark.parametrize("n_tests", [1, 7, 64, 5000])
def test_hit_fraction_matches_reference(n_tests):
    from servosurf.kernels._prep import _hit_fraction

    rng = np.random.default_rng(5)
    t, theta, r, z, fs = wandering_path(rng)
    window = (0.4, -0.05, 0.08)
    rmin, rmax, reach = 1.99e-3, 1.995e-3, 5e-6
    m = theta.size - 1
    g = (math.sqrt(5) - 1) / 2
    idx = np.minimum((np.mod(np.arange(n_tests) * g, 1.0) * m).astype(int), m - 1)
    keep_all, _ = naive.crop_mask(theta, r, rmin, rmax, reach, window)
    hit = np.zeros(m, dtype=bool)  # per interval, from the reference marks
    rl = np.minimum(r[:-1], r[1:])
    rh = np.maximum(r[:-1], r[1:])
    rel = np.mod(theta[:-1] - 0.4 + np.pi, 2 * np.pi) - np.pi
    dth = np.diff(theta)
    hit = (((rl <= rmax + reach) & (rh >= rmin - reach)) | (rl <= reach - rmin)) & (
        ((rel <= 0.08) & (rel + dth >= -0.05)) | (rel - 2 * np.pi + dth >= -0.05)
        | (dth >= 2 * np.pi))
    assert keep_all[:-1][hit].all()  # the per-interval marks agree with the mask
    got = _hit_fraction(theta, r, n_tests, rmin, rmax, reach, True, *window)
    np.testing.assert_allclose(got, hit[idx].mean(), rtol=0, atol=1e-15)
    if n_tests == 5000:
        assert 0.0 < got < 1.0
        assert abs(got - hit.mean()) < 0.05  # spread over the whole path


def test_crop_estimate_does_not_alias_with_the_revolution():
    # 64 samples per revolution: every 64th interval sits at the same angle, so a
    # strided estimate would see the whole path hitting; the path must still be
    # cropped, and the clearance check must see only the cropped part (the steep
    # steps lie half a turn away from the field)
    import warnings

    from servosurf.toolpath._sweep import prepare_path

    n = 70000
    k = np.arange(n)
    theta = 2 * np.pi * k / 64
    fs = 1280.0
    r = np.full(n, 2e-3)
    near_pi = np.abs(np.mod(theta, 2 * np.pi) - np.pi) < 0.5
    z = np.where(near_pi & (k % 2 == 1), 1e-4, 0.0)
    path = tp.SampledPath(k / fs, theta, r, z, fs)
    field = tp.Field(pitch_x=1e-6, pitch_y=1e-6, nx=8, ny=8, center_x=2e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prep = prepare_path(path, tp.Tool(), field, check=True)
    assert prep.path.n < 0.2 * n


def test_uniform_initial_equals_the_same_initial_array():
    # a scalar pre-cut height is written by the kernel row by row; an array is
    # read from the output: both give the same map, bit for bit
    rng = np.random.default_rng(6)
    t, theta, r, z, fs = wandering_path(rng, gaps=False)
    path = tp.SampledPath(t, theta, r, z - 2e-6, fs)
    field = tp.Field(pitch_x=2e-6, pitch_y=2e-6, nx=24, ny=20, center_x=2e-3)
    tool = tp.Tool(clearance_angle=math.pi / 2)
    cut = tp.sweep(path, tool, field, initial=np.inf).z
    assert np.isfinite(cut).all()  # the path reaches every pixel
    level = float(np.median(cut))  # about half the pixels stay at this level
    for v in (0.0, level, np.inf):
        a = tp.sweep(path, tool, field, initial=v).z
        b = tp.sweep(path, tool, field, initial=np.full(field.shape, v)).z
        np.testing.assert_array_equal(a, b)
    a = tp.sweep(path, tool, field, initial=level).z
    assert 0 < np.count_nonzero(a == level) < a.size
