"""The flat-face physics as simulate parts (issue 18, item 6), the one flat-face Ra
definition and the Ra budget by model part."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from servosurf.cli import main
from servosurf.cutting import Material, Workpiece, cutting_rules
from servosurf.errors import ConfigError
from servosurf.report import (
    BUDGET_STEPS,
    FLAT_RA_DEFINITION,
    FlatFaceModel,
    analyse,
    flat_face_budget,
    flat_face_ra,
)
from servosurf.servo import PSDModel, load_machine
from servosurf.simulation import DEFAULT_PARTS, PARTS, simulate
from servosurf.toolpath import load_toolpath, sample, sweep_ordered

FLAT = "toolpaths/flat_facing.toml"
KW = {"bandwidth": 1448.0, "mass": 0.175}  # the paper's cutting set-up


@pytest.fixture(scope="module")
def small_flat():
    """The seed paper's flat cut on a 40 x 40 field at 0.55 um (fast)."""
    spec = load_toolpath(FLAT)
    return dataclasses.replace(spec, field=dataclasses.replace(spec.field, nx=40,
                                                               ny=40))


def fts_base_machine(base_vibration=True):
    """The built-in machine with the sensor target on the FTS base; with
    ``base_vibration`` a base vibration set here (the calibrated machine needs
    none): 0.43 pm/sqrt(Hz) at 1 kHz falling as f^-4 in amplitude."""
    m = load_machine()
    if base_vibration:
        d = dataclasses.replace(m.disturbances, base_vibration=PSDModel(
            level=4.3e-13, ref_frequency=1000.0, slope=-4.0))
        m = dataclasses.replace(m, disturbances=d)
    return dataclasses.replace(m, sensor=dataclasses.replace(
        m.sensor, target="fts-base"))


def kinematic_ra(spec):
    """Ra of a kinematic facing cut, f^2 / (18 sqrt(3) R)."""
    return spec.path.feed_per_rev**2 / (18 * math.sqrt(3) * spec.tool.nose_radius)


def test_parts_and_defaults():
    assert DEFAULT_PARTS == ("tracking", "force", "vibration")
    assert set(DEFAULT_PARTS) < set(PARTS)
    for p in ("out-of-loop", "spindle", "ploughing", "side-flow", "recovery"):
        assert p in PARTS


def test_default_parts_unchanged_by_the_new_parts(small_flat):
    """The default run is the servo loop only; a part that adds nothing (out-of-loop
    with the sensor on the metrology frame) leaves the map bit for bit."""
    a = simulate(small_flat, seed=1, instrument=None, **KW)
    b = simulate(small_flat, seed=1, instrument=None, parts=DEFAULT_PARTS, **KW)
    c = simulate(small_flat, seed=1, instrument=None,
                 parts=DEFAULT_PARTS + ("out-of-loop",), **KW)
    np.testing.assert_array_equal(a.surface.z, b.surface.z)
    np.testing.assert_array_equal(a.surface.z, c.surface.z)
    assert set(a.deviation) == {"tracking", "force", "vibration", "hooks"}
    assert not np.any(c.deviation["out-of-loop"])
    assert c.settings["sensor_target"] == "metrology-frame"
    assert "material_rules" not in a.settings


def test_outside_parts_add_to_the_tool_height(small_flat):
    res = simulate(small_flat, seed=2, instrument=None, machine=fts_base_machine(),
                   parts=("vibration", "out-of-loop", "spindle"), **KW)
    ool, spin = res.deviation["out-of-loop"], res.deviation["spindle"]
    assert ool.std() > 0.1e-9 and spin.std() > 0.5e-9
    # the spindle stream does not depend on the loop: the same draw at any bandwidth
    other = simulate(small_flat, seed=2, instrument=None, parts=("spindle",),
                     bandwidth=900.0, mass=0.175)
    np.testing.assert_array_equal(other.deviation["spindle"], spin)
    kin = simulate(small_flat, parts=(), instrument=None, **KW)
    assert flat_face_ra(res.surface) > 2 * flat_face_ra(kin.surface)


@pytest.mark.parametrize("parts", [("ploughing",), ("side-flow",), ("recovery",),
                                   ("tracking", "ploughing", "side-flow",
                                    "recovery")])
def test_material_parts_are_the_ordered_sweep(small_flat, parts):
    res = simulate(small_flat, seed=0, instrument=None, parts=parts, **KW)
    rules = cutting_rules(res.workpiece.material, small_flat.tool, parts)
    assert res.settings["material_rules"] == rules.to_dict()
    # the kinematic path (plus tracking: a constant height offset on a face)
    path = sample(small_flat, fs=res.machine.controller.sample_rate,
                  field=small_flat.field, tool=small_flat.tool,
                  reach=small_flat.tool.chord_half_width(
                      small_flat.path.depth_of_cut + 1e-6))
    idx = path.index - round(res.t[0] * res.machine.controller.sample_rate)
    path = path.with_z(path.z + res.total_deviation[idx])
    ref = sweep_ordered(path, small_flat.tool, small_flat.field, rules=rules,
                        initial=0.0)
    np.testing.assert_array_equal(res.surface.z, ref.z)


def test_ploughing_raises_the_flat_ra_as_brammertz_says(small_flat):
    """A kinematic face with h_min: the ridge grows by (h_min/2)(1 + R h_min/f^2)
    (Brammertz); Ra of the steady profile grows accordingly (above 0.257 nm)."""
    tool = dataclasses.replace(small_flat.tool, edge_radius=8e-9)  # h_min = 2 nm
    spec = dataclasses.replace(small_flat, tool=tool)
    kin = flat_face_ra(simulate(spec, parts=(), instrument=None).surface)
    pl = simulate(spec, parts=("ploughing",), instrument=None)
    assert kin == pytest.approx(kinematic_ra(spec), rel=0.01)
    z = pl.surface.level().z
    f, R, h = spec.path.feed_per_rev, tool.nose_radius, 2e-9
    rt = f**2 / (8 * R) + 0.5 * h * (1 + R * h / f**2)
    # pixels at 0.55 um sample the 2 um period; the peak lies within 0.3 um
    assert z.max() - z.min() == pytest.approx(rt, rel=0.1)
    assert flat_face_ra(pl.surface) > 2 * kin


def test_flat_ra_definition_in_analyse(small_flat):
    res = simulate(small_flat, parts=(), instrument="cp300-20x", **KW)
    out = analyse(res)
    assert out["ra_m"] == pytest.approx(kinematic_ra(small_flat), rel=0.01)
    assert out["ra_m"] == flat_face_ra(res.surface)  # the machined map
    assert out["ra_instrument_m"] == flat_face_ra(res.measured)
    assert out["ra_instrument_m"] < out["ra_m"]  # the optics blur the marks
    assert out["roughness_definition"].startswith(FLAT_RA_DEFINITION)


def test_flat_face_ra_closed_form_on_a_synthetic_map():
    from servosurf.metrology import Surface

    x = np.arange(3000) * 0.01e-6  # 15 periods of 2 um, 200 samples each
    # a tilted cosine (orthogonal to the plane over whole periods)
    z = 1e-9 * np.cos(2 * np.pi * x / 2e-6) + 1e-4 * x  # 3 nm over the field
    y = np.arange(20)[:, None] * 0.01e-6
    s = Surface(z[None, :] + 2e-3 * y, 0.01e-6, 0.01e-6)  # and 0.4 nm along y
    # Ra of a sinusoid of amplitude A is 2A/pi; the tilt is removed
    assert flat_face_ra(s) == pytest.approx(2e-9 / math.pi, rel=2e-3)


def test_budget_steps_add_one_part_each():
    labels = [label for label, _ in BUDGET_STEPS]
    assert labels[0] == "kinematic" and len(set(labels)) == len(labels)
    assert BUDGET_STEPS[1][1] == DEFAULT_PARTS
    for (_, a), (_, b) in zip(BUDGET_STEPS[1:], BUDGET_STEPS[2:], strict=False):
        assert set(a) < set(b) and len(set(b) - set(a)) == 1
    assert set(BUDGET_STEPS[-1][1]) == set(PARTS)


def test_budget_rows_are_simulate_runs(small_flat):
    steps = (("kinematic", ()), ("servo loop", DEFAULT_PARTS),
             ("everything", PARTS))
    b = flat_face_budget(small_flat, instrument=None, seed=3, steps=steps)
    assert [r["label"] for r in b.rows] == ["kinematic", "servo loop", "everything"]
    ra = b.ra_by_part()
    assert ra["kinematic"] == pytest.approx(kinematic_ra(small_flat), rel=0.01)
    assert b.rows[0]["added_ra_m"] is None
    assert b.rows[2]["added_ra_m"] == pytest.approx(ra["everything"]
                                                    - ra["servo loop"])
    # a row equals a direct simulate() of its step (the replay adds the same
    # deviations)
    direct = simulate(small_flat, machine=fts_base_machine(False), seed=3,
                      parts=PARTS,
                      instrument=None, **KW)
    assert ra["everything"] == pytest.approx(flat_face_ra(direct.surface), rel=1e-9)
    assert b.settings["sensor_target"] == "fts-base"
    assert b.settings["material_rules"]["min_chip_thickness_m"] == pytest.approx(
        0.25 * 20e-9)
    d = json.loads(json.dumps(b.to_dict()))
    assert d["paper_ra_m"] == 1.2e-9 and d["definition"] == FLAT_RA_DEFINITION
    assert "kinematic" in b.table()


def test_budget_model_other_material(small_flat):
    model = FlatFaceModel(small_flat, deviation_parts=("vibration",), seed=0)
    a = model.ra(("vibration", "ploughing"))
    wp = Workpiece(material=Material(min_chip_thickness_ratio=0.05))
    b = model.ra(("vibration", "ploughing"), workpiece=wp)
    assert b < a  # a thinner minimum chip leaves a lower ridge
    with pytest.raises(ConfigError, match="not computed"):
        model.ra(("spindle",))
    with pytest.raises(ConfigError, match="unknown"):
        model.ra(("wobble",))


def test_budget_refuses_a_lenslet_toolpath():
    with pytest.raises(ConfigError, match="facing"):
        FlatFaceModel("toolpaths/lenslet_5um.toml")


def test_simulate_cli_material_parts(tmp_path, capsys):
    text = Path(FLAT).read_text().replace("nx = 640", "nx = 40").replace(
        "ny = 480", "ny = 40")
    tp = tmp_path / "flat.toml"
    tp.write_text(text)
    rc = main(["simulate", str(tp), "--parts", "tracking", "vibration", "spindle",
               "ploughing", "--out", str(tmp_path / "o"), "--json", "--no-render",
               "--format", "npz"])
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    assert data["settings"]["parts"] == ["tracking", "vibration", "spindle",
                                         "ploughing"]
    assert data["settings"]["material_rules"]["min_chip_thickness_m"] == 5e-9
    assert data["ra_m"] > 0.5e-9 and data["ra_instrument_m"] > 0
