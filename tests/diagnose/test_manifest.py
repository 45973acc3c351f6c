"""Manifest parsing: typed tables, range checks with units, presets, and paths
relative to the manifest only."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from servosurf.cli import main
from servosurf.diagnose import CaseTable, Manifest, RecordingTable, load_manifest
from servosurf.errors import ConfigError
from servosurf.run import PRESETS

FE = '[[recording]]\npath = "fe.csv"\nkind = "following-error"\n'


def _fe_csv(folder: Path) -> Path:
    t = np.arange(64) / 10e3
    rows = "\n".join(f"{a:.9g},{1e-9 * np.sin(a * 1e3):.6g}" for a in t.tolist())
    p = folder / "fe.csv"
    p.write_text("time_s,following_error_m\n" + rows + "\n")
    return p


def _write(folder: Path, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    _fe_csv(folder)
    m = folder / "manifest.toml"
    m.write_text(text)
    return m


def test_case_table_values_aliases_and_recordings_alias(tmp_path):
    m = _write(
        tmp_path,
        'machine = "seed-prototype"\nbandwidth-hz = 500\n'
        'mass = 0.1\n\n[[recordings]]\npath = "fe.csv"\n'
        'kind = "following-error"\nname = "idle"\ncondition = "spindle off"\n',
    )
    man = load_manifest(m)
    assert isinstance(man, Manifest)
    assert (man.machine, man.bandwidth, man.moving_mass) == (
        "seed-prototype",
        500.0,
        0.1,
    )
    assert man.run.bandwidth == 500.0 and man.run.mass == 0.1
    (rec,) = man.recordings
    assert rec.name == "idle" and rec.path == tmp_path / "fe.csv"
    assert rec.options == {"condition": "spindle off"}
    assert rec.data["fs"] == pytest.approx(10e3)


def test_preset_starts_the_case_and_keys_change_it(tmp_path):
    p = PRESETS["paper-optimum-light"]
    light = '[case]\npreset = "paper-optimum-light"\n'
    man = load_manifest(_write(tmp_path / "a", light + "\n" + FE))
    assert (man.bandwidth, man.moving_mass) == (p.bandwidth, p.mass)
    assert man.run.preset == "paper-optimum-light"
    man = load_manifest(
        _write(
            tmp_path / "b",
            '[case]\npreset = "paper-optimum-light"\nbandwidth = 700.0\n\n' + FE,
        )
    )
    assert (man.bandwidth, man.moving_mass) == (700.0, p.mass)
    with pytest.raises(
        ConfigError,
        match="unknown run preset 'paper-cuting'.*Did you mean: paper-cutting",
    ):
        load_manifest(
            _write(tmp_path / "c", '[case]\npreset = "paper-cuting"\n\n' + FE)
        )


@pytest.mark.parametrize(
    "body, match",
    [
        (
            "[case]\nbandwdith = 468.0\n",
            r"unknown case key 'bandwdith' \(did you mean: "
            r"bandwidth",
        ),
        (
            "[case]\nbandwidth = -468.0\n",
            r"case\.bandwidth must be > 0 Hz, got -468\.0",
        ),
        ("[case]\nmoving-mass = 175.0\n", r"case\.moving-mass"),
        ('[case]\nbandwidth = "fast"\n', r"case\.bandwidth: expected"),
        (
            "[case]\nspecific-cutting-force = 0.0\n",
            r"case\.specific-cutting-force must be > 0 N/m\^2",
        ),
        ("bandwidth = 468.0\nfoo = 1\n", r"unknown key 'foo'"),
    ],
)
def test_case_errors_name_the_file_the_key_and_the_unit(tmp_path, body, match):
    m = _write(tmp_path, body + "\n" + FE)
    with pytest.raises(ConfigError, match=match) as exc:
        load_manifest(m)
    assert str(exc.value).startswith(str(m)) and "\n" not in str(exc.value)


@pytest.mark.parametrize(
    "extra, match",
    [
        ("radius = -1e-3\n", r"recording 1: radius must be > 0 m, got -0\.001"),
        ("start = [1.0]\n", r"recording 1: start: expected tuple\[float, float\]"),
        (
            "angle_start = 0.1\n",
            r"recording 1: unknown key 'angle_start' \(did you mean: "
            r"angle-start",
        ),
    ],
)
def test_recording_errors(tmp_path, extra, match):
    m = _write(tmp_path, "bandwidth = 468.0\n\n" + FE + extra)
    with pytest.raises(ConfigError, match=match):
        load_manifest(m)


def test_paths_are_relative_to_the_manifest_only(tmp_path, monkeypatch):
    # a toolpath in the current directory's toolpaths/ is not found any more
    cwd = tmp_path / "cwd"
    (cwd / "toolpaths").mkdir(parents=True)
    from servosurf.toolpath import builtin_toolpaths

    src = builtin_toolpaths()["lenslet_5um"]
    (cwd / "toolpaths" / "mine.toml").write_text(src.read_text())
    monkeypatch.chdir(cwd)
    m = _write(tmp_path / "case", '[case]\ntoolpath = "mine.toml"\n\n' + FE)
    with pytest.raises(ConfigError, match=r"toolpath 'mine\.toml': no such file"):
        load_manifest(m)
    # beside the manifest it is found, whatever the current directory
    (tmp_path / "case" / "mine.toml").write_text(src.read_text())
    assert load_manifest(m).toolpath == tmp_path / "case" / "mine.toml"
    # a built-in name still works
    m2 = _write(tmp_path / "b", '[case]\ntoolpath = "lenslet_5um"\n\n' + FE)
    assert load_manifest(m2).toolpath == src


def test_tables_have_one_field_per_key_with_units():
    import dataclasses

    units = {f.name: f.metadata.get("unit") for f in dataclasses.fields(CaseTable)}
    assert units["bandwidth"] == "Hz" and units["moving_mass"] == "kg"
    assert units["specific_cutting_force"] == "N/m^2"
    units = {f.name: f.metadata.get("unit") for f in dataclasses.fields(RecordingTable)}
    assert units["radius"] == units["x0"] == units["start"] == "m"
    assert units["angle_start"] == units["direction"] == "rad"


def test_cli_bad_value_is_one_line_exit_1(tmp_path, capsys):
    m = _write(tmp_path, "[case]\nbandwidth = -1.0\n\n" + FE)
    assert main(["diagnose", str(m), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "case.bandwidth must be > 0 Hz" in err, err
