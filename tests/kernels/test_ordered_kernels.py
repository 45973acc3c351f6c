"""Time-ordered sweep (material rules) against the plain-numpy reference, the
envelope kernel and closed forms (Brammertz's ridge, a hand-computed cusp)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.errors import ConfigError

try:  # tests/ on sys.path (rootdir-relative packages)
    from reference import ATOL_REFERENCE, naive
except ImportError:  # tests/ itself is a package
    from tests.reference import ATOL_REFERENCE, naive

from .test_sweep_kernels import STEEP_TOOL, facing_case, random_path

R = 0.5e-3  # m, nose radius (seed paper Table 2)
F = 2e-6  # m per revolution (Table 2)
D = 5e-6  # m depth of cut (Table 2)

#: A rule set with every rule on (m): h_min, side-flow height and width, recovery.
ALL = tp.CuttingRules(min_chip_thickness=2e-9, side_flow_height=0.6e-9,
                      side_flow_width=0.3e-6, recovery_height=1.5e-9,
                      recovery_decay=4e-9)
RULE_SETS = {
    "ploughing": tp.CuttingRules(min_chip_thickness=3e-9),
    "side-flow": tp.CuttingRules(side_flow_height=1e-9, side_flow_width=0.5e-6),
    "recovery": tp.CuttingRules(recovery_height=2e-9, recovery_decay=3e-9),
    "all": ALL,
}


def naive_ordered(path, tool, field, rules, initial=None):
    """Reference map for a SampledPath on a Field (plain numpy)."""
    x, y = field.coords()
    init = np.zeros(field.shape) if initial is None else np.broadcast_to(
        np.asarray(initial, dtype=float), field.shape)
    wav = tool.waviness_table() if tool.has_waviness else None
    return naive.ordered_sweep(path.t, path.theta, path.r, path.z, path.fs, x, y,
                               tool.nose_radius, tool.half_width, init,
                               rules.as_array(), wav)


# ------------------------------------------------------- kinematic rules = envelope
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("gaps", [False, True])
def test_no_rules_equals_envelope_bit_for_bit(seed, gaps):
    rng = np.random.default_rng(seed)
    path = random_path(rng, monotone_r=bool(seed), gaps=gaps)
    field = tp.Field(pitch_x=0.4e-6, pitch_y=0.4e-6, nx=14, ny=11, center_x=2e-3,
                     center_y=0.0)
    a = tp.sweep(path, STEEP_TOOL, field).z
    b = tp.sweep_ordered(path, STEEP_TOOL, field, rules=tp.CuttingRules()).z
    np.testing.assert_array_equal(a, b)


def test_no_rules_equals_envelope_across_the_axis():
    spec = tp.ToolpathSpec(
        kind="facing", path=tp.FacingToolpath(r_start=60e-6, r_end=0.0),
        tool=tp.Tool(),
        field=tp.Field(pitch_x=3e-6, pitch_y=3e-6, nx=13, ny=11, center_x=0.0),
    )
    path = tp.sample(spec, field=spec.field, fs=20e3)
    a = tp.sweep(path, spec.tool, spec.field).z
    b = tp.sweep_ordered(path, spec.tool, spec.field, rules=tp.CuttingRules()).z
    np.testing.assert_array_equal(a, b)


# --------------------------------------------------------------- against reference
@pytest.mark.parametrize("name", sorted(RULE_SETS))
def test_facing_matches_reference(name):
    spec = facing_case(nx=10, ny=7, pitch=0.3e-6)
    path = tp.sample(spec, field=spec.field)
    rules = RULE_SETS[name]
    a = tp.sweep_ordered(path, spec.tool, spec.field, rules=rules).z
    ref = naive_ordered(path, spec.tool, spec.field, rules)
    np.testing.assert_allclose(a, ref, rtol=0, atol=ATOL_REFERENCE)
    kin = tp.sweep(path, spec.tool, spec.field).z
    assert np.abs(a - kin).max() > 0.1e-9  # the rules change the map


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_paths_match_reference(seed):
    rng = np.random.default_rng(seed)
    path = random_path(rng, monotone_r=seed != 1, gaps=seed == 2)
    field = tp.Field(pitch_x=0.4e-6, pitch_y=0.4e-6, nx=9, ny=8, center_x=2e-3,
                     center_y=0.0)
    for rules in RULE_SETS.values():
        a = tp.sweep_ordered(path, STEEP_TOOL, field, rules=rules).z
        ref = naive_ordered(path, STEEP_TOOL, field, rules)
        np.testing.assert_allclose(a, ref, rtol=0, atol=ATOL_REFERENCE)


def test_across_the_axis_matches_reference():
    spec = tp.ToolpathSpec(
        kind="facing", path=tp.FacingToolpath(r_start=40e-6, r_end=0.0,
                                              feed_per_rev=4e-6),
        tool=tp.Tool(),
        # no pixel on the axis itself: there the crossing angle is undefined (a
        # rounding of x or y picks it), and with material rules the order of the
        # crossings, which that angle sets, matters
        field=tp.Field(pitch_x=2.5e-6, pitch_y=2.5e-6, nx=9, ny=7, center_x=0.7e-6,
                       center_y=0.3e-6),
    )
    path = tp.sample(spec, field=spec.field, fs=20e3)
    a = tp.sweep_ordered(path, spec.tool, spec.field, rules=ALL).z
    ref = naive_ordered(path, spec.tool, spec.field, ALL)
    np.testing.assert_allclose(a, ref, rtol=0, atol=ATOL_REFERENCE)


def test_initial_map_nan_and_tiles():
    spec = facing_case(nx=10, ny=8, pitch=0.3e-6)
    path = tp.sample(spec, field=spec.field)
    init = np.zeros(spec.field.shape)
    init[2, 3] = np.nan
    init[5:, :] = 1e-6  # a step in the pre-cut face
    whole = tp.sweep_ordered(path, spec.tool, spec.field, rules=ALL, initial=init).z
    ref = naive_ordered(path, spec.tool, spec.field, ALL, initial=init)
    assert np.isnan(whole[2, 3])
    np.testing.assert_allclose(whole, ref, rtol=0, atol=ATOL_REFERENCE)
    tile = tp.sweep_ordered(path, spec.tool, spec.field, rules=ALL, initial=init,
                            rows=(4, 8), cols=(2, 7)).z
    np.testing.assert_array_equal(tile, whole[4:8, 2:7])


# -------------------------------------------------------------------- closed forms
def _kinematic_row(h_min, *, pitch=5e-9, periods=2):
    """One radial row of a steady-state kinematic facing cut (R, F, D above)."""
    spec = tp.ToolpathSpec(
        kind="facing",
        path=tp.FacingToolpath(r_start=5.1e-3, r_end=4.9e-3, feed_per_rev=F,
                               depth_of_cut=D),
        tool=tp.Tool(),
        field=tp.Field(pitch_x=pitch, pitch_y=pitch, nx=int(periods * F / pitch),
                       ny=1, center_x=5e-3 + 0.3e-6, center_y=0.0),
    )
    path = tp.sample(spec, field=spec.field)
    rules = tp.CuttingRules(min_chip_thickness=h_min)
    z = tp.sweep_ordered(path, spec.tool, spec.field, rules=rules).z[0]
    x, _ = spec.field.coords()
    return x, z


def _arc(v):
    """Height of the R arc at radial offset v from the tip (tip at -D), in m."""
    return -D + R - np.sqrt(R * R - v * v)


def _x_star(h_min):
    """Offset v from a pass where its uncut thickness (to the pass one feed
    outward, exact circles) equals h_min: the ploughing boundary (root by
    bisection)."""
    lo, hi = -F, F / 2
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _arc(mid - F) - _arc(mid) > h_min:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("h_min", [1e-9, 2e-9, 3e-9])
def test_ploughing_reproduces_brammertz(h_min):
    """Rt = f^2/(8R) + (h_min/2)(1 + R h_min / f^2) (Brammertz 1961), valid for
    h_min <= f^2/(2R) = 4 nm; and the whole steady-state profile point by point."""
    x, z = _kinematic_row(h_min)
    # passes cross the row (angle 0) at r_k = r_start - k F
    xs = _x_star(h_min)
    k = np.floor((5.1e-3 - x + xs) / F)  # the pass k with v = x - r_k in [xs - F, xs)
    v = x - (5.1e-3 - k * F)
    expected = _arc(v)
    near_jump = np.abs(v - xs) < 2 * (x[1] - x[0])
    np.testing.assert_allclose(z[~near_jump], expected[~near_jump], rtol=0,
                               atol=ATOL_REFERENCE)
    brammertz = F**2 / (8 * R) + 0.5 * h_min * (1 + R * h_min / F**2)
    rt = z.max() - z.min()
    # grid: the peak is sampled within one pitch of the jump (slope <= 3F/(2R))
    assert rt == pytest.approx(brammertz, abs=(x[1] - x[0]) * 1.5 * F / R + 1e-13)
    assert rt > F**2 / (8 * R) + 0.5 * h_min  # above the kinematic Rt


def test_kinematic_row_is_f2_over_8r():
    x, z = _kinematic_row(0.0)
    # the cusp is sampled within half a pitch, where the arcs slope by F / (2R)
    pitch = x[1] - x[0]
    assert z.max() - z.min() == pytest.approx(F**2 / (8 * R),
                                              abs=0.5 * pitch * F / R + 1e-13)


def _two_pass(rules, x, r1=5e-3, r2=5e-3 - F):
    """Kernel map of two revolutions at constant radii r1 then r2 (tip at -D)."""
    n = 4000
    theta = np.linspace(-np.pi, 3 * np.pi, n)
    r = np.where(theta < np.pi, r1, r2)
    z = np.full(n, -D)
    fs = 1e4
    path = tp.SampledPath(np.arange(n) / fs, theta, r, z, fs)
    field = tp.Field(pitch_x=x[1] - x[0], pitch_y=1e-6, nx=x.size, ny=1,
                     center_x=0.5 * (x[0] + x[-1]), center_y=0.0)
    return tp.sweep_ordered(path, tp.Tool(), field, rules=rules).z[0]


def test_recovery_on_a_hand_computed_cusp():
    """Two passes one feed apart: the second pass's chip thins to zero at the cusp,
    where the recovery min(h, d0 exp(-h/h_d)) is largest."""
    d0, hd = 2e-9, 3e-9
    rules = tp.CuttingRules(recovery_height=d0, recovery_decay=hd)
    r1, r2 = 5e-3, 5e-3 - F
    x = np.linspace(r2 - 0.5e-6, r1 + 0.5e-6, 601)
    z = _two_pass(rules, x, r1, r2)
    z1 = _arc(x - r1)
    h1 = 0.0 - z1
    s1 = z1 + np.minimum(h1, d0 * np.exp(-h1 / hd))
    z2 = _arc(x - r2)
    h2 = s1 - z2
    s2 = np.where(h2 > 0, z2 + np.minimum(h2, d0 * np.exp(-np.maximum(h2, 0) / hd)),
                  s1)
    np.testing.assert_allclose(z, s2, rtol=0, atol=ATOL_REFERENCE)
    # the recovery is largest where the second chip thins out to h* = d0
    # exp(-h*/h_d), which lies h* R / F inward of the cusp (the chip grows by F/R
    # per metre there)
    h_star = 0.0
    for _ in range(200):
        h_star = d0 * math.exp(-h_star / hd)
    lift = z - np.minimum(z1, z2)
    cusp = 0.5 * (r1 + r2)
    assert x[np.argmax(lift)] == pytest.approx(cusp - h_star * R / F,
                                               abs=2 * (x[1] - x[0]))
    assert lift.max() == pytest.approx(h_star, rel=2e-3)


def test_side_flow_ridge_on_a_hand_computed_cusp():
    """The second pass leaves a ridge a (1 - d/b) beyond its cut boundary, d the
    lateral distance: the two arcs' height difference grows by F/R per metre."""
    a, b = 1e-9, 0.4e-6
    rules = tp.CuttingRules(side_flow_height=a, side_flow_width=b)
    r1, r2 = 5e-3, 5e-3 - F
    x = np.linspace(r2 - 0.5e-6, r1 + 0.5e-6, 801)
    z = _two_pass(rules, x, r1, r2)
    z1, z2 = _arc(x - r1), _arc(x - r2)
    # outward of the cusp the second pass does not cut: its edge is z2 - z1 above
    # the first pass's surface, and the slopes of the two arcs differ by F / R
    d = (z2 - z1) * R / F
    ridge = np.where((d > 0) & (d < b), a * (1 - d / b), 0.0)
    expected = np.where(d > 0, z1 + ridge, z2)
    away = np.abs(x - 0.5 * (r1 + r2)) > 2 * (x[1] - x[0])
    np.testing.assert_allclose(z[away], expected[away], rtol=0, atol=ATOL_REFERENCE)
    assert z.max() - np.minimum(z1, z2).max() == pytest.approx(a, rel=0.02)


def test_rules_validation():
    with pytest.raises(ConfigError, match="side_flow_width"):
        tp.CuttingRules(side_flow_height=1e-9)
    with pytest.raises(ConfigError, match="recovery_decay"):
        tp.CuttingRules(recovery_height=1e-9)
    with pytest.raises(ConfigError, match="min_chip_thickness"):
        tp.CuttingRules(min_chip_thickness=-1e-9)
    with pytest.raises(ConfigError, match="rules must be CuttingRules"):
        spec = facing_case(nx=3, ny=3)
        tp.sweep_ordered(tp.sample(spec, field=spec.field), spec.tool, spec.field,
                         rules=(1e-9, 0, 0, 0, 0))
    with pytest.raises(TypeError):
        spec = facing_case(nx=3, ny=3)
        tp.sweep_ordered(tp.sample(spec, field=spec.field), spec.tool, spec.field,
                         rules=ALL, bogus=1)


def test_side_flow_ridge_from_across_the_axis():
    """A point cut first by a pass on its own side (tip at x = +22 um), then met by
    the arc of a pass on the far side of the axis (tip at x = -16 um): the two arcs
    cross at x = 3 um and beyond it the far pass leaves a ridge whose lateral
    distance uses the physical slopes (x + 16 um)/R and (x - 22 um)/R."""
    a, b = 1e-9, 0.4e-6
    rules = tp.CuttingRules(side_flow_height=a, side_flow_width=b)
    r1, r2 = 22e-6, 16e-6
    n = 4000
    theta = np.linspace(-np.pi / 2, 3 * np.pi / 2, n)  # crossings at 0 and pi
    r = np.where(theta < np.pi / 2, r1, r2)
    path = tp.SampledPath(np.arange(n) / 1e4, theta, r, np.full(n, -D), 1e4)
    x = np.linspace(2e-6, 4e-6, 401)
    field = tp.Field(pitch_x=x[1] - x[0], pitch_y=1e-6, nx=x.size, ny=1,
                     center_x=0.5 * (x[0] + x[-1]), center_y=0.0)
    z = tp.sweep_ordered(path, tp.Tool(), field, rules=rules).z[0]
    z1, z2 = _arc(x - r1), _arc(x + r2)  # the far tip sits at x = -r2
    d = (z2 - z1) / ((r1 + r2) / R)  # slopes differ by (r1 + r2) / R
    expected = np.where(d > 0, z1 + np.where(d < b, a * (1 - d / b), 0.0), z2)
    away = np.abs(x - 0.5 * (r1 - r2)) > 2 * (x[1] - x[0])
    np.testing.assert_allclose(z[away], expected[away], rtol=0, atol=ATOL_REFERENCE)
    assert z.max() - np.minimum(z1, z2).max() == pytest.approx(a, rel=0.02)
