"""simulate(hooks=...) with hooks on the FTS loop: perturbation(), nonlinearity(),
base_lines() and workpiece() (servosurf._hooks), against independent routes to the
same machine."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from servosurf.cutting import load_workpiece
from servosurf.errors import ConfigError
from servosurf.servo import LoopPerturbation, ServoLoop, load_machine
from servosurf.simulation import simulate
from servosurf.toolpath import load_toolpath

LENSLET = "toolpaths/lenslet_5um.toml"


@pytest.fixture(scope="module")
def spec():
    """The 5 um lenslets on a 60 x 50 field at 1.5 um (fast)."""
    s = load_toolpath(LENSLET)
    return dataclasses.replace(s, field=dataclasses.replace(
        s.field, nx=60, ny=50, pitch_x=1.5e-6, pitch_y=1.5e-6))


@pytest.fixture(scope="module")
def machine():
    """The paper's 0.175 kg set-up with the tuned controller gains written in."""
    m = load_machine().with_moving_mass(0.175).with_bandwidth(468.0)
    pidf = ServoLoop(m).pidf
    c = dataclasses.replace(m.controller, kp=pidf.kp, ki=pidf.ki, kd=pidf.kd,
                            tf=pidf.tf)
    return dataclasses.replace(m, controller=c)


class _Hook:
    """A hook with the given loop methods (None: absent)."""

    def __init__(self, pert=None, nonlin=None, lines=None, wp=None):
        if pert is not None:
            self.perturbation = lambda: pert
        if nonlin is not None:
            self.nonlinearity = lambda: dict(nonlin)
        if lines is not None:
            self.base_lines = lambda: tuple(lines)
        if wp is not None:
            self.workpiece = wp


def _same(a, b):
    np.testing.assert_array_equal(a.surface.z, b.surface.z)
    for k in a.deviation:
        np.testing.assert_array_equal(a.deviation[k], b.deviation[k], err_msg=k)
    np.testing.assert_array_equal(a.following_error, b.following_error)


def test_hooks_that_change_nothing_leave_the_results_bit_identical(spec, machine):
    base = simulate(spec, machine=machine, seed=3)
    idle = _Hook(pert=LoopPerturbation(), nonlin={}, lines=())
    _same(simulate(spec, machine=machine, seed=3, hooks=[idle]), base)
    # a current limit far above any demand never clips
    _same(simulate(spec, machine=machine, seed=3,
                   hooks=[_Hook(nonlin={"max_current": 1e3})]), base)


def test_perturbation_hook_is_the_perturbed_machine_under_the_installed_controller(
        spec, machine):
    """A delay and a recalibrated mass as hooks equal simulating the machine file
    that has them, with the installed controller's gains held (vibration too)."""
    pert = LoopPerturbation(extra_delay=1.3e-6, moving_mass=0.18)
    got = simulate(spec, machine=machine, seed=4, hooks=[_Hook(pert=pert)])
    want = simulate(spec, machine=pert.apply(machine), seed=4)
    _same(got, want)
    assert np.max(np.abs(got.surface.z - simulate(spec, machine=machine,
                                                  seed=4).surface.z)) > 1e-10


def test_perturbations_of_several_hooks_compose(spec, machine):
    a = _Hook(pert=LoopPerturbation(extra_delay=1e-6))
    b = _Hook(pert=LoopPerturbation(extra_delay=0.5e-6, force_constant=7.5))
    got = simulate(spec, machine=machine, parts=("tracking",), hooks=[a, b])
    pert = LoopPerturbation(extra_delay=1.5e-6, force_constant=7.5)
    want = simulate(spec, machine=pert.apply(machine), parts=("tracking",))
    np.testing.assert_allclose(got.surface.z, want.surface.z, rtol=0,
                               atol=1e-18)  # the two delays add in another order
    clash = _Hook(pert=LoopPerturbation(force_constant=7.0))
    with pytest.raises(ConfigError, match="force_constant"):
        simulate(spec, machine=machine, parts=("tracking",), hooks=[b, clash])


def test_workpiece_hook_is_the_workpiece_argument(spec, machine):
    wp = load_workpiece(None)
    k = 1.4 * wp.material.specific_thrust_pressure
    hard = dataclasses.replace(wp, material=dataclasses.replace(
        wp.material, specific_thrust_pressure=k))
    hook = _Hook(wp=lambda w: dataclasses.replace(w, material=dataclasses.replace(
        w.material, specific_thrust_pressure=k)))
    _same(simulate(spec, machine=machine, seed=5, hooks=[hook]),
          simulate(spec, machine=machine, seed=5, workpiece=hard))


def test_base_line_hook_adds_the_loops_steady_response(spec, machine):
    """A base line of amplitude a at f adds a |H(f)| cos(2 pi f t + arg H) to the
    tool height and a |H_fe(f)| ... to the following error, H from the loop's FRF
    (python-control-free closed form: ServoLoop.frf)."""
    f0, a = 730.0, 20e-9
    base = simulate(spec, machine=machine, parts=("tracking",))
    got = simulate(spec, machine=machine, parts=("tracking",),
                   hooks=[_Hook(lines=[(f0, a)])])
    h = ServoLoop(machine).frf(np.array([f0])).paths
    t = got.t
    for key, arr in (("tool", got.deviation["hooks"]),
                     ("following_error", got.following_error - base.following_error)):
        hh = h[("base", key)][0]
        np.testing.assert_allclose(
            arr, a * abs(hh) * np.cos(2 * np.pi * f0 * t + np.angle(hh)),
            rtol=0, atol=1e-9 * a)
    assert math.isclose(float(np.max(np.abs(got.deviation["hooks"]))),
                        a * abs(h[("base", "tool")][0]), rel_tol=1e-3)


def test_loop_hooks_need_the_fts_loop(spec, machine):
    with pytest.raises(ConfigError, match="FTS servo loop"):
        simulate(spec, machine=machine, parts=("kinematic",),
                 hooks=[_Hook(nonlin={"kf_b1": 1e3})])
