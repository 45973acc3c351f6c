"""An NC program as a toolpath: time bases, rotation sense, the axis, references,
links, sampling and the swept surface against independent oracles."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from reference import naive

import servosurf.toolpath as tp
from servosurf.errors import ConfigError

MM = 1e-3
#: Two sweeps of the same geometry sampled differently: interpolation rounding only.
SWEEP_ATOL = 1e-12  # m, 1 pm


def read(text: str, **kw) -> tp.NCProgram:
    return tp.read_nc_program(io.StringIO(text), **kw)


def facing_program(r0, f, n_rev, z, *, step_deg=1.0, sign=1, x_sign=1,
                   header="G71 G90\n"):
    """A spiral facing program: C from 0 by ``step_deg``, X = r0 - f C / 360 (mm)."""
    k = np.arange(int(round(n_rev * 360 / step_deg)) + 1)
    c = k * step_deg
    x = x_sign * (r0 - f * c / 360.0)
    lines = [f"C{sign * ci:.6f} X{xi:.9f} Z{z:.9f}" for ci, xi in zip(c, x,
                                                                        strict=True)]
    return header + "\n".join(lines) + "\n"


def path_of(text, **kw) -> tp.BlockPath:
    kw.setdefault("nose_radius", 0.5e-3)
    return tp.BlockPath.from_program(read(text), **kw)


# ---------------------------------------------------------------------------------
# time bases
# ---------------------------------------------------------------------------------


def test_spindle_speed_time_base():
    p = path_of("C0 X1 Z0\nC90 X0.9 Z0\nC180 X0.8 Z-0.001\n", spindle_speed=1.0)
    # 90 degrees at 1 rev/s: 0.25 s per block
    np.testing.assert_allclose(p.t, [0.0, 0.25, 0.5])
    np.testing.assert_allclose(p.theta, [0.0, math.pi / 2, math.pi])
    np.testing.assert_allclose(p.r, np.array([1.0, 0.9, 0.8]) * MM)
    np.testing.assert_allclose(p.z, [0.0, 0.0, -1e-6])
    assert p.spindle_speed == 1.0 and p.rev_per_s == 1.0
    assert p.duration == 0.5 and p.n_revolutions == pytest.approx(0.5)
    # interpolation in time is linear in C, X and Z (the machine's)
    th, r, z = p.evaluate(np.array([0.125, 0.375]))
    np.testing.assert_allclose(th, [math.pi / 4, 3 * math.pi / 4])
    np.testing.assert_allclose(r, np.array([0.95, 0.85]) * MM)
    np.testing.assert_allclose(z, [0.0, -0.5e-6])


def test_block_time_and_program_time_bases():
    text = "C0 X1 Z0\nC0.5 X0.99 Z0\nC1.5 X0.98 Z0\n"
    p = path_of(text, block_time=0.01)
    np.testing.assert_allclose(p.t, [0.0, 0.01, 0.02])
    assert p.spindle_speed is None
    # G93 F6000: 0.01 s per block (C 1.5 degrees in 0.02 s = 12.5 rpm)
    q = path_of("G93 F6000\n" + text)
    np.testing.assert_allclose(q.t, [0.0, 0.01, 0.02])
    assert "G93" in q.time_base
    # the user's time base wins over the program's
    np.testing.assert_allclose(path_of("G93 F6000\n" + text, block_time=1.0).t,
                               [0.0, 1.0, 2.0])


def test_missing_or_unusable_time_base():
    with pytest.raises(ConfigError, match=r"line 1: the program gives no time for its "
                       r"cutting blocks.*--spindle-rpm N or --block-time S"):
        path_of("C0 X1 Z0\nC0.5 X0.99 Z0\n")
    # 1021/1022: G93 F0.001 is 60000 s per 0.5 degree block
    with pytest.raises(ConfigError, match=r"60000 s per cutting block, a mean spindle "
                       r"speed of 1.39e-06 rpm: no usable time base"):
        path_of("G93 F0.001\nC0 X1 Z0\nC0.5 X0.99 Z0\n")
    with pytest.raises(ConfigError, match="one time base"):
        path_of("C0 X1 Z0\nC1 X1 Z0\n", spindle_speed=1.0, block_time=1.0)


def test_two_axis_program_time_bases():
    pgm = "X0.010 Z0\nX0.008 Z0\nX0.004 Z0\n"
    # 60 rpm and 2 um per revolution: 1 s per 2 um of path
    p = path_of(pgm, spindle_speed=1.0, feed_per_rev=2e-6)
    np.testing.assert_allclose(p.t, [0.0, 1.0, 3.0])
    np.testing.assert_allclose(p.theta, 2 * np.pi * p.t)
    q = path_of(pgm, spindle_speed=1.0, block_time=0.5)
    np.testing.assert_allclose(q.t, [0.0, 0.5, 1.0])
    # G94 F in mm/min: 0.002 mm at 0.12 mm/min = 1 s
    r = path_of("G94 F0.12\n" + pgm, spindle_speed=1.0)
    np.testing.assert_allclose(r.t, [0.0, 1.0, 3.0])
    with pytest.raises(ConfigError, match="two-axis program .* --spindle-rpm"):
        path_of(pgm, block_time=1.0)
    with pytest.raises(ConfigError, match="no feed for its cutting moves"):
        path_of(pgm, spindle_speed=1.0)
    with pytest.raises(ConfigError, match="two-axis programs only"):
        path_of("C0 X1 Z0\nC1 X1 Z0\n", feed_per_rev=1e-6)


# ---------------------------------------------------------------------------------
# rotation sense, the axis, reference, links
# ---------------------------------------------------------------------------------


def test_rotation_sense_and_mirror_frame():
    up = "C0 X1 Z0\nC90 X0.9 Z0\n"
    down = "C0 X1 Z0\nC-90 X0.9 Z0\n"
    assert not path_of(up, block_time=1.0).mirrored
    assert path_of(up, block_time=1.0, rotation="cw").mirrored
    assert path_of(down, block_time=1.0).mirrored
    assert not path_of(down, block_time=1.0, rotation="cw").mirrored
    for text in (up, down):
        assert np.all(np.diff(path_of(text, block_time=1.0).theta) > 0)
    with pytest.raises(ConfigError, match=r"line 3: C turns back"):
        path_of("C0 X1 Z0\nC10 X1 Z0\nC5 X1 Z0\n", block_time=1.0)
    with pytest.raises(ConfigError, match=r"line 2: cutting block moves X/Z while C "
                       r"stays"):
        path_of("C0 X1 Z0\nC0 X0.5 Z0\nC10 X0.4 Z0\n", block_time=1.0)


def test_block_across_the_axis_is_split():
    # X from +0.1 to -0.3 mm while C turns 0 -> 90 degrees: the axis a quarter of
    # the way, at 22.5 degrees
    p = path_of("C0 X0.1 Z0\nC90 X-0.3 Z-0.002\n", spindle_speed=0.25)
    np.testing.assert_allclose(p.r, np.array([0.1, 0.0, 0.0, 0.3]) * MM, atol=1e-18)
    np.testing.assert_allclose(
        p.theta, [0.0, math.pi / 8, math.pi / 8 + math.pi, math.pi / 2 + math.pi])
    np.testing.assert_allclose(p.t, [0.0, 0.25, 0.25, 1.0])
    np.testing.assert_allclose(p.z, [0.0, -0.5e-6, -0.5e-6, -2e-6])
    # entirely past the axis: radius |X|, half a turn on
    q = path_of("C0 X-0.1 Z0\nC90 X-0.2 Z0\n", spindle_speed=0.25)
    np.testing.assert_allclose(q.r, np.array([0.1, 0.2]) * MM)
    np.testing.assert_allclose(q.theta, [math.pi, 1.5 * math.pi])


def test_centre_reference_converted_to_tip():
    text = "C0 X1 Z0.5\nC90 X0.9 Z0.5\n"
    tip = path_of(text, block_time=1.0, nose_radius=0.2e-3)
    centre = path_of(text, block_time=1.0, nose_radius=0.2e-3, reference="centre")
    np.testing.assert_allclose(centre.z, tip.z - 0.2e-3)
    assert centre.reference == "centre" and tip.reference == "tip"
    pgm = ";Reference Point : Tool Center\nX0.01 Z0.5\nX0 Z0.5\n"
    stated = tp.BlockPath.from_program(read(pgm, format="pgm"), nose_radius=1e-4,
                                       spindle_speed=1.0, block_time=1.0)
    np.testing.assert_allclose(stated.z, 0.5e-3 - 1e-4)
    with pytest.raises(ConfigError, match="states a centre path"):
        tp.BlockPath.from_program(read(pgm, format="pgm"), nose_radius=1e-4,
                                  spindle_speed=1.0, block_time=1.0, reference="tip")


def test_runs_separated_by_links():
    text = ("G93 F600\nC0 X1 Z0\nC90 X0.9 Z0\n"
            "G94 Z5 F600\nG94 X1\nG94 Z0 F600\n"     # link: 0.5 + 0.01 + 0.5 s
            "G93 F600\nC90 X1 Z-0.001\nC180 X0.9 Z-0.001\n")
    p = path_of(text)
    assert p.n_runs == 2
    # run 2 starts where the link leaves C (90 degrees), raised by a whole turn so
    # that the angle keeps increasing; its first block, a plunge with C standing
    # (0.1 s), belongs to the link
    np.testing.assert_allclose(p.theta, [0, math.pi / 2, 2.5 * math.pi, 3 * math.pi])
    np.testing.assert_allclose(p.t, [0.0, 0.1, 1.21, 1.31])
    np.testing.assert_allclose(p.cutting_spans(), [[0.0, 0.1], [1.21, 1.31]])
    np.testing.assert_allclose(p.z, [0, 0, -1e-6, -1e-6])
    # links no longer than a block still leave a gap of 2 blocks (or 1 ms)
    q = path_of("C0 X1 Z0\nC90 X0.9 Z0\nG0 X1\nG1 C180 X1 Z0\nC270 X0.9 Z0\n",
                block_time=1.0)
    # run 2 starts from the end of the rapid (C 90, X 1)
    np.testing.assert_allclose(q.t, [0.0, 1.0, 3.0, 4.0, 5.0])
    s = q.vertex_samples()
    np.testing.assert_array_equal(s.gaps(), [False, True, False, False, False])


def test_time_span_for_radius():
    p = path_of("C0 X1 Z0\nC90 X0.5 Z0\nC180 X0.9 Z0\n", block_time=1.0)
    # r goes 1 -> 0.5 -> 0.9 mm: inside [0.6, 0.8] mm from t = 0.4 to 1.75 s
    assert p.time_span_for_radius(0.6e-3, 0.8e-3) == pytest.approx((0.4, 1.75))
    assert p.time_span_for_radius(2e-3, 3e-3) is None
    assert p.time_span_for_radius(0.0, 0.55e-3) == pytest.approx((0.9, 1.125))


# ---------------------------------------------------------------------------------
# sampling and the swept surface
# ---------------------------------------------------------------------------------


def test_sampling_links_left_out_and_windows_subset():
    text = ("G93 F3000\n"
            + facing_program(5.0, 0.002, 3, -0.005, step_deg=2.0, header="")
            + "G94 Z1 F600\nG93 F3000\nC1080 X4.99 Z-0.005\nC1082 X4.9899 Z-0.005\n")
    p = path_of(text)
    assert p.n_runs == 2
    fs = 20e3
    full = tp.sample(p, fs=fs)
    # no sample inside the link
    (a0, a1), (b0, b1) = p.cutting_spans()
    assert not np.any((full.t > a1 + 1e-12) & (full.t < b0 - 1e-12))
    assert full.gaps().sum() == 1
    fld = tp.Field(pitch_x=1e-6, pitch_y=1e-6, nx=20, ny=10, center_x=5e-3 - 3e-6,
                   center_y=1e-6)
    win = tp.sample(p, fs=fs, field=fld, reach=0.1e-3)
    assert 0 < win.n < full.n / 5
    k = np.searchsorted(full.index, win.index)
    np.testing.assert_array_equal(full.index[k], win.index)
    for name in ("t", "theta", "r", "z"):
        np.testing.assert_array_equal(getattr(win, name), getattr(full, name)[k])
    tool = tp.Tool(nose_radius=0.5e-3)
    a = tp.sweep(full, tool, fld, initial=np.inf)
    b = tp.sweep(win, tool, fld, initial=np.inf)
    np.testing.assert_allclose(b.z, a.z, rtol=0, atol=SWEEP_ATOL)


def test_facing_program_matches_facing_toolpath():
    """The BlockPath of a program writing a plain facing spiral sweeps the same
    surface as FacingToolpath (both are linear in angle between samples)."""
    f, rpm = 2e-6, 250.0
    facing = tp.FacingToolpath(feed_per_rev=f, spindle_speed=rpm / 60, r_start=5.1e-3,
                               r_end=4.9e-3, depth_of_cut=5e-6)
    n_rev = (facing.r_start - facing.r_end) / f
    prog = read(facing_program(5.1, f / MM, n_rev, -0.005, step_deg=3.0))
    bp = tp.BlockPath.from_program(prog, nose_radius=0.5e-3, spindle_speed=rpm / 60)
    tool = tp.Tool(nose_radius=0.5e-3)
    fld = tp.Field(pitch_x=0.5e-6, pitch_y=0.5e-6, nx=64, ny=48, center_x=5e-3,
                   center_y=2e-6)
    ref = tp.sweep(tp.sample(facing, field=fld, tool=tool), tool, fld, initial=0.0)
    got = tp.sweep(bp.vertex_samples(), tool, fld, initial=0.0)
    np.testing.assert_allclose(got.z, ref.z, rtol=0, atol=SWEEP_ATOL)
    assert bp.duration == pytest.approx(facing.duration, rel=1e-12)


def test_mirror_frame_gives_the_mirror_image():
    tool = tp.Tool(nose_radius=0.5e-3)
    fld = tp.Field(pitch_x=1e-6, pitch_y=1e-6, nx=30, ny=21, center_x=1e-3,
                   center_y=3e-6)
    mirror = tp.Field(pitch_x=1e-6, pitch_y=1e-6, nx=30, ny=21, center_x=1e-3,
                      center_y=-3e-6)
    # a spiral with a Z ripple along C, turning C up (ccw) or down (its mirror)
    k = np.arange(721)
    c = 0.5 * k
    x = 1.02 - 0.01 * c / 360
    z = -0.001 + 0.0005 * np.sin(np.radians(7 * c))
    up = "\n".join(f"C{a:.3f} X{b:.9f} Z{d:.9f}" for a, b, d in zip(c, x, z,
                                                                       strict=True))
    down = up.replace("C", "C-")
    surf = {}
    for name, text, field in (("up", up, fld), ("down", down, mirror)):
        spec = tp.nc_spec(read(text), tool=tool, field=field, block_time=1e-3)
        from servosurf.simulation import simulate

        surf[name] = simulate(spec, parts=("kinematic",)).surface
    assert surf["down"].y0 == pytest.approx(mirror.y0)
    np.testing.assert_allclose(surf["down"].z[::-1], surf["up"].z, rtol=0,
                               atol=SWEEP_ATOL)


def test_rotation_sense_puts_the_cut_where_stated():
    # one turn at r = 0.2 mm; the tool dips 2 um at C = 90 degrees only
    c = np.arange(0, 361, 5.0)
    z = np.where(c == 90, -0.002, 0.0)
    text = "\n".join(f"C{a:g} X0.2 Z{b:g}" for a, b in zip(c, z, strict=True))
    fld = tp.Field(pitch_x=2e-6, pitch_y=2e-6, nx=3, ny=3, center_x=0.0)
    tool = tp.Tool(nose_radius=0.5e-3)
    from servosurf.simulation import simulate

    for rotation, y in (("ccw", 0.2e-3), ("cw", -0.2e-3)):
        spec = tp.nc_spec(read(text), tool=tool, block_time=1e-3, rotation=rotation,
                          field=tp.Field(pitch_x=2e-6, pitch_y=2e-6, nx=3, ny=3,
                                         center_x=0.0, center_y=y))
        deep = simulate(spec, parts=("kinematic",)).surface.z[1, 1]
        other = simulate(
            spec.__class__(kind="nc", path=spec.path, tool=tool,
                           field=tp.Field(pitch_x=2e-6, pitch_y=2e-6, nx=3, ny=3,
                                          center_x=0.0, center_y=-y)),
            parts=("kinematic",)).surface.z[1, 1]
        assert deep == pytest.approx(-2e-6, abs=1e-12), rotation
        assert other == pytest.approx(0.0, abs=1e-12), rotation
    del fld


def _brute_force(c_deg, x, z, R, hw, px, py):
    """Lowest edge height over points (px, py) for a path given by vertices in
    (C, signed X, Z), C increasing, theta = C: for every half turn k the tool's
    radial line passes the point at C = atan2(py, px) + k pi, where the point lies
    at signed coordinate (-1)^k r_p along it (no splitting at the axis)."""
    cr = np.radians(c_deg)
    out = np.full(px.shape, np.inf)
    for idx in np.ndindex(px.shape):
        rp = math.hypot(px[idx], py[idx])
        th = math.atan2(py[idx], px[idx])
        k0 = math.floor((cr[0] - th) / math.pi) - 1
        k1 = math.ceil((cr[-1] - th) / math.pi) + 1
        for k in range(k0, k1 + 1):
            target = th + k * math.pi
            if not cr[0] <= target <= cr[-1]:
                continue
            xs = np.interp(target, cr, x)
            zs = np.interp(target, cr, z)
            dr = (-1) ** k * rp - xs
            if abs(dr) <= hw:
                out[idx] = min(out[idx], zs + R - math.sqrt(R * R - dr * dr))
    return out


def test_path_across_the_axis_matches_signed_brute_force():
    # a facing spiral from X = +40 um through the axis (inside a block, at C =
    # 712.9 degrees) to X = -41 um
    c = np.arange(0, 4 * 360 + 1, 2.0)
    x = 0.04 - 0.081 * c / c[-1]
    z = -0.001 + 0.0002 * np.cos(np.radians(3 * c))
    text = "\n".join(f"C{a:g} X{b:.9f} Z{d:.9f}" for a, b, d in zip(c, x, z,
                                                                      strict=True))
    tool = tp.Tool(nose_radius=0.2e-3)
    # half a pixel off the axis: the axis point itself lies in every radial plane
    # (its height is a minimum over the whole path, which no radial sweep takes)
    fld = tp.Field(pitch_x=1e-6, pitch_y=1e-6, nx=41, ny=21, center_x=0.5e-6)
    from servosurf.simulation import simulate

    spec = tp.nc_spec(read(text), tool=tool, field=fld, block_time=1e-3)
    got = simulate(spec, parts=("kinematic",)).surface.z
    xs, ys = fld.coords()
    px, py = np.meshgrid(xs, ys)
    ref = _brute_force(c, x * MM, z * MM, tool.nose_radius, tool.half_width, px, py)
    np.testing.assert_allclose(got, ref, rtol=0, atol=SWEEP_ATOL)


def test_kinematic_sweep_equals_naive_sweep_of_the_blocks():
    """simulate(parts=("kinematic",)) equals the plain-numpy sweep of the block end
    points (which the test derives itself from the program text)."""
    c = np.arange(0, 3 * 360 + 1, 1.5)
    x = 0.3 - 0.006 * c / 360
    z = -0.0005 + 0.0001 * np.sin(np.radians(c))
    text = "G71\n" + "\n".join(f"C{a:g} X{b:.9f} Z{d:.9f}"
                               for a, b, d in zip(c, x, z, strict=True))
    tool = tp.Tool(nose_radius=0.1e-3)
    fld = tp.Field(pitch_x=1e-6, pitch_y=1e-6, nx=12, ny=8, center_x=0.293e-3,
                   center_y=4e-6)
    from servosurf.simulation import simulate

    res = simulate(tp.nc_spec(read(text), tool=tool, field=fld, block_time=2e-3),
                   parts=("kinematic",))
    t = 2e-3 * np.arange(c.size)
    xs, ys = fld.coords()
    ref = naive.sweep(t, np.radians(c), x * MM, z * MM, 500.0, xs, ys,
                      tool.nose_radius, tool.half_width, np.full(fld.shape, np.inf))
    np.testing.assert_allclose(res.surface.z, ref, rtol=0, atol=SWEEP_ATOL)
    assert res.t.size == 0 and res.settings["parts"] == ["kinematic"]


# ---------------------------------------------------------------------------------
# specs: TOML kind "nc" and nc_spec
# ---------------------------------------------------------------------------------


def test_toml_kind_nc(tmp_path):
    (tmp_path / "progs").mkdir()
    (tmp_path / "progs" / "p.nc").write_text("C0 X1 Z0.3\nC90 X0.9 Z0.3\n")
    toml = tmp_path / "case.toml"
    toml.write_text(
        'kind = "nc"\n'
        '[nc]\nprogram = "progs/p.nc"\nspindle-speed-rpm = 30.0\nrotation = "cw"\n'
        '[tool]\nnose-radius = 0.2e-3\nreference = "centre"\n'
    )
    spec = tp.load_toolpath(toml)
    assert spec.kind == "nc" and isinstance(spec.path, tp.BlockPath)
    np.testing.assert_allclose(spec.path.z, [0.1e-3, 0.1e-3])
    np.testing.assert_allclose(spec.path.t, [0.0, 0.5])   # 90 deg at 0.5 rev/s
    assert spec.path.mirrored and spec.path.rotation == "cw"
    # the default field: the band through the axis, pitch 0.5 um
    assert (spec.field.center_x, spec.field.center_y) == (0.0, 0.0)
    assert spec.field.pitch_x == 0.5e-6 and spec.field.nx == 4001
    # command-line overrides replace the whole time base and the tool radius
    over = tp.load_toolpath(toml, nose_radius=0.1e-3,
                            nc_overrides={"block_time": 2.0, "spindle_speed": None})
    np.testing.assert_allclose(over.path.t, [0.0, 2.0])
    np.testing.assert_allclose(over.path.z, [0.2e-3, 0.2e-3])
    toml.write_text('kind = "nc"\n[nc]\nprogram = "progs/p.nc"\nspindel-speed = 1\n')
    with pytest.raises(ConfigError, match="Did you mean: nc.spindle-speed"):
        tp.load_toolpath(toml)
    toml.write_text('kind = "nc"\n[nc]\nprogram = "progs/p.nc"\nblock-time = 1.0\n')
    with pytest.raises(ConfigError, match="states no tool nose radius"):
        tp.load_toolpath(toml)
    toml.write_text('kind = "nc"\n[nc]\nprogram = "progs/p.nc"\n'
                    'spindle-speed = 1000.0\n[tool]\nnose-radius = 1e-4\n')
    with pytest.raises(ConfigError, match="in rev/s, got 1000.0 .*spindle-speed-rpm"):
        tp.load_toolpath(toml)


def test_band_field():
    fld = tp.band_field(1.031171e-3)
    assert fld.nx == 4125 and fld.ny == 5 and fld.pitch_x == 0.5e-6
    x, y = fld.coords()
    assert x[fld.nx // 2] == 0.0 and y[fld.ny // 2] == 0.0
    assert x[-1] <= 1.031171e-3 < x[-1] + fld.pitch_x
    with pytest.raises(ConfigError, match=r"band pitch must be in \(0, 1e-6\] m"):
        tp.band_field(1e-3, pitch=2e-6)


def test_real_1022_revolutions_and_feed(tmp_path):
    from tests.conftest import SHARED

    prog = SHARED / "data" / "upm_sts" / "1022" / "1022-spiralPath20230418T214917.nc"
    if not prog.is_file():
        pytest.skip(f"shared UPM data not found at {prog}")
    p = tp.BlockPath.from_program(tp.read_nc_program(prog), nose_radius=189.36e-6,
                                  block_time=1e-3)
    assert p.n_revolutions == pytest.approx(38.0)
    assert p.t.size == 27361 and p.duration == pytest.approx(27.36)
    # SOURCES.md: feed per revolution 25.9-33.2 um, mean 28.9 um, on r = 0.05-0.5 mm
    r, f = p.feed_per_revolution()
    m = (r >= 0.05e-3) & (r <= 0.5e-3)
    assert f[m].min() == pytest.approx(25.9e-6, abs=0.05e-6)
    assert f[m].max() == pytest.approx(33.2e-6, abs=0.05e-6)
    assert f[m].mean() == pytest.approx(28.9e-6, abs=0.05e-6)
