"""Swept-arc kernels against the plain-numpy reference and against each other."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import servosurf.toolpath as tp

try:  # tests/ on sys.path (rootdir-relative packages)
    from reference import ATOL_IDENTICAL, ATOL_REFERENCE, naive
except ImportError:  # tests/ itself is a package
    from tests.reference import ATOL_IDENTICAL, ATOL_REFERENCE, naive

# A tool whose clearance never triggers the warning on random paths.
STEEP_TOOL = tp.Tool(clearance_angle=math.pi / 2)


def naive_sweep(path, tool, field, initial=None):
    """Reference envelope for a SampledPath on a Field (plain numpy)."""
    x, y = field.coords()
    init = np.zeros(field.shape) if initial is None else np.broadcast_to(
        np.asarray(initial, dtype=float), field.shape)
    wav = tool.waviness_table() if tool.has_waviness else None
    return naive.sweep(path.t, path.theta, path.r, path.z, path.fs, x, y,
                       tool.nose_radius, tool.half_width, init, wav)


def check_all(path, tool, field, initial=None):
    """Pruned == exhaustive (to 1 fm) == reference (to 1 pm); returns the map."""
    a = tp.sweep(path, tool, field, initial=initial, method="pruned").z
    b = tp.sweep(path, tool, field, initial=initial, method="exhaustive").z
    ref = naive_sweep(path, tool, field, initial)
    np.testing.assert_array_equal(np.isnan(a), np.isnan(ref))
    np.testing.assert_allclose(a, b, rtol=0, atol=ATOL_IDENTICAL)  # 1 fm
    np.testing.assert_allclose(a, ref, rtol=0, atol=ATOL_REFERENCE)  # 1 pm
    return a


def random_path(rng, n=1500, *, monotone_r=True, turns=6.0, r0=2e-3, gaps=False):
    """A random sampled path: irregular angle steps, radius and height wander."""
    steps = rng.uniform(0.2, 1.8, n - 1)
    theta = np.concatenate(([rng.uniform(-3, 3)], steps)).cumsum()
    theta = theta[0] + (theta - theta[0]) * (2 * np.pi * turns / (theta[-1] - theta[0]))
    if monotone_r:
        r = r0 - np.concatenate(([0.0], rng.uniform(0, 2e-7, n - 1).cumsum()))
    else:
        r = r0 + np.concatenate(([0.0], rng.normal(0, 3e-7, n - 1).cumsum()))
    z = -3e-6 + 2e-6 * rng.standard_normal(n).cumsum() / np.sqrt(n)
    fs = 1000.0
    t = np.arange(n) / fs
    path = tp.SampledPath(t, theta, r, z, fs)
    if gaps:
        keep = np.ones(n, dtype=bool)
        for s in rng.integers(10, n - 60, 5):
            keep[s:s + rng.integers(2, 40)] = False
        path = path.select(keep)
    return path


def facing_case(nx=12, ny=9, pitch=0.5e-6, center=(5e-3, 0.0), **kw):
    spec = tp.ToolpathSpec(
        kind="facing",
        path=tp.FacingToolpath(r_start=5.06e-3, r_end=4.94e-3, **kw),
        tool=tp.Tool(),
        field=tp.Field(pitch_x=pitch, pitch_y=pitch, nx=nx, ny=ny,
                       center_x=center[0], center_y=center[1]),
    )
    return spec


# ---------------------------------------------------------------------------- tests
def test_facing_matches_reference():
    spec = facing_case()
    path = tp.sample(spec, field=spec.field)
    z = check_all(path, spec.tool, spec.field)
    assert np.all(z < 0)


def test_facing_full_path_equals_windowed_path():
    spec = facing_case(nx=6, ny=5)
    full = tp.sample(spec)
    win = tp.sample(spec, field=spec.field)
    assert win.n < full.n / 20
    a = tp.sweep(full, spec.tool, spec.field).z
    b = tp.sweep(win, spec.tool, spec.field).z
    np.testing.assert_array_equal(a, b)


def test_lenslet_matches_reference():
    spec = tp.ToolpathSpec(
        kind="lenslet",
        path=tp.LensletToolpath(ring_count=2),
        tool=tp.Tool(),
        field=tp.Field(pitch_x=12e-6, pitch_y=12e-6, nx=15, ny=13, center_x=10e-3),
    )
    path = tp.sample(spec, field=spec.field, fs=20e3)
    z = check_all(path, spec.tool, spec.field)
    assert z.min() == pytest.approx(-5e-6, abs=5e-9)  # 5 nm


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("monotone_r", [True, False])
def test_random_paths_match_reference(seed, monotone_r):
    rng = np.random.default_rng(seed)  # the paths depend on the seed, results do not
    path = random_path(rng, monotone_r=monotone_r, gaps=bool(seed % 2))
    field = tp.Field(pitch_x=3e-5, pitch_y=2e-5, nx=7, ny=6,
                     center_x=1.99e-3 * math.cos(0.3), center_y=1.99e-3 * math.sin(0.3))
    initial = rng.uniform(-2e-6, 0.0, field.shape)
    initial[0, 0] = np.nan  # start
    initial[-1, -1] = np.nan  # end
    initial[2, :] = np.nan  # a slice
    z = check_all(path, STEEP_TOOL, field, initial)
    assert np.isnan(z[2]).all() and np.isfinite(z[3]).all()


def test_single_pixel_and_single_revolution():
    rng = np.random.default_rng(7)
    path = random_path(rng, n=200, turns=1.0)
    field = tp.Field(nx=1, ny=1, center_x=1.9999e-3, center_y=1e-6)
    check_all(path, STEEP_TOOL, field)
    field = tp.Field(pitch_x=1e-5, pitch_y=1e-5, nx=5, ny=4, center_x=-1.99e-3,
                     center_y=0.0)
    check_all(path, STEEP_TOOL, field)


def test_two_samples_and_initial_inf():
    path = tp.SampledPath(t=[0.0, 1e-3], theta=[-0.1, 0.1], r=[1e-3, 1e-3],
                          z=[0.0, -1e-6], fs=1000.0)
    field = tp.Field(pitch_x=1e-5, pitch_y=1e-5, nx=5, ny=3, center_x=1e-3)
    z = check_all(path, STEEP_TOOL, field, initial=np.inf)
    assert np.isfinite(z[1]).all()
    empty = tp.SampledPath(t=[0.0], theta=[0.0], r=[1e-3], z=[0.0], fs=1000.0)
    out = tp.sweep(empty, STEEP_TOOL, field, initial=1e-6).z
    np.testing.assert_array_equal(out, 1e-6)


def test_facing_through_the_axis_uses_the_arc_across_it():
    spec = tp.ToolpathSpec(
        kind="facing",
        path=tp.FacingToolpath(r_start=60e-6, r_end=0.0, feed_per_rev=4e-6,
                               spindle_speed=50.0),
        tool=tp.Tool(),
        field=tp.Field(pitch_x=9e-6, pitch_y=9e-6, nx=9, ny=9, center_x=0.0),
    )
    path = tp.sample(spec, fs=20e3)
    z = check_all(path, spec.tool, spec.field)
    # the centre is cut to the full depth by the part of the arc across the axis
    assert z[4, 4] == pytest.approx(-5e-6, abs=1e-9)  # 1 nm


def test_waviness_matches_reference():
    ang = np.linspace(-1.2, 1.2, 41)
    dev = 20e-9 * np.sin(7 * ang)
    tool = tp.Tool(waviness_angle=tuple(ang), waviness_deviation=tuple(dev))
    spec = facing_case(nx=8, ny=5)
    path = tp.sample(spec, field=spec.field)
    z = check_all(path, tool, spec.field)
    flat = tp.sweep(path, tp.Tool(), spec.field).z
    # near the tip dR(phi) ~ 20 nm * 7 phi, phi ~ 2e-3 rad at the cusps: ~0.2 nm
    assert np.abs(z - flat).max() > 1e-10  # the waviness shows (> 0.1 nm)


def test_tiles_reproduce_the_whole_field_bit_for_bit():
    rng = np.random.default_rng(3)
    path = random_path(rng, n=3000, turns=10)
    field = tp.Field(pitch_x=2e-5, pitch_y=2e-5, nx=13, ny=11,
                     center_x=1.99e-3, center_y=0.0)
    whole = tp.sweep(path, STEEP_TOOL, field).z
    tiled = np.empty_like(whole)
    for r0, r1 in ((0, 4), (4, 11)):
        for c0, c1 in ((0, 5), (5, 9), (9, 13)):
            s = tp.sweep(path, STEEP_TOOL, field, rows=(r0, r1), cols=(c0, c1))
            tiled[r0:r1, c0:c1] = s.z
            xs, ys = s.coords()
            assert xs[0] == field.coords()[0][c0] or math.isclose(
                xs[0], field.coords()[0][c0], abs_tol=1e-18)
    np.testing.assert_array_equal(tiled, whole)


def test_threads_do_not_change_the_result():
    spec = facing_case(nx=32, ny=16)
    path = tp.sample(spec, field=spec.field)
    a = tp.sweep(path, spec.tool, spec.field, n_threads=1).z
    b = tp.sweep(path, spec.tool, spec.field, n_threads=2).z
    np.testing.assert_array_equal(a, b)


def test_kernels_run_without_jit():
    """The kernel bodies also run as plain Python (NUMBA_DISABLE_JIT=1, tiny case)."""
    code = textwrap.dedent("""
        import numpy as np, servosurf.toolpath as tp
        spec = tp.ToolpathSpec(kind="facing",
            path=tp.FacingToolpath(r_start=1.004e-3, r_end=0.996e-3, feed_per_rev=2e-6,
                                   spindle_speed=20.0),
            field=tp.Field(pitch_x=1e-6, pitch_y=1e-6, nx=3, ny=2, center_x=1e-3))
        path = tp.sample(spec, field=spec.field, fs=4000.0)
        a = tp.sweep(path, spec.tool, spec.field, method="pruned").z
        b = tp.sweep(path, spec.tool, spec.field, method="exhaustive").z
        assert np.array_equal(a, b), (a, b)
        print(repr(a.tolist()))
    """)
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    nojit = np.array(eval(res.stdout))  # noqa: S307 - our own repr of floats
    spec = tp.ToolpathSpec(
        kind="facing",
        path=tp.FacingToolpath(r_start=1.004e-3, r_end=0.996e-3, feed_per_rev=2e-6,
                               spindle_speed=20.0),
        field=tp.Field(pitch_x=1e-6, pitch_y=1e-6, nx=3, ny=2, center_x=1e-3))
    path = tp.sample(spec, field=spec.field, fs=4000.0)
    jit = tp.sweep(path, spec.tool, spec.field).z
    np.testing.assert_allclose(jit, nojit, rtol=0, atol=ATOL_REFERENCE)  # 1 pm


def test_fastmath_flags_are_the_shared_constant():
    """Every njit kernel uses kernels._config.FASTMATH (no nnan/ninf)."""
    import importlib
    import pathlib

    from numba.core.registry import CPUDispatcher

    import servosurf.kernels as k

    assert {"nnan", "ninf", "fast"}.isdisjoint(k.FASTMATH)
    for f in sorted(pathlib.Path(k.__file__).parent.glob("_*.py")):
        if f.stem in ("__init__", "_config"):
            continue
        mod = importlib.import_module(f"servosurf.kernels.{f.stem}")
        for name, obj in vars(mod).items():
            if isinstance(obj, CPUDispatcher):
                assert set(obj.targetoptions.get("fastmath", ())) == k.FASTMATH, (
                    f.name, name)


@pytest.mark.parametrize("y", [0.0, 3e-7, -2.5e-4, 4e-3, -1e-3])
@pytest.mark.parametrize("x0", [-2e-3, -1.6e-5, 5e-3])
def test_row_angles_match_arctan2(y, x0):
    """Anchored series angles equal numpy.arctan2 to a few ulp, near the axis too."""
    from servosurf.kernels._sweep import ANCHOR, _row_polar

    nx, dx, col0 = 5 * ANCHOR + 7, 5e-7, 13
    rps = np.empty(nx)
    phis = np.empty(nx)
    _row_polar(y, x0, dx, col0, rps, phis)
    x = x0 + (col0 + np.arange(nx)) * dx
    exact = np.arctan2(y, x)
    # the kernel forms x with a fused multiply-add: coordinates differ by < 1e-20 m
    np.testing.assert_allclose(rps, np.hypot(x, y), rtol=1e-15, atol=1e-20)
    ulp = np.spacing(np.maximum(np.abs(exact), 1e-300))
    r = np.hypot(x, y)
    tol = 4 * ulp + np.divide(1e-20, r, out=np.full(nx, np.inf), where=r > 0)
    assert np.all(np.abs(phis - exact) <= tol), np.abs(phis - exact).max()


def test_row_angles_depend_on_the_absolute_column_only():
    """A row computed in pieces gives the same angles bit for bit (tiles)."""
    from servosurf.kernels._sweep import ANCHOR, _row_polar

    nx, x0, dx, y = 3 * ANCHOR + 5, 4e-3, 5e-7, 2e-4
    whole_r, whole_p = np.empty(nx), np.empty(nx)
    _row_polar(y, x0, dx, 0, whole_r, whole_p)
    for c0, c1 in ((0, 17), (17, ANCHOR + 3), (ANCHOR + 3, nx)):
        r, p = np.empty(c1 - c0), np.empty(c1 - c0)
        _row_polar(y, x0, dx, c0, r, p)
        np.testing.assert_array_equal(p, whole_p[c0:c1])
        np.testing.assert_array_equal(r, whole_r[c0:c1])


def test_tiles_across_anchor_columns_reproduce_the_whole_field():
    spec = facing_case(nx=100, ny=6)
    path = tp.sample(spec, field=spec.field)
    whole = tp.sweep(path, spec.tool, spec.field).z
    tiled = np.empty_like(whole)
    for c0, c1 in ((0, 31), (31, 33), (33, 70), (70, 100)):
        tiled[:, c0:c1] = tp.sweep(path, spec.tool, spec.field, cols=(c0, c1)).z
    np.testing.assert_array_equal(tiled, whole)
