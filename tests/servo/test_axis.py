"""Machine-axis model: the second-order Z slide against scipy's continuous-time
simulation and the closed-form ramp lag; machine files that select it."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sps

from servosurf.errors import ConfigError
from servosurf.servo import AxisModel, load_machine


def test_second_order_matches_lsim_on_piecewise_linear_input():
    ax = AxisModel(model="second-order", bandwidth=80.0, damping=0.3, sample_rate=8e3)
    rng = np.random.default_rng(17)  # seeded command
    n = 4000
    t = np.arange(n) / ax.sample_rate
    u = np.cumsum(rng.normal(0.0, 1e-8, n)) + 1e-6  # m, random walk from 1 um
    got = ax.response(u)
    wn = 2 * np.pi * ax.bandwidth
    sys = sps.lti([wn * wn], [1.0, 2 * ax.damping * wn, wn * wn])
    # lsim interpolates the input linearly between samples (the machine's blocks);
    # start at rest at u[0]: simulate u - u[0] from zero state, add u[0] back
    _, ref, _ = sps.lsim(sys, u - u[0], t)
    np.testing.assert_allclose(got, ref + u[0], rtol=0, atol=1e-15)  # 1 fm


def test_ramp_lag_closed_form():
    ax = AxisModel(model="second-order", bandwidth=50.0, damping=0.7, sample_rate=5e3)
    v = 2e-6  # m/s
    t = np.arange(5000) / ax.sample_rate
    y = ax.response(v * t)
    wn = 2 * np.pi * ax.bandwidth
    # steady state of a unity-gain second-order system on a ramp: lag 2 zeta / wn
    np.testing.assert_allclose(y[-1], v * (t[-1] - 2 * ax.damping / wn), rtol=0,
                               atol=1e-15)
    # at rest: a constant command is followed exactly
    np.testing.assert_allclose(ax.response(np.full(100, 3e-6)), 3e-6, rtol=0,
                               atol=1e-18)
    np.testing.assert_array_equal(AxisModel(model="none").response(v * t), v * t)


def test_axis_validation_and_machine_files(tmp_path):
    with pytest.raises(ConfigError, match="sample-rate must be >= 20 x"):
        AxisModel(model="second-order", bandwidth=1e3, sample_rate=10e3)
    with pytest.raises(ConfigError, match="no transfer function"):
        AxisModel(model="fts").discrete()
    assert load_machine().axis.model == "fts"
    assert load_machine("sts-ideal-axes").axis.model == "none"
    f = tmp_path / "moore.toml"
    f.write_text('inherit = "sts-ideal-axes"\nname = "moore"\n[axis]\n'
                 'model = "second-order"\nbandwidth = 40.0\ndamping = 0.5\n')
    m = load_machine(f)
    assert (m.axis.model, m.axis.bandwidth, m.axis.damping) == ("second-order", 40.0,
                                                                0.5)
    f.write_text('inherit = "seed-prototype"\n[axis]\nmodel = "slide"\n')
    with pytest.raises(ConfigError, match="axis.model must be one of"):
        load_machine(f)
