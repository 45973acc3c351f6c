"""The typed run configuration: the seed paper's presets, TOML loading through
config.from_mapping, unknown keys, implausible values, and the run it gives."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.run import (
    DEFAULT_PRESET,
    PRESET_NOTES,
    PRESETS,
    RunConfig,
    load_run,
    preset,
)

#: The paper's set-ups, read off the seed paper (section 5.1, Fig. 12a: optimal
#: crossovers 874 Hz at 0.075 kg and 468 Hz at 0.175 kg; section 5.3, Figs 17-19:
#: the lenslets cut at 1448 Hz with 0.175 kg, measured on the CP300 20X).
PAPER = {
    "paper-cutting": (1448.0, 0.175),
    "paper-optimum-heavy": (468.0, 0.175),
    "paper-optimum-light": (874.0, 0.075),
}


@pytest.mark.parametrize("name", sorted(PAPER))
def test_each_preset_holds_the_papers_set_up(name):
    cfg = preset(name)
    assert (cfg.bandwidth, cfg.mass) == PAPER[name]
    assert cfg.instrument == "cp300-20x"
    assert cfg.seed == 0 and cfg.preset == name
    assert cfg.machine is None and cfg.parts is None
    assert name in PRESET_NOTES


def test_the_presets_are_the_papers_and_the_commands_default_is_the_cut():
    assert set(PRESETS) == set(PAPER)
    assert DEFAULT_PRESET == "paper-cutting"


def test_presets_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        PRESETS["paper-cutting"].bandwidth = 1.0


def test_from_toml_starts_from_a_preset(tmp_path):
    f = tmp_path / "run.toml"
    f.write_text('preset = "paper-optimum-light"\nseed = 4\n'
                 'parts = ["tracking", "vibration"]\nn-threads = 1\n')
    cfg = RunConfig.load(f)
    assert (cfg.bandwidth, cfg.mass, cfg.seed) == (874.0, 0.075, 4)
    assert cfg.parts == ("tracking", "vibration") and cfg.n_threads == 1
    assert cfg.instrument == "cp300-20x"
    assert load_run(f) == cfg
    assert load_run("paper-optimum-light") is PRESETS["paper-optimum-light"]


def test_from_mapping_without_a_preset_leaves_the_machines_values():
    cfg = RunConfig.from_mapping({"bandwidth": 900.0, "instrument": "none"})
    assert cfg.bandwidth == 900.0 and cfg.mass is None and cfg.instrument is None


def test_mapping_round_trip():
    cfg = preset("paper-cutting").replace(seed=7, parts=("tracking",))
    assert RunConfig.from_mapping(cfg.to_mapping()) == cfg


@pytest.mark.parametrize(("data", "match"), [
    ({"bandwdith": 1448.0}, r"unknown key 'run\.bandwdith'.*Did you mean: "
                            r"run\.bandwidth"),
    ({"preset": "paper-cuting"}, r"run\.preset.*Did you mean: paper-cutting"),
    ({"mass": 175.0}, r"run\.mass = 175 kg.*175 g = 0\.175 kg"),
    ({"bandwidth": -3.0}, r"run\.bandwidth"),
    ({"parts": ["trackng"]}, r"Did you mean: tracking"),
    ({"parts": ["tracking", "kinematic"]}, r"'kinematic' is the commanded path"),
    ({"seed": -1}, r"seed"),
    ({"n-threads": 0}, r"n-threads"),
])
def test_bad_keys_and_values_are_one_line_errors(data, match):
    with pytest.raises(ConfigError, match=match):
        RunConfig.from_mapping(data, prefix="run")


def test_unknown_preset_and_source():
    with pytest.raises(ConfigError, match="Did you mean: paper-optimum-heavy"):
        preset("paper-optimum-hevy")
    with pytest.raises(ConfigError, match="run TOML file"):
        load_run("no-such-preset")


def test_machine_model_applies_mass_then_bandwidth():
    from servosurf.servo import load_machine

    m = preset("paper-optimum-light").machine_model()
    assert m.mechanics.moving_mass == pytest.approx(0.075, abs=1e-15)
    assert m.controller.bandwidth == 874.0
    ref = load_machine().with_moving_mass(0.075).with_bandwidth(874.0)
    assert m == ref


def test_simulate_from_a_preset_equals_the_keywords():
    """A run from the preset is the run with the paper's numbers as keywords; a
    keyword replaces the preset's value."""
    from servosurf.simulation import simulate
    from servosurf.toolpath import load_toolpath

    spec = load_toolpath("toolpaths/lenslet_5um.toml")
    fld = dataclasses.replace(spec.field, pitch_x=4e-6, pitch_y=4e-6, nx=40, ny=40)
    spec = dataclasses.replace(spec, field=fld)
    a = simulate(spec, "paper-cutting", instrument="none", seed=3)
    b = simulate(spec, bandwidth=1448.0, mass=0.175, seed=3)
    np.testing.assert_array_equal(a.surface.z, b.surface.z)
    assert a.measured is None
    assert a.settings["bandwidth_hz"] == 1448.0
    assert a.settings["moving_mass_kg"] == 0.175
    c = simulate(spec, preset("paper-cutting").replace(instrument=None),
                 bandwidth=468.0, seed=3)
    assert c.settings["bandwidth_hz"] == 468.0
