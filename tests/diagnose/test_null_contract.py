"""The null test as a contract: ``servosurf simulate`` -> its map on disk ->
``servosurf diagnose`` on the manifest simulate wrote is "consistent".

The simulator and the diagnosis share one loop model (servo/ and kernels/), but
not the surface: simulate sweeps the tool over a pixel grid with the exact
swept-arc kernel, writes a DATX file and, with an instrument, resamples it to a
camera, adds optics and noise; the diagnosis evaluates the tool's lowest pass at
each measured point and treats the instrument as a nuisance. A "consistent"
verdict on every shipped diagnosable toolpath, with and without the instrument
and for several seeds, is the contract that the two agree on the same case.

Each case is a different (toolpath, instrument, seed). Design-surface toolpaths
are simulated but not diagnosed yet: for them simulate writes no manifest and a
hand-written manifest is refused with a clear message (tested below).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from servosurf.cli import main

#: Every diagnosable toolpath, each instrument setting, a different seed each:
#: four diagnoses of 15-30 s. ``python benchmarks/null_roundtrip.py`` runs the
#: whole grid (three toolpaths x two instruments x several seeds) and prints it.
CASES = [
    ("lenslet_5um", "cp300-20x", 0),
    ("lenslet_10um", "none", 1),
    ("flat_facing", "cp300-20x", 2),
    ("lenslet_5um", "none", 3),
]


@pytest.mark.parametrize(("toolpath", "instrument", "seed"), CASES)
def test_simulate_then_diagnose_is_consistent(toolpath, instrument, seed, tmp_path,
                                              capsys):
    sim = tmp_path / "sim"
    assert main(["-q", "simulate", toolpath, "--instrument", instrument,
                 "--seed", str(seed), "--no-render", "--out", str(sim)]) == 0
    manifest = sim / "manifest.toml"
    assert manifest.is_file()
    capsys.readouterr()
    assert main(["diagnose", str(manifest), "--out", str(tmp_path / "d"),
                 "--json"]) == 0
    verdict = json.loads(capsys.readouterr().out)
    assert verdict["verdict"] == "consistent", (
        verdict["verdict"], verdict.get("mismatches"), verdict.get("explanations"))
    assert not verdict["explanations"]


@pytest.mark.parametrize("toolpath", ["sphere", "lenslet_array_hex"])
def test_design_surfaces_are_refused_not_misdiagnosed(toolpath, tmp_path, capsys):
    import numpy as np

    from servosurf.toolpath import builtin_toolpaths

    np.savez(tmp_path / "map.npz", z=np.zeros((8, 8)), dx=1e-6, dy=1e-6)
    (tmp_path / "m.toml").write_text(
        f'toolpath = "{builtin_toolpaths()[toolpath]}"\n'
        '[[recording]]\npath = "map.npz"\nkind = "surface"\n')
    assert main(["diagnose", str(tmp_path / "m.toml"), "--out",
                 str(tmp_path / "d")]) == 1
    err = capsys.readouterr().err
    assert "cannot be diagnosed yet" in err and "'surface'" in err
    assert err.count("\n") == 1
    assert not (tmp_path / "d").exists()


EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "manifests"


@pytest.fixture(scope="module")
def example_recordings(tmp_path_factory):
    """The shipped example manifests with their recordings (idle records, FRFs)
    written by examples/manifests/make.py."""
    import importlib.util
    import shutil

    folder = tmp_path_factory.mktemp("examples")
    spec = importlib.util.spec_from_file_location("make_examples", EXAMPLES / "make.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.write_all(folder, groups=("idle", "frf"))
    for m in EXAMPLES.glob("*.toml"):
        shutil.copy(m, folder / m.name)
    return folder


@pytest.mark.parametrize("manifest", ["following_error", "frf_open_loop",
                                      "frf_closed_loop", "frf_force"])
def test_example_channels_are_consistent(manifest, example_recordings, capsys):
    """Each channel's null test: the idle records (whose periodogram sees the
    model PSD through the window's leakage) and the three FRFs as a controller
    measures them."""
    out = example_recordings / f"d_{manifest}"
    assert main(["diagnose", str(example_recordings / f"{manifest}.toml"), "--out",
                 str(out), "--json"]) == 0
    verdict = json.loads(capsys.readouterr().out)
    assert verdict["verdict"] == "consistent", (verdict["verdict"],
                                                verdict.get("mismatches"))
    assert not verdict["mismatches"]
