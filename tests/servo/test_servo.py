"""Servo model: plant vs the paper's closed forms, loop vs python-control, tuning."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from servosurf.errors import ConfigError, ModelError
from servosurf.servo import (
    PIDF,
    Machine,
    ServoLoop,
    load_machine,
    paper_eq_frf,
    plant_from_machine,
    tune_pidf,
)

RTOL_FRF = 1e-9  # two exact evaluations of the same rational functions


@pytest.fixture(scope="module")
def machine() -> Machine:
    return load_machine().with_moving_mass(0.175).with_bandwidth(468.0)


def test_plant_matches_paper_closed_forms(machine):
    f = np.geomspace(1, 50e3, 400)
    net = plant_from_machine(machine).frf(f)
    eq = paper_eq_frf(machine, f)
    for key in ("tool_force", "actuator_force", "base"):
        np.testing.assert_allclose(net[key][:, 0], eq[key], rtol=RTOL_FRF)


def test_cached_plant_frfs_stay_each_plants_own(machine):
    """The plant FRF cache (a diagnosis asks for a few plants thousands of times)
    returns each plant's closed forms, however the requests interleave, and its
    arrays cannot be changed in place by one caller under another."""
    f = np.geomspace(1, 50e3, 300)
    other = dataclasses.replace(
        machine, mechanics=dataclasses.replace(machine.mechanics,
                                               k2=2.0 * machine.mechanics.k2))
    for _ in range(3):
        for m in (machine, other):
            net = plant_from_machine(m).frf(f)
            eq = paper_eq_frf(m, f)
            for key in ("tool_force", "actuator_force", "base"):
                np.testing.assert_allclose(net[key][:, 0], eq[key], rtol=RTOL_FRF)
    g = f.copy()
    g[-1] *= 1.0 + 1e-3  # another grid, if only by its last point
    np.testing.assert_allclose(plant_from_machine(machine).frf(g)["base"][:, 0],
                               paper_eq_frf(machine, g)["base"], rtol=RTOL_FRF)
    with pytest.raises(ValueError, match="read-only"):
        net["base"][0, 0] = 0.0


def test_plant_static_compliance(machine):
    # at DC a force on the tool sees k1 in series with (k2 in series with k3) + k5
    m = machine.mechanics
    ground = 1 / (1 / m.k2 + 1 / m.k3) + m.k5
    expected = 1 / m.k1 + 1 / ground
    x = plant_from_machine(machine).frf(np.array([1e-4]))["tool_force"][0, 0]
    np.testing.assert_allclose(x.real, expected, rtol=1e-6)


def test_tuning_hits_crossover_and_margin(machine):
    loop = ServoLoop(machine)
    lc = loop.loop_gain(np.array([468.0]))[0]
    np.testing.assert_allclose(abs(lc), 1.0, rtol=1e-9)
    np.testing.assert_allclose(180 + np.degrees(np.angle(lc)), 60.0, atol=1e-7)
    mg = loop.margins()
    np.testing.assert_allclose(mg["crossover_hz"], 468.0, rtol=1e-3)
    assert mg["bandwidth_3db_hz"] > mg["crossover_hz"]


def test_tuning_infeasible_raises(machine):
    c = dataclasses.replace(
        machine.controller, phase_margin=89.0, derivative_filter_ratio=1.0
    )
    with pytest.raises(ModelError, match="cannot tune"):
        tune_pidf(dataclasses.replace(machine, controller=c))


def _control_loop(loop: ServoLoop):
    """The same continuous loop built with python-control, input by input."""
    ct = pytest.importorskip("control")
    mach = loop.machine
    a, b, cx = loop.plant.state_space()
    sd = 1 if mach.sensor.location == "carrier" else 0
    # plant with inputs [F, Fa], outputs [x1, x_meas]
    plant = ct.ss(a, b, np.vstack([cx[0], cx[sd]]), np.zeros((2, 2)))
    wi, ws = mach.actuator.corner, mach.sensor.corner
    # state-space forms keep the high-order products well conditioned
    amp = ct.ss(ct.tf([mach.actuator.current_gain * wi**2], [1, 2 * wi, wi**2]))
    sens = ct.ss(ct.tf([ws**2], [1, 2 * ws, ws**2]))
    num, den = loop.pidf.tf_coefficients()
    pid = ct.ss(ct.tf(num, den))
    return ct, plant, amp, sens, pid


def test_closed_loop_matches_python_control(machine):
    loop = ServoLoop(machine)
    ct, plant, amp, sens, pid = _control_loop(loop)
    mach = machine
    bl, s_gain = mach.actuator.force_constant, mach.sensor.sensitivity
    f = np.geomspace(10, 30e3, 300)
    ours = loop.frf(f, discrete=False).paths
    # forward path from error (m) to Fa: S * C * amp * Bl
    fwd = s_gain * pid * amp * bl
    p_a1, p_am = plant[0, 1], plant[1, 1]
    p_f1, p_fm = plant[0, 0], plant[1, 0]
    loop_tf = fwd * p_am * sens
    # reference -> tool and following error
    s_tf = ct.feedback(ct.ss([], [], [], [[1.0]]), loop_tf)
    t_r_tool = p_a1 * fwd * s_tf
    # force -> tool: p_f1 - p_a1 fwd sens p_fm / (1 + L)
    f_tool = p_f1 - p_a1 * fwd * sens * p_fm * s_tf
    # current noise -> tool: Bl p_a1 - p_a1 fwd sens Bl p_am / (1 + L)
    i_tool = bl * p_a1 - p_a1 * fwd * sens * bl * p_am * s_tf
    w = 2 * np.pi * f
    for key, sys in (
        ((("reference", "tool")), t_r_tool),
        ((("reference", "following_error")), s_tf),
        ((("force", "tool")), f_tool),
        ((("current_noise", "tool")), i_tool),
    ):
        ref = ct.frequency_response(sys, w).complex.ravel()
        np.testing.assert_allclose(ours[key], ref, rtol=1e-6, err_msg=str(key))


def test_discrete_loop_matches_time_simulation(machine):
    """Steady-state sine response of the exact discrete loop vs the FRF model."""
    loop = ServoLoop(machine)
    fs = loop.fs
    for f0 in (100.0, 1000.0):
        n = int(fs * 0.2)
        t = np.arange(n) / fs
        r = 1e-6 * np.sin(2 * np.pi * f0 * t)
        out = loop.simulate(reference=r)
        tail = slice(n // 2, n)
        # project onto the sine and cosine of f0 over whole periods
        c = np.exp(-2j * np.pi * f0 * t[tail])
        h_sim = 2 * np.mean(out["tool"][tail] * c) / (2 * np.mean(r[tail] * c))
        h_frf = loop.frf(np.array([f0])).paths[("reference", "tool")][0]
        np.testing.assert_allclose(abs(h_sim), abs(h_frf), rtol=2e-3)
        assert abs(np.angle(h_sim / h_frf)) < np.radians(0.5)


def test_stability_changes_with_bandwidth():
    m = load_machine().with_moving_mass(0.175)
    assert ServoLoop(m.with_bandwidth(468)).is_stable()
    assert not ServoLoop(m.with_bandwidth(1700)).is_stable()


def test_step_response_matches_python_control(machine):
    """Continuous closed-loop step response (r -> measured) vs python-control."""
    loop = ServoLoop(machine)
    ct, plant, amp, sens, pid = _control_loop(loop)
    fwd = machine.sensor.sensitivity * pid * amp * machine.actuator.force_constant
    t_meas = ct.feedback(fwd * plant[1, 1] * sens, 1)
    t = np.linspace(0, 0.01, 2001)
    _, y = ct.step_response(t_meas, t)
    f = np.geomspace(1, 20e3, 200)
    # compare the FRF, which fixes the step response of an LTI system uniquely
    ours = loop.frf(f, discrete=False).paths[("reference", "sensor")]
    ref = ct.frequency_response(t_meas, 2 * np.pi * f).complex.ravel()
    np.testing.assert_allclose(ours, ref, rtol=1e-6)
    assert abs(y[-1] - 1.0) < 0.05  # integral action: no steady-state error


def test_explicit_gains_used():
    m = load_machine()
    c = dataclasses.replace(m.controller, kp=1.0, ki=10.0, kd=1e-4, tf=1e-5)
    loop = ServoLoop(dataclasses.replace(m, controller=c))
    assert loop.pidf == PIDF(1.0, 10.0, 1e-4, 1e-5, m.controller.sample_rate)


def test_partial_gains_rejected():
    with pytest.raises(ConfigError, match="kp, ki, kd, tf"):
        dataclasses.replace(load_machine().controller, kp=1.0)


def test_moving_mass_goes_to_configured_mass():
    m = load_machine()
    heavy = m.with_moving_mass(0.175)
    assert heavy.mechanics.moving_mass == pytest.approx(0.175)
    target = m.mechanics.added_mass_on
    assert getattr(heavy.mechanics, target) == pytest.approx(
        getattr(m.mechanics, target) + 0.1
    )
    with pytest.raises(ConfigError, match="--mass"):
        m.with_moving_mass(0.001)
