"""Tests of the diagnosis simulator (servosurf.diagnose._sim) under catalogue terms."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from servosurf.diagnose import CATALOGUE, CaseModel, Model
from servosurf.diagnose import effects as E
from servosurf.servo import load_machine
from servosurf.servo._ident import set_param


def _nominal():
    return load_machine().with_moving_mass(0.175).with_bandwidth(468.0)


def _with_fixed_gains(m, pidf):
    """The machine with the controller gains of ``pidf`` written in (not redesigned)."""
    c = dataclasses.replace(m.controller, kp=pidf.kp, ki=pidf.ki, kd=pidf.kd,
                            tf=pidf.tf)
    return dataclasses.replace(m, controller=c)


def test_sensor_bandwidth_recalibration_is_the_machine_with_that_sensor():
    """A recalibrated sensor bandwidth B simulates the machine whose sensor has
    bandwidth B under the installed controller: open-loop FRF and a 100 Hz
    tracking record equal those of a CaseModel built on that machine."""
    m = _nominal()
    case = CaseModel(m)
    m20 = _with_fixed_gains(set_param(m, "sensor.bandwidth", 20e3), case.pidf)
    ref = CaseModel(m20)
    p = Model.of(E.RecalibrationParams(sensor_bandwidth=20e3))
    f = np.geomspace(10.0, 60e3, 300)
    got = case.paths(p, f)["open_loop"]
    want = ref.paths(Model(), f)["open_loop"]
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # and it is not the nominal sensor (the knob does something)
    nom = case.paths(Model(), f)["open_loop"]
    assert np.max(np.abs(got / nom - 1)) > 0.1
    t = np.arange(4000) / case.fs
    cmd = 10e-6 * np.sin(2 * np.pi * 100.0 * t)
    a = case.simulate(p, reference=cmd)["fe"]
    b = ref.simulate(Model(), reference=cmd)["fe"]
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-15)
    # the lag of the sensor is in the following error: 15 vs 20 kHz differ by nm
    c = case.simulate(Model(), reference=cmd)["fe"]
    assert np.sqrt(np.mean((a - c) ** 2)) > 1e-9


def test_recalibration_frees_the_sensor_bandwidth_around_the_nominal():
    recal = next(e for e in CATALOGUE if e.name == "recalibration")
    assert "sensor_bandwidth" in [f.name for f in recal.params.quantities()]
    ev = E.Evidence(fs=199.6e3, nominal=E.Nominal(
        moving_mass=0.175, flexure_stiffness=2e4, flexure_damping=2.0,
        force_constant=8.0, sensor_bandwidth=15e3))
    plant = next(c for c in recal.configs(ev, Model()) if c.label == "plant")
    m0 = recal.start(Model(), plant, np.zeros(5), ev)  # every plant knob nominal
    frees = {f.name: f for f in recal.free(m0, 0, ev)}
    assert frees["sensor_bandwidth"].lo == 5e3 and frees["sensor_bandwidth"].hi == 45e3
    q = frees["sensor_bandwidth"].set(m0, 18e3)
    assert recal.term(q, 0).sensor_bandwidth == 18e3 and recal.active(q)
    assert not recal.active(recal.remove(q, 0))


def test_elastic_recovery_is_never_negative():
    """Spring-back lifts the surface; a negative fraction is not that physics."""
    eff = next(e for e in CATALOGUE if e.name == "elastic-recovery")
    (f,) = eff.free(Model(), 0, E.Evidence(fs=199.6e3))
    assert f.lo == 0.0 and f.hi > 0.0
    lo, _hi = E.ElasticRecoveryParams(0.01).bounds(E.Evidence(fs=199.6e3))["recovery"]
    assert lo == 0.0


# ------------------------------------------------------------ one loop model
_CONTRACT = {
    "nominal": (Model(), None, None),
    "mode": (Model.of(E.StructuralModeParams(6100.0, 0.03, 2e-8)), "modes", None),
    "delay": (Model.of(E.LoopDelayParams(1.3e-6)), "delay", None),
    "recalibration": (Model.of(E.RecalibrationParams(
        moving_mass=0.16, flexure_stiffness=2.5e4, force_constant=7.5,
        sensor_bandwidth=18e3)), "recal", None),
    "nonlinear": (Model.of(E.AmplifierSaturationParams(0.4),
                           E.ForceConstantPositionParams(b1=2e3),
                           E.FlexureNonlinearityParams(k_cubic=3e13)), None, "nl"),
}


def _independent_perturbation(kind):
    from servosurf.servo import LoopPerturbation, StructuralMode

    if kind == "modes":
        return LoopPerturbation(modes=(StructuralMode(6100.0, 0.03, 2e-8),))
    if kind == "delay":
        return LoopPerturbation(extra_delay=1.3e-6)
    if kind == "recal":
        return LoopPerturbation(moving_mass=0.16, flexure_stiffness=2.5e4,
                                force_constant=7.5, sensor_bandwidth=18e3)
    return None



@pytest.mark.parametrize("name", sorted(_CONTRACT))
def test_case_model_is_the_servo_loop(name):
    """The diagnosis's model of a case is the simulator's loop (FRF and time)."""
    from servosurf.servo import Nonlinearity, ServoLoop

    p, pert_kind, nl_kind = _CONTRACT[name]
    m = _nominal()
    case = CaseModel(m)
    loop = ServoLoop(m)
    pert = _independent_perturbation(pert_kind)
    nl = (Nonlinearity(max_current=0.4, kf_b1=2e3, flexure_k3=3e13)
          if nl_kind else None)
    f = np.geomspace(20.0, 80e3, 120)
    got = case.paths(p, f)
    frf = loop.frf(f, perturbation=pert)
    for (inp, out), h in frf.paths.items():
        key = (inp, "fe" if out == "following_error" else out)
        np.testing.assert_array_equal(got[key], h, err_msg=str(key))
    np.testing.assert_array_equal(got["open_loop"],
                                  loop.open_loop(f, perturbation=pert))
    t = np.arange(3000) / case.fs
    cmd = 10e-6 * np.sin(2 * np.pi * 100.0 * t)
    a = case.simulate(p, reference=cmd)
    b = loop.simulate(reference=cmd, perturbation=pert, nonlinearity=nl)
    np.testing.assert_array_equal(a["fe"], b["following_error"])
    np.testing.assert_array_equal(a["tool"], b["tool"])
    assert case.is_stable(p) == loop.is_stable(perturbation=pert)
