"""How recordings were acquired, as the diagnosis must read them (issue 19 items 5-6).

* A command record logged at another rate than the controller's comes through an
  anti-alias filter, which rings on the loop's start-up step: the diagnosis leaves
  the first :data:`RESAMPLED_SETTLE` out (projected out of data and model). The
  oracle is scipy's polyphase FIR decimator (``resample_poly``, a Kaiser window of
  its own design) applied to the controller-rate record with the loop at rest
  before it, not anything of the diagnosis.
* A ring profile measured from a start angle known to a fraction of a micrometre
  is rotated about the spindle axis: a shift along the circle at every point, which
  translations of the circle cannot represent; it is a nuisance of the profile.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import resample_poly

from servosurf.diagnose import Model
from servosurf.diagnose._blocks import RESAMPLED_SETTLE, Context, PointsBlock, TimeBlock
from servosurf.diagnose._sim import CaseModel
from servosurf.diagnose._surface import PointSet, surface_heights
from servosurf.servo import load_machine
from servosurf.toolpath import load_toolpath


@pytest.fixture(scope="module")
def ctx() -> Context:
    machine = load_machine().with_moving_mass(0.175).with_bandwidth(468.0)
    return Context(CaseModel(machine, load_toolpath("lenslet_5um")))


def _decimated_air_cut(ctx, n_half: int):
    """An air cut of the lenslet command from rest, logged at fs / 2 through
    scipy's anti-alias FIR; the loop idles (zero command, zero error) before."""
    case = ctx.case
    n = 2 * n_half
    t = np.arange(n) / case.fs
    cmd = case.toolpath.path.z_at(t)
    fe = case.simulate(Model(), reference=cmd)["fe"]
    pad = 400  # the filter sees the idle loop before the record
    fe_pad = np.concatenate([np.zeros(pad), fe, fe[-1] + np.zeros(pad)])
    fe_dec = resample_poly(fe_pad, 1, 2, window=("kaiser", 10.0))[pad // 2:][:n_half]
    return {"fe": fe_dec, "command": cmd[::2]}, fe[::2]


def test_decimated_record_is_compared_after_the_filter_settled(ctx):
    rec, plain = _decimated_air_cut(ctx, 8192)
    fs = ctx.case.fs / 2
    # the filter rings on the start-up step (micrometres), then agrees with the
    # plain samples far below the noise
    head = int(math.ceil(RESAMPLED_SETTLE * fs))
    assert np.max(np.abs(rec["fe"][:head] - plain[:head])) > 1e-8
    block = TimeBlock(ctx, "aircut", [rec], fs, Model())
    w = block.residual(Model())
    # whitened: N(0, 1) per value for noise; this record has none, so only the
    # decimator's passband ripple and the filter tail remain
    assert np.sum(w**2) < 0.05 * w.size, (np.sum(w**2), w.size)
    # the same record sampled at the controller rate needs no settling
    full = TimeBlock(ctx, "full", [{"fe": ctx.case.simulate(
        Model(), reference=ctx.case.toolpath.path.z_at(
            np.arange(16384) / ctx.case.fs))["fe"],
        "command": ctx.case.toolpath.path.z_at(np.arange(16384) / ctx.case.fs)}],
        ctx.case.fs, Model())
    assert full.bases[0].shape[1] < block.bases[0].shape[1] - head // 2


def test_ringing_would_dominate_without_the_settling(ctx, monkeypatch):
    import servosurf.diagnose._blocks as blocks

    rec, _ = _decimated_air_cut(ctx, 8192)
    monkeypatch.setattr(blocks, "RESAMPLED_SETTLE", 0.0)
    block = TimeBlock(ctx, "unsettled", [rec], ctx.case.fs / 2, Model())
    w = block.residual(Model())
    assert np.sum(w**2) > 10 * w.size


def _ring(ctx, dx=6e-6, angle=0.4):
    path = ctx.case.toolpath.path
    r = float(path.ring_radii()[0])
    n = int(0.25 * 2 * math.pi * r / dx)  # a quarter of the ring
    s = dx * np.arange(n)
    th = angle + s / r
    return r, s, th


def _ring_block(ctx, shift):
    """A ring profile measured ``shift`` (m) along the circle from where the
    manifest says it starts, with a piston."""
    r, s, th = _ring(ctx)
    x, y = r * np.cos(th), r * np.sin(th)
    rot = shift / r
    xr = math.cos(rot) * x - math.sin(rot) * y
    yr = math.sin(rot) * x + math.cos(rot) * y
    traj = ctx.trajectory(Model())
    z = surface_heights(ctx.case, PointSet(ctx.case, xr, yr), Model(), traj) + 7e-9
    return PointsBlock(ctx, "ring", "profile", x, y, z, Model(), along=s)


def test_ring_profile_start_angle_is_a_nuisance(ctx):
    block = _ring_block(ctx, 0.1e-6)
    r = block.nuisance_fit(Model())
    # first order in the shift: the remainder is (shift^2 / 2) d2z/ds2
    assert np.sqrt(np.mean(r**2)) < 2e-11, np.sqrt(np.mean(r**2))
    # the shift is visible: heights at the nominal points differ by much more
    raw = block.z - surface_heights(ctx.case, block.pts, Model(),
                                    ctx.trajectory(Model()))
    assert np.sqrt(np.mean((raw - raw.mean()) ** 2)) > 20 * np.sqrt(np.mean(r**2))


def _colored(rng, psd, n, fs):
    """Gaussian series of one-sided PSD ``psd(f)`` (plain FFT filtering of white
    noise on a buffer four times longer, the middle kept; nothing below
    fs / 4096, as the machine file documents)."""
    m = 4 * n
    f = np.fft.rfftfreq(m, 1.0 / fs)
    gain = np.zeros(f.size)
    on = f >= fs / 4096
    gain[on] = np.sqrt(psd(f[on]) * fs / 2.0)
    x = np.fft.irfft(np.fft.rfft(rng.standard_normal(m)) * gain, m)
    return x[n : 2 * n]


@pytest.mark.parametrize("sensor_factor", [1.0, 1.6])
def test_record_noise_level_is_profiled_per_source(ctx, sensor_factor):
    """An air cut whose sensor noise has 1.6 x the machine file's power: the
    record's profiled sensor level is 1.6, and its whitened residual is N(0, 1)
    again; with the machine file's noise nothing is profiled. (The current noise
    dominates only a few dozen bins below 300 Hz: its level is not tested.)"""
    from servosurf.noise import evaluate_psd

    case = ctx.case
    fs = case.fs
    n = 32768
    d = case.machine.disturbances
    rng = np.random.default_rng(21)  # seeded: any draw works
    s_n = _colored(rng, lambda f: sensor_factor * evaluate_psd(d.sensor_noise, f),
                   n, fs)
    i_n = _colored(rng, lambda f: evaluate_psd(d.current_noise, f), n, fs)
    cmd = case.toolpath.path.z_at(np.arange(n) / fs)
    fe = case.loop.simulate(reference=cmd, sensor_noise=s_n,
                            current_noise=i_n)["following_error"]
    block = TimeBlock(ctx, f"noisy{sensor_factor}", [{"fe": fe, "command": cmd}], fs,
                      Model())
    got = block.noise_factors
    if sensor_factor == 1.0:
        assert got.get("sensor_noise", 1.0) == 1.0, got
    else:
        assert abs(got["sensor_noise"] / sensor_factor - 1) < 0.08, got
    w = block.residual(Model())
    assert abs(np.mean(w**2) - 1) < 0.05


@pytest.mark.parametrize("shift", [0.23e-6, -0.6e-6])
def test_ring_profile_is_registered_not_only_linearised(ctx, shift):
    """A ring profile rotated by a fraction of a micrometre along the circle: the
    block finds the rotation (``registration["along_m"]``) and evaluates the model
    there, so what is left is the noise-free remainder of the iteration, far below
    the second-order remainder the linearised nuisance leaves (which named a null
    case's rotation thermal drift). The oracle is the rotation the test applied."""
    import servosurf.diagnose._blocks as blocks

    block = _ring_block(ctx, shift)
    got = block.registration["along_m"]
    assert got == pytest.approx(shift, rel=0.01, abs=0.0), got
    # translations of the arc are nearly collinear with the rotation on a quarter
    # ring: they may take a few picometres, not the shift
    for k in ("x_m", "y_m"):
        assert abs(block.registration[k]) < 0.02 * abs(shift), block.registration
    rms_reg = np.sqrt(np.mean(block.nuisance_fit(Model()) ** 2))
    saved = blocks.REGISTER_ITERATIONS
    try:
        blocks.REGISTER_ITERATIONS = 0  # the linearised nuisance alone
        lin = _ring_block(ctx, shift)
    finally:
        blocks.REGISTER_ITERATIONS = saved
    assert lin.registration["along_m"] == 0.0
    rms_lin = np.sqrt(np.mean(lin.nuisance_fit(Model()) ** 2))
    assert rms_reg < 0.01 * rms_lin, (rms_reg, rms_lin)


def test_unshifted_ring_profile_is_left_where_it_is(ctx):
    """No shift, no move: a registration step below REGISTER_TOL of the pitch is
    not taken (the points stay the manifest's)."""
    block = _ring_block(ctx, 0.0)
    assert block.registration == {"x_m": 0.0, "y_m": 0.0, "along_m": 0.0}
