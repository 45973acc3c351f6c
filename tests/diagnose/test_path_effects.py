"""Path-side catalogue effects (issue 19 item 7): asynchronous spindle error.

* the hook, simulated through :func:`servosurf.simulation.simulate` on a facing cut,
  changes the machined surface by ``a cos(2 pi f t + phi)`` at the time of the pass
  that cut each pixel, the pass times computed here from the facing geometry with
  plain numpy (an oracle sharing no code with the sweep kernel or the diagnosis);
* the non-integer order test;
* a detection test: a case of the discovery benchmark's generator (drifting sines,
  not the catalogue's fixed sine) diagnosed from its map and ring profile.
"""

from __future__ import annotations

import dataclasses
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from servosurf.diagnose import effects as E

REPO = Path(__file__).resolve().parents[2]
FACING = REPO / "toolpaths" / "flat_facing.toml"


def _small_facing():
    """A facing cut with a 10 um feed (25 nm cusps) at 600 rpm over a small field."""
    from servosurf.toolpath import load_toolpath

    spec = load_toolpath(FACING)
    path = dataclasses.replace(spec.path, feed_per_rev=10e-6, spindle_speed=10.0,
                               r_start=5.2e-3)
    fld = dataclasses.replace(spec.field, nx=40, ny=30, pitch_x=1.0e-6,
                              pitch_y=1.0e-6)
    return dataclasses.replace(spec, path=path, field=fld)


def _pass_times(spec, x, y):
    """Time (s) of the pass nearest to each point and its radial offset (m):
    plain numpy on the facing geometry r(t) = r_start - feed n t, theta(t) =
    theta0 + 2 pi n t."""
    p = spec.path
    n = p.spindle_speed
    r = np.hypot(x, y)
    th = np.arctan2(y, x)
    t0 = np.mod(th - p.theta_start, 2 * math.pi) / (2 * math.pi * n)
    j = np.rint(((p.r_start - r) / (p.feed_per_rev * n) - t0) * n)
    t = t0 + j / n
    dr = r - (p.r_start - p.feed_per_rev * n * t)
    return t, dr


def test_async_error_simulates_as_a_fixed_sine_at_the_pass_times():
    from servosurf.simulation import simulate

    spec = _small_facing()
    q = E.SpindleAsyncErrorParams(frequency=237.3, amplitude=2e-9, phase=0.7)
    nom = simulate(spec, parts=("tracking",))
    res = simulate(spec, parts=("tracking",), hooks=[q])
    x, y = spec.field.coords()
    xx, yy = np.meshgrid(x, y)
    t, dr = _pass_times(spec, xx, yy)
    # near the pass centre the same pass cuts with and without the term: the cusp
    # (f^2 / 8R = 25 nm) exceeds twice the amplitude there by far
    centre = np.abs(dr) < 0.25 * spec.path.feed_per_rev
    assert centre.sum() > 100
    want = q.amplitude * np.cos(2 * math.pi * q.frequency * t + q.phase)
    got = (res.surface.z - nom.surface.z)[centre]
    np.testing.assert_allclose(got, want[centre], rtol=0, atol=1e-3 * q.amplitude)
    # the pattern is not a spindle order: it differs between revolutions at the
    # same angle (one column of the field: the same angle, successive passes)
    assert np.ptp(want[centre]) > q.amplitude


def test_non_integer_order_test():
    from servosurf.diagnose.effects._spindle_async_error import is_synchronous

    fsp = 250.0 / 60.0
    assert is_synchronous(7 * fsp, fsp)
    assert is_synchronous(7.015 * fsp, fsp)
    assert not is_synchronous(7.03 * fsp, fsp)
    assert not is_synchronous(7.5 * fsp, fsp)
    assert not is_synchronous(0.4 * fsp, fsp)  # below the first order
    assert not is_synchronous(100.0, 0.0)  # no spindle


def _generated_case(discovery, tmp: Path, effect: str, enr: float, seed: int):
    """A case of the benchmark generator with only its map and ring profile in the
    manifest; returns (manifest path, truth)."""
    C = discovery("cases")
    campaign = C.CAMPAIGNS["test"]
    spec = {"effects": [effect], "ool": None, "enr": enr, "seed": seed}
    p, ool, truth, _achieved = C.build(spec, campaign)
    full = tmp / "full"
    C.write_case(full, p, ool, campaign, seed)
    text = (full / "manifest.toml").read_text()
    head, *recs = text.split("[[recording]]")
    keep = [r for r in recs if re.search(r'kind = "(surface|profile)"', r)]
    tp = re.search(r'toolpath = "(.*)"', head).group(1)
    head = head.replace(tp, str((full / tp).resolve()))
    case = tmp / "case"
    case.mkdir()
    for r in keep:
        name = re.search(r'path = "(.*)"', r).group(1)
        shutil.copy(full / name, case / name)
    (case / "manifest.toml").write_text(head + "".join("[[recording]]" + r
                                                       for r in keep))
    return case / "manifest.toml", truth[effect]


@pytest.mark.slow
def test_async_error_is_detected_and_named(discovery, tmp_path):
    """Drifting sines at a non-integer order (ENR 0.5) on the map and ring
    profile: named spindle-async-error against the other outside-the-loop
    effects of the tool height in time, frequency within 0.1 % and amplitude
    within 10 % (base lines, whose idle-record refinement alone takes minutes,
    are left to the blind benchmark)."""
    from servosurf.diagnose import diagnose, get_effect

    manifest, truth = _generated_case(discovery, tmp_path, "spindle-async-error",
                                      0.5, 11)
    names = ("spindle-async-error", "spindle-axial-error", "thermal-drift")
    d = diagnose(manifest, effects=[get_effect(n) for n in names], max_terms=1)
    ex = sorted(d.to_dict()["explanations"], key=lambda e: -e["delta_bic"])
    assert ex and ex[0]["effect"] == "spindle-async-error", [e["effect"] for e in ex]
    par = ex[0]["parameters"]
    assert par["frequency_1_hz"] == pytest.approx(truth["frequency_1_hz"], rel=1e-3)
    assert par["amplitude_1_m"] == pytest.approx(truth["amplitude_1_m"], rel=0.1)


# ------------------------------------------------------------------ tool wear
def _arc_envelope(spec, xx, yy, radius):
    """Heights (m) of the facing cut by the closed form: the lower envelope of the
    round-nose arcs ``-d + R - sqrt(R^2 - dr^2)`` of the three nearest passes,
    each pass with its own nose radius ``radius(t)`` (plain numpy)."""
    p = spec.path
    n = p.spindle_speed
    t, _dr = _pass_times(spec, xx, yy)
    r = np.hypot(xx, yy)
    out = np.full(xx.shape, np.inf)
    for k in (-1, 0, 1):
        tk = t + k / n
        dr = r - (p.r_start - p.feed_per_rev * n * tk)
        R = radius(tk)
        out = np.minimum(out, -p.depth_of_cut + R - np.sqrt(R * R - dr * dr))
    return out


def test_wear_simulates_as_arcs_of_growing_radius():
    """A facing cut with the nose radius growing 50 um per second (10 % of R at the
    field): the simulator's surface change is the closed-form change of the arc
    envelope, the cusp height f^2 / (8 R(t)) falling with time."""
    from servosurf.diagnose.effects._tool_wear import cutting_speed
    from servosurf.simulation import simulate

    spec = _small_facing()
    v = cutting_speed(spec)
    R0 = spec.tool.nose_radius
    rate = 50e-6  # m/s of radius growth
    q = E.ToolWearParams(rate / v, v)
    nom = simulate(spec, parts=("tracking",))
    res = simulate(spec, parts=("tracking",), hooks=[q])
    x, y = spec.field.coords()
    xx, yy = np.meshgrid(x, y)
    want = (_arc_envelope(spec, xx, yy, lambda t: R0 + rate * t)
            - _arc_envelope(spec, xx, yy, lambda t: np.full(np.shape(t), R0)))
    got = res.surface.z - nom.surface.z
    # the simulator holds the tool constant over each piece of the path (the
    # field's window of one revolution, 0.4 ms here): the radius differs from
    # the pass's own by at most rate * 0.4 ms
    t, _ = _pass_times(spec, xx, yy)
    tol = rate * 0.4e-3 * (spec.path.feed_per_rev ** 2) / (2 * R0**2) + 1e-13
    assert np.ptp(want) > 1e-9  # the cusps drop by nanometres over the field
    np.testing.assert_allclose(got, want, rtol=0, atol=tol + 1e-3 * np.ptp(want))


@pytest.mark.slow
def test_wear_is_detected_and_named(discovery, tmp_path):
    """A map over the three lenslet rings (4.5 um pixels) of a tool whose radius
    grows by the generator's saturating law (not the catalogue's linear one) by
    0.3 um over the toolpath: named tool-wear, not a static radius error, with
    the mean growth within 30 %."""
    from servosurf.diagnose import diagnose, get_effect

    C = discovery("cases")
    case = C.base_case()
    spec = case.toolpath
    rng = np.random.default_rng(31)
    kn, truth, _s0 = C.draw("tool-wear", rng)
    p = E.Model.of(*kn(0.3e-6))
    fld = dataclasses.replace(spec.field, nx=90, ny=70, pitch_x=4.5e-6,
                              pitch_y=4.5e-6, center_x=9.8e-3, center_y=0.0)
    traj = C.tool_series(case, E.Model(), None, spec.path.duration)
    z = C.sweep_surface(case, p, traj, fld)
    z = z + C.INSTRUMENT_NOISE * rng.standard_normal(z.shape)
    np.savez(tmp_path / "surface.npz", z=z, dx=fld.pitch_x, dy=fld.pitch_y,
             x0=fld.x0, y0=fld.y0)
    (tmp_path / "manifest.toml").write_text(
        f'[case]\nmachine = "seed-prototype"\ntoolpath = "{C.TOOLPATH.as_posix()}"\n'
        f"bandwidth = {C.BANDWIDTH}\nmoving-mass = {C.MASS}\n\n"
        '[[recording]]\npath = "surface.npz"\nkind = "surface"\n')
    names = ("tool-wear", "tool-radius-error", "thermal-drift")
    d = diagnose(tmp_path / "manifest.toml", effects=[get_effect(n) for n in names],
                 max_terms=2)
    ex = sorted(d.to_dict()["explanations"], key=lambda e: -e["delta_bic"])
    assert ex and ex[0]["effect"] == "tool-wear", [(e["effect"], e["parameters"])
                                                   for e in ex]
    want = truth(0.3e-6)["growth"]
    assert ex[0]["parameters"]["growth"] == pytest.approx(want, rel=0.3)


def test_cutting_speed_of_an_nc_spiral_is_the_surface_speed(tmp_path):
    """An NC spiral at 13.9 rev/s (0.5 deg per 0.1 ms block) from r = 0.30 to
    0.20 mm at a constant feed: the edge cuts 2 pi n mean(r) = 21.8 mm/s
    (closed form, the radial feed neglected: 1e-5 of it)."""
    from servosurf.diagnose.effects._tool_wear import cutting_speed
    from servosurf.toolpath import load_toolpath

    rows = []
    for k in range(10 * 720 + 1):
        r = 0.30 - 0.010 * k / 720
        rows.append(f"C{(k * 0.5) % 360:.6f} X{r:.6f} Z-0.002")
    (tmp_path / "spiral.nc").write_text("\n".join(rows) + "\n")
    toml = tmp_path / "spiral.toml"
    toml.write_text(
        'kind = "nc"\n[nc]\nprogram = "spiral.nc"\nblock-time = 1e-4  # s\n'
        'reference = "tip"\nrotation = "ccw"\n[tool]\nnose-radius = 0.5e-3  # m\n')
    spec = load_toolpath(toml)
    n = 0.5 / 360 / 1e-4  # rev/s
    want = 2 * np.pi * n * 0.25e-3
    assert cutting_speed(spec) == pytest.approx(want, rel=1e-4)
