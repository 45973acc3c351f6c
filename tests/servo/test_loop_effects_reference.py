"""The loop-side catalogue effects in the one loop kernel: numpy oracle, closed forms.

Each catalogue effect that acts inside the FTS loop (flexure hysteresis, friction,
the converters' dead band) reaches the kernel through its ``nonlinearity()`` hook.
Oracles:

* :mod:`reference.naive_loop` (plain numpy, named fields) on the hook's fields;
* closed forms of the held loop (integral action: at rest the motor force balances
  the flexure, so the coil current carries every extra static force):
  Bouc-Wen memory (``z = z_y (1 - exp(-d / z_y))`` on a first loading, elastic
  unloading ``dz = dd`` while ``z > 0``), friction on a steady ramp
  (``F_c tanh(V / v_s)``), the dead band's offset of the held command (``b``);
* the ADC reading on its grid; the quantisation-noise floors
  ``step / sqrt(6 fs)`` (white noise of variance ``step^2 / 12`` per sample);
* sensor pickup lines in the simulated following error only.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from reference.naive_loop import closed_loop

from servosurf.diagnose import effects as E
from servosurf.servo import Nonlinearity, ServoLoop, load_machine

#: Kernel against the numpy oracle: same arithmetic up to fast-math reassociation.
RTOL_KERNEL = 1e-9
#: Closed forms of the held loop: the integrator's residual after 0.25 s of hold
#: (its slowest pole is about 24 Hz) and the carriage's share of the flexure force
#: (k3 >> k2), relative to the static current.
RTOL_HELD = 2e-3


@pytest.fixture(scope="module")
def loop() -> ServoLoop:
    return ServoLoop(load_machine().with_moving_mass(0.175).with_bandwidth(468.0))


def _nl(term) -> Nonlinearity:
    return Nonlinearity(**term.nonlinearity())


TERMS = {
    "flexure-hysteresis": E.FlexureHysteresisParams(2e3, 1.5e-6),
    "friction": E.FrictionParams(0.03, 2e-5),
    "converter-quantisation": E.ConverterQuantisationParams(dead_band=3e-4),
}


@pytest.mark.parametrize("name", sorted(TERMS))
def test_loop_effect_hooks_match_numpy(loop, name):
    nl = _nl(TERMS[name])
    n = 2000
    t = np.arange(n) / loop.fs
    ref = 6e-6 * np.sin(2 * np.pi * 350.0 * t) + 1e-6 * np.sin(2 * np.pi * 2100 * t)
    rng = np.random.default_rng(11)  # seeded: any draw works
    noise = rng.standard_normal(n) * 1e-4
    got = loop.simulate(reference=ref, current_noise=noise, nonlinearity=nl)
    want = closed_loop(loop, reference=ref, current_noise=noise, nonlinearity=nl)
    for key in want:
        scale = max(float(np.max(np.abs(want[key]))), 1e-300)
        np.testing.assert_allclose(got[key], want[key], rtol=0,
                                   atol=RTOL_KERNEL * scale, err_msg=key)
    lin = loop.simulate(reference=ref, current_noise=noise)
    assert np.max(np.abs(got["following_error"] - lin["following_error"])) > 1e-10


def _ramps(fs, legs, leg=0.1, hold=0.25):
    """Reference through ``legs`` (positions in m), each reached in ``leg`` s on a
    raised cosine (no velocity step), then held ``hold`` s."""
    pts = [0.0]
    n = int(leg * fs)
    s = 0.5 - 0.5 * np.cos(np.pi * np.arange(1, n + 1) / n)
    for x in legs:
        pts += list(pts[-1] + (x - pts[-1]) * s)
    pts += [legs[-1]] * int(hold * fs)
    return np.array(pts)


def _held(out, key="current", tail=2000):
    return float(np.mean(out[key][-tail:]))


def test_bouc_wen_memory_in_the_held_current(loop):
    """After a first loading to X the element holds z_y (1 - exp(-X / z_y)); after
    loading to 2X and unloading to X it holds z(2X) - X (elastic unloading): the
    held coil current differs from the linear loop's by k_h z / Kf. The legs are
    slow (0.6 s): the loop's lag behind the hysteretic force at the reversal
    shortens the loading by a share that falls as 1 / leg time (9 % at 20 ms, 0.06
    % at 0.6 s)."""
    term = TERMS["flexure-hysteresis"]
    kh, zy = term.stiffness, term.yield_displacement
    kf = loop.machine.actuator.force_constant
    x = 0.5 * zy
    z_up = zy * -math.expm1(-x / zy)
    z_peak = zy * -math.expm1(-2 * x / zy)
    z_down = z_peak - x
    assert z_down > 0  # still on the elastic branch
    for legs, z in (([x], z_up), ([2 * x, x], z_down)):
        r = _ramps(loop.fs, legs, leg=0.6)
        lin = loop.simulate(reference=r)
        hyst = loop.simulate(reference=r, nonlinearity=_nl(term))
        assert abs(_held(hyst, "tool") - x) < 1e-3 * x  # the loop holds X
        d_cur = _held(hyst) - _held(lin)
        want = kh * z / kf
        assert d_cur == pytest.approx(want, rel=RTOL_HELD)
    # memory: the same position, two currents (a memoryless term gives one)
    assert abs(z_up - z_down) * kh / kf > 100 * RTOL_HELD * abs(want)


def test_friction_on_a_steady_ramp(loop):
    """On a ramp at V the friction force is F_c tanh(V / v_s); integral action
    leaves it in the coil current: Delta I = F_c tanh(V / v_s) / Kf."""
    term = TERMS["friction"]
    kf = loop.machine.actuator.force_constant
    fs = loop.fs
    v = 1e-4  # m/s
    n = int(0.4 * fs)
    r = v * np.arange(n) / fs
    lin = loop.simulate(reference=r)
    fr = loop.simulate(reference=r, nonlinearity=_nl(term))
    d_cur = _held(fr) - _held(lin)
    want = term.level * math.tanh(v / term.velocity) / kf
    assert d_cur == pytest.approx(want, rel=RTOL_HELD)
    # at rest the smoothed law carries no force: a held position is unchanged
    r0 = _ramps(fs, [2e-6], hold=0.4)
    d_rest = _held(loop.simulate(reference=r0, nonlinearity=_nl(term))) - _held(
        loop.simulate(reference=r0))
    assert abs(d_rest) < 1e-3 * want


def test_dead_band_offsets_the_held_command(loop):
    """Held at X > 0 the amplifier needs the linear loop's command u0 > 0; with a
    dead band b the controller must command u0 + b (same current)."""
    b = TERMS["converter-quantisation"].dead_band
    r = _ramps(loop.fs, [3e-6])
    lin = loop.simulate(reference=r)
    dead = loop.simulate(reference=r, nonlinearity=_nl(TERMS["converter-quantisation"]))
    assert _held(lin, "u") > 0
    assert _held(dead, "u") - _held(lin, "u") == pytest.approx(b, rel=RTOL_HELD)
    assert _held(dead) == pytest.approx(_held(lin), rel=RTOL_HELD)


def test_adc_step_puts_the_reading_on_its_grid(loop):
    q = 2e-9
    n = 3000
    t = np.arange(n) / loop.fs
    ref = 5e-6 * np.sin(2 * np.pi * 300.0 * t)
    out = loop.simulate(reference=ref, nonlinearity=Nonlinearity(adc_step=q))
    k = out["sensor"] / q
    np.testing.assert_allclose(k, np.round(k), rtol=0, atol=1e-6)
    assert np.unique(np.round(k)).size > 100  # the reading moves over many steps


def test_quantisation_noise_floors():
    """DAC and ADC steps add white noise of variance step^2 / 12 per sample (one-
    sided density step^2 / (6 fs)). The DAC's is a current floor the amplifier's
    roll-off shapes, in quadrature with the machine file's; the ADC's is added to
    the sensor-noise PSD after its roll-off: white up to the Nyquist frequency,
    as the Welch PSD of a rounding error is (the oracle: scipy on rounded numbers,
    not servosurf's PSD code)."""
    import scipy.signal

    from servosurf.noise import evaluate_psd

    m = load_machine()
    fs = m.controller.sample_rate
    dq, aq = 3e-4, 2e-9
    got = E.ConverterQuantisationParams(dac_step=dq, adc_step=aq).machine(m)
    d0, d1 = m.disturbances, got.disturbances
    i_q = m.actuator.current_gain * dq / math.sqrt(6 * fs)
    assert d1.current_noise.floor == pytest.approx(
        math.sqrt(d0.current_noise.floor**2 + i_q**2), rel=1e-12)
    # the rest of the machine is untouched
    assert dataclasses.replace(d1, current_noise=d0.current_noise,
                               sensor_noise=d0.sensor_noise) == d0
    assert dataclasses.replace(d1.sensor_noise, white=0.0) == d0.sensor_noise
    assert E.ConverterQuantisationParams(dead_band=1e-3).machine(m) is m
    # a rounded signal: the rounding error's variance is step^2 / 12 and its PSD
    # is flat to fs / 2 (at the sensor's 15 kHz corner and at 0.45 fs alike)
    rng = np.random.default_rng(5)  # seeded: any draw works
    x = np.cumsum(rng.standard_normal(400_000)) * 3 * aq
    err = aq * np.floor(x / aq + 0.5) - x
    assert np.var(err) == pytest.approx(aq**2 / 12, rel=0.02)
    f, pxx = scipy.signal.welch(err, fs=fs, nperseg=4096)
    for f0 in (1e3, m.disturbances.sensor_noise.corner, 0.45 * fs):
        sel = np.abs(f - f0) < 0.02 * fs
        added = (evaluate_psd(d1.sensor_noise, np.array([f0]))
                 - evaluate_psd(d0.sensor_noise, np.array([f0])))[0]
        assert added == pytest.approx(np.mean(pxx[sel]), rel=0.05, abs=0.0), f0


def test_sensor_pickup_is_in_the_following_error_only():
    """simulate(hooks=[pickup]) adds -a cos(2 pi f t) to the following error (the
    logged reading carries +a cos) and leaves the surface bit for bit."""
    from servosurf.simulation import simulate
    from servosurf.toolpath import load_toolpath

    spec = load_toolpath("toolpaths/lenslet_5um.toml")
    spec = dataclasses.replace(spec, field=dataclasses.replace(
        spec.field, nx=40, ny=30, pitch_x=1.5e-6, pitch_y=1.5e-6))
    m = load_machine().with_moving_mass(0.175).with_bandwidth(468.0)
    f0, a = 250.0, 3e-9
    base = simulate(spec, machine=m, parts=("tracking",))
    got = simulate(spec, machine=m, parts=("tracking",),
                   hooks=[E.SensorPickupParams(f0, a)])
    np.testing.assert_array_equal(got.surface.z, base.surface.z)
    np.testing.assert_allclose(got.following_error - base.following_error,
                               -a * np.cos(2 * np.pi * f0 * got.t), rtol=0,
                               atol=1e-6 * a)
