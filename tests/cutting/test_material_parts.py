"""Parameters of the flat-face physics: workpiece ratios, tool edge radius, sensor
target and spindle PSD (keys, units, validation, defaults in the shipped files)."""

from __future__ import annotations

from pathlib import Path

import pytest

from servosurf.cutting import Material, cutting_rules, load_workpiece
from servosurf.errors import ConfigError
from servosurf.servo import describe_machine, load_machine
from servosurf.toolpath import Tool, load_toolpath


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_shipped_files_carry_the_parameters():
    wp = load_workpiece("workpieces/nip.toml")
    assert wp.material == Material(
        name=wp.material.name,
        specific_cutting_pressure=3.5e9, source=wp.material.source)  # = defaults
    for name in ("flat_facing", "lenslet_5um", "lenslet_10um"):
        assert load_toolpath(f"toolpaths/{name}.toml").tool.edge_radius == 20e-9
    m = load_machine()
    assert m.sensor.target == "metrology-frame"
    assert m.spindle.axial_error.floor == 3.5e-11
    assert m.spindle.axial_error.corner == 500.0
    assert m.spindle.fmin == 0.05


def test_rules_scale_with_the_edge_radius():
    mat = Material(min_chip_thickness_ratio=0.3, side_flow_height_ratio=0.1,
                   side_flow_width_ratio=5.0, recovery_ratio=0.2,
                   recovery_decay_ratio=2.0)
    r = cutting_rules(mat, Tool(edge_radius=10e-9),
                      ["tracking", "ploughing", "side-flow", "recovery"])
    assert r.to_dict() == pytest.approx({
        "min_chip_thickness_m": 3e-9, "side_flow_height_m": 1e-9,
        "side_flow_width_m": 50e-9, "recovery_height_m": 2e-9,
        "recovery_decay_m": 20e-9}, rel=1e-12)
    assert cutting_rules(mat, Tool(), ["tracking", "vibration"]).is_kinematic
    only = cutting_rules(mat, Tool(edge_radius=10e-9), ["side-flow"])
    assert only.min_chip_thickness == 0.0 and only.recovery_height == 0.0


@pytest.mark.parametrize("key, value, match", [
    ("min-chip-thickness-ratio", 2.0, "material.min-chip-thickness-ratio must be <= 1"),
    ("min-chip-thickness-ratio", -0.1, ">= 0"),
    ("recovery-decay-ratio", 0.0, "material.recovery-decay-ratio must be > 0"),
    ("side-flow-width-ratio", "wide", "expected float"),
    ("min-chip-thicknes-ratio", 0.3, "Did you mean"),
])
def test_workpiece_ratios_validated(tmp_path, key, value, match):
    v = f'"{value}"' if isinstance(value, str) else value
    p = write(tmp_path, "w.toml", f"[material]\n{key} = {v}\n")
    with pytest.raises(ConfigError, match=match):
        load_workpiece(p)


def test_edge_radius_unit_slip_named(tmp_path):
    text = Path("toolpaths/flat_facing.toml").read_text().replace(
        "edge-radius = 20e-9", "edge-radius = 20.0")
    p = write(tmp_path, "t.toml", text)
    with pytest.raises(ConfigError, match=r"edge-radius.*meant in nm"):
        load_toolpath(p)


@pytest.mark.parametrize("text, match", [
    ('[sensor]\ntarget = "fts"\n', "sensor.target must be one of"),
    ("[spindle]\nfmin = 0.0\n", "spindle.fmin must be > 0"),
    ("[spindle.axial-error]\nfloor = -1e-11\n", "spindle.axial-error.floor"),
])
def test_machine_keys_validated(tmp_path, text, match):
    p = write(tmp_path, "m.toml", 'inherit = "seed-prototype"\n' + text)
    with pytest.raises(ConfigError, match=match):
        load_machine(p)


def test_machine_keys_documented_and_round_trip(tmp_path):
    rows = {r["key"]: r for r in describe_machine()}
    assert rows["sensor.target"]["source"]
    assert rows["spindle.fmin"]["unit"] == "Hz"
    assert rows["spindle.axial-error.floor"]["doc"]
    m = load_machine(write(tmp_path, "m.toml",
                           'inherit = "seed-prototype"\n[sensor]\ntarget = '
                           '"fts-base"\n[spindle.axial-error]\nfloor = 2e-11\n'))
    assert m.sensor.target == "fts-base" and m.spindle.axial_error.floor == 2e-11
    again = load_machine(write(tmp_path, "again.toml", m.to_toml()))
    assert again.sensor == m.sensor and again.spindle == m.spindle
