"""Sampling toolpaths at the controller rate, whole and by field windows."""

from __future__ import annotations

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.errors import ConfigError


def small_facing(**kw):
    return tp.ToolpathSpec(
        kind="facing",
        path=tp.FacingToolpath(r_start=5.02e-3, r_end=4.98e-3, **kw),
        field=tp.Field(pitch_x=1e-6, pitch_y=1e-6, nx=8, ny=6, center_x=5e-3),
    )


def test_full_sampling():
    spec = small_facing()
    p = tp.sample(spec)
    assert p.fs == tp.FS_DEFAULT
    assert p.n == int(spec.path.duration * p.fs) + 1
    np.testing.assert_array_equal(p.index, np.arange(p.n))
    assert not p.gaps().any()
    np.testing.assert_allclose(np.diff(p.theta), 2 * np.pi * spec.path.spindle_speed
                               / p.fs, rtol=1e-9)


def test_windowed_samples_are_a_subset_of_the_full_path():
    spec = small_facing()
    full = tp.sample(spec)
    win = tp.sample(spec, field=spec.field)
    assert 0 < win.n < full.n / 20
    k = win.index
    for name in ("t", "theta", "r", "z"):
        np.testing.assert_array_equal(getattr(win, name), getattr(full, name)[k])
    assert win.gaps().sum() >= spec.path.n_revolutions - 2
    # every window spans the field's angles with margin
    c, lo, hi = spec.field.angular_window()
    rel = np.mod(win.theta - c + np.pi, 2 * np.pi) - np.pi
    assert rel.min() < lo and rel.max() > hi


def test_count_samples_matches_sample():
    spec = small_facing()
    for kw in ({}, {"field": spec.field}, {"field": spec.field, "reach": 5e-6},
               {"t_window": (0.5, 0.7)}):
        assert tp.count_samples(spec, **kw) == tp.sample(spec, **kw).n


def test_t_window_and_reach():
    spec = small_facing()
    p = tp.sample(spec, t_window=(1.0, 2.0))
    assert p.t[0] >= 1.0 - 2 / p.fs and p.t[-1] <= 2.0 + 2 / p.fs
    near = tp.sample(spec, field=spec.field, reach=10e-6)
    wide = tp.sample(spec, field=spec.field)
    assert near.n < wide.n
    far = tp.Field(nx=2, ny=2, center_x=9e-3)
    assert tp.sample(spec, field=far).n == 0


def test_guards():
    with pytest.raises(ConfigError, match="max_samples"):
        tp.sample(small_facing(), max_samples=1000)
    with pytest.raises(ConfigError, match="needs a tool"):
        tp.sample(small_facing().path, field=tp.Field())
    with pytest.raises(TypeError, match="unexpected keyword"):
        tp.sample(small_facing(), fss=1.0)
    with pytest.raises(ConfigError, match="one length"):
        tp.SampledPath(t=[0, 1], theta=[0, 1], r=[1], z=[0, 0], fs=1.0)


def test_add_z_and_slope():
    p = tp.sample(small_facing(), t_window=(0.0, 0.01))
    q = p.add_z(np.full(p.n, 1e-9))
    np.testing.assert_allclose(q.z - p.z, 1e-9, rtol=0, atol=1e-21)
    with pytest.raises(ConfigError, match="shape"):
        p.add_z(np.zeros(3))
    np.testing.assert_allclose(p.slope_along_cut(), 0.0, atol=1e-15)


def test_clearance_warning():
    spec = tp.ToolpathSpec(kind="lenslet",
                           path=tp.LensletToolpath(amplitude=20e-6, depth_of_cut=10e-6,
                                                   surface_speed=20e-3, ring_count=1),
                           field=tp.Field(nx=21, ny=21, pitch_x=10e-6, pitch_y=10e-6,
                                          center_x=10e-3))
    path = tp.sample(spec, field=spec.field, fs=20e3)
    with pytest.warns(tp.ToolpathWarning, match="clearance angle"):
        tp.sweep(path, spec.tool, spec.field)
    ok = tp.load_toolpath(
        __import__("pathlib").Path(__file__).resolve().parents[2]
        / "toolpaths" / "lenslet_10um.toml")
    p2 = tp.sample(ok, t_window=(0.0, 0.05), fs=20e3)
    angle = tp.check_clearance(p2, ok.tool)  # no warning: 11.9 < 15 degree
    assert np.degrees(angle) == pytest.approx(11.9, abs=0.2)


@pytest.mark.parametrize("kind", ["facing", "lenslet"])
def test_numba_sampling_matches_the_path_formulas(kind):
    if kind == "facing":
        spec = small_facing()
    else:
        spec = tp.ToolpathSpec(kind="lenslet", path=tp.LensletToolpath(ring_count=2))
    p = tp.sample(spec, fs=20e3)
    theta, r, z = spec.path.evaluate(p.t)
    np.testing.assert_array_equal(p.index, np.arange(p.n))
    np.testing.assert_allclose(p.theta, theta, rtol=1e-14, atol=0)
    np.testing.assert_allclose(p.r, r, rtol=0, atol=1e-17)  # 10 am
    np.testing.assert_allclose(p.z, z, rtol=0, atol=1e-17)  # 10 am
