"""Machine files: unknown keys, types, ranges, inheritance."""

from __future__ import annotations

import pytest

from servosurf.errors import ConfigError
from servosurf.servo import builtin_machines, describe_machine, load_machine


def write(tmp_path, text):
    p = tmp_path / "m.toml"
    p.write_text(text)
    return p


def test_builtin_loads_and_is_listed():
    assert "seed-prototype" in builtin_machines()
    m = load_machine()
    assert m.mechanics.moving_mass == pytest.approx(0.075)
    assert m.controller.sample_rate == 199.6e3
    assert {d.name for d in m.alternative_disturbances} == {
        "section-3.3", "section-3.3-3dB"
    }


def test_unknown_key_suggests(tmp_path):
    p = write(tmp_path, "[controller]\nbandwith = 500.0\n")
    with pytest.raises(
        ConfigError, match=r"controller\.bandwith.*Did you mean: controller\.bandwidth"
    ):
        load_machine(p)


def test_out_of_range_names_dotted_key(tmp_path):
    p = write(tmp_path, "[mechanics]\nm1 = -0.01\n")
    with pytest.raises(ConfigError, match=r"mechanics\.m1 must be > 0 kg"):
        load_machine(p)


def test_type_mismatch(tmp_path):
    p = write(tmp_path, '[sensor]\nbandwidth = "fast"\n')
    with pytest.raises(
        ConfigError, match=r"sensor\.bandwidth: expected float, got str"
    ):
        load_machine(p)


def test_literal_choice(tmp_path):
    p = write(tmp_path, '[sensor]\nlocation = "tol"\n')
    with pytest.raises(ConfigError, match="Did you mean: 'tool'"):
        load_machine(p)


def test_invalid_toml_and_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_machine(write(tmp_path, "[x\n"))
    with pytest.raises(ConfigError, match="no such file"):
        load_machine(tmp_path / "nope.toml")


def test_inherit_changes_only_given_keys(tmp_path):
    p = write(tmp_path, 'inherit = "seed-prototype"\n[controller]\nbandwidth = 874.0\n')
    m = load_machine(p)
    base = load_machine()
    assert m.controller.bandwidth == 874.0
    assert m.mechanics == base.mechanics
    assert m.disturbances == base.disturbances


def test_every_parameter_documented():
    rows = describe_machine()
    keys = {r["key"] for r in rows}
    for k in (
        "mechanics.m1",
        "mechanics.k5",
        "mechanics.c3",
        "actuator.force-constant",
        "actuator.current-gain",
        "actuator.current-bandwidth",
        "sensor.sensitivity",
        "sensor.bandwidth",
        "controller.sample-rate",
        "controller.delay",
        "controller.bandwidth",
        "controller.kp",
    ):
        assert k in keys
    for r in rows:
        assert r["doc"], r["key"]
