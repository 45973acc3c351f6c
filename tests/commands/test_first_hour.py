"""The first hour of a new user (issue 20): built-ins by name, what each command
says, nonsense refused early in one line, whole runs or nothing."""

from __future__ import annotations

import errno
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from servosurf import _progress
from servosurf.cli import main
from servosurf.metrology import Surface

REPO = Path(__file__).resolve().parents[2]
LENS = REPO / "toolpaths" / "lenslet_5um.toml"


def _one_error_line(capsys) -> str:
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1, cap.err
    assert "Traceback" not in cap.err
    return lines[0]


def _variant(tmp_path: Path, name: str, old: str, new: str) -> Path:
    """The 5 um lenslet file with one line replaced (the line must exist)."""
    text = LENS.read_text()
    assert re.search(old, text, flags=re.M), old
    path = tmp_path / f"{name}.toml"
    path.write_text(re.sub(old, new, text, count=1, flags=re.M))
    return path


@pytest.fixture()
def small_lens(tmp_path) -> Path:
    """The 5 um lenslet on a 64 x 64 field at 2 um (seconds, not minutes)."""
    text = LENS.read_text()
    for old, new in (("pitch-x = 0.55e-6", "pitch-x = 2e-6"),
                     ("pitch-y = 0.55e-6", "pitch-y = 2e-6"),
                     ("nx = 640", "nx = 64"), ("ny = 480", "ny = 64")):
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "small_lens.toml"
    path.write_text(text)
    return path


# ---------------------------------------------------------------- built-ins


def test_builtin_names_list_and_resolve(capsys, tmp_path, monkeypatch):
    from servosurf._builtins import builtin_files, resolve_file
    from servosurf.toolpath import builtin_toolpaths, load_toolpath

    monkeypatch.chdir(tmp_path)  # an empty folder: no toolpaths/ here
    names = sorted(p.stem for p in (REPO / "toolpaths").glob("*.toml"))
    assert sorted(builtin_toolpaths()) == names  # every repository file ships
    assert sorted(builtin_files("workpiece")) == sorted(
        p.stem for p in (REPO / "workpieces").glob("*.toml"))
    # the same file: the package data is the repository folder, not a copy
    assert builtin_toolpaths()["lenslet_5um"].read_bytes() == LENS.read_bytes()
    assert load_toolpath("lenslet_5um") == load_toolpath(LENS)
    assert load_toolpath("lenslet_5um.toml") == load_toolpath(LENS)
    # a user's own file wins over the built-in of the same name
    own = tmp_path / "lenslet_5um.toml"
    own.write_text(LENS.read_text().replace("ring-count = 3", "ring-count = 2"))
    assert resolve_file("lenslet_5um.toml", kind="toolpath") == Path(
        "lenslet_5um.toml")
    assert load_toolpath("lenslet_5um.toml").path.ring_count == 2
    # a folder path to a missing file names the built-in to use instead
    from servosurf.errors import ConfigError

    with pytest.raises(ConfigError, match="give the name alone: flat_facing"):
        resolve_file("toolpaths/flat_facing.toml", kind="toolpath")
    with pytest.raises(ConfigError, match="not found.*lenslet_10um"):
        resolve_file("nope", kind="toolpath")

    assert main(["toolpaths"]) == 0
    out = capsys.readouterr().out
    for name in names:  # one line each, with the file's description
        desc = load_toolpath(name).description
        assert re.search(rf"^\s+{name}\s+{re.escape(desc)}$", out, flags=re.M)
    assert re.search(r"^\s+nip\s+\S", out, flags=re.M)
    assert main(["toolpaths", "--show", "nip"]) == 0
    assert capsys.readouterr().out == (REPO / "workpieces" / "nip.toml").read_text()
    assert main(["toolpaths", "--show", "bogus"]) == 1
    assert "lenslet_5um" in _one_error_line(capsys)


def test_paper_surface_rows_from_any_folder(tmp_path, monkeypatch):
    """The paper's surface rows find the built-in toolpaths from an empty folder."""
    from servosurf.report import _paper

    monkeypatch.chdir(tmp_path)
    calls = []

    def fake_load(path, *a, **kw):  # stop after the toolpath was found
        calls.append(Path(path))
        raise _Found

    class _Found(Exception):
        pass

    import servosurf.toolpath
    from servosurf.servo import load_machine

    monkeypatch.setattr(servosurf.toolpath, "load_toolpath", fake_load)
    with pytest.raises(_Found):
        _paper.surface_rows({"machine": load_machine()})
    assert calls[0].is_file() and calls[0].read_bytes() == LENS.read_bytes()
    from servosurf.toolpath import builtin_toolpaths

    # the package's own data (what a wheel ships), not a folder found by walking
    # up from the module (which exists only in a source checkout)
    assert calls[0].parent == builtin_toolpaths()["lenslet_5um"].parent


# ------------------------------------------------------ refuse nonsense early


BAD_TOML = [
    # (name, line, replacement, words the one-line error must hold)
    ("amp10", r"^amplitude = 10e-6", "amplitude = 10",
     ["lenslet.amplitude = 10 m", "10 um = 1e-05 m"]),
    ("amp1e3", r"^amplitude = 10e-6", "amplitude = 1e3",
     ["lenslet.amplitude = 1000 m", "plausible range"]),
    ("pitch1e3", r"^pitch-x = 0.55e-6", "pitch-x = 1e3",
     ["field.pitch-x = 1000 m", "1000 nm = 1e-06 m"]),
    ("f1e9", r"^frequency = 100.0", "frequency = 1e9",
     ["lenslet.frequency = 1e+09 Hz", "plausible range"]),
    ("radius200", r"^nose-radius = 0.5e-3", "nose-radius = 200",
     ["tool.nose-radius = 200 m", "200 um = 0.0002 m"]),
    ("grid", r"^nx = 640\nny = 480", "nx = 100000\nny = 100000",
     ["100000 x 100000 px", "memory", "--force"]),
]


@pytest.mark.parametrize("name, old, new, words", BAD_TOML,
                         ids=[b[0] for b in BAD_TOML])
def test_absurd_toolpath_values_refused_in_one_line(name, old, new, words, tmp_path,
                                                    capsys):
    path = _variant(tmp_path, name, old, new)
    out = tmp_path / "out"
    assert main(["simulate", str(path), "--out", str(out)]) == 1
    err = _one_error_line(capsys)
    for w in words:
        assert w in err
    assert not out.exists() and not list(tmp_path.glob(".out.*"))


def test_frequency_above_nyquist_refused(small_lens):
    """Beyond the file's plausible range (Python API): the controller's Nyquist."""
    import dataclasses

    from servosurf.errors import ConfigError
    from servosurf.simulation import simulate
    from servosurf.toolpath import load_toolpath

    spec = load_toolpath(small_lens)
    fast = dataclasses.replace(spec, path=dataclasses.replace(spec.path,
                                                              frequency=1.2e5))
    with pytest.raises(ConfigError, match=r"lenslet.frequency = 120000 Hz .*Nyquist "
                       r"frequency 99800 Hz"):
        simulate(fast)


def test_latin1_toml_is_one_line(tmp_path, capsys):
    path = tmp_path / "latin1.toml"
    path.write_bytes(b"# depth 5 \xb5m\n" + LENS.read_bytes())
    assert main(["simulate", str(path), "--out", str(tmp_path / "o")]) == 1
    err = _one_error_line(capsys)
    assert "not UTF-8" in err and "0xb5 on line 1" in err


@pytest.mark.parametrize("argv, words", [
    (["simulate", "lenslet_5um", "--seed", "1.5"], ["--seed", "'1.5'"]),
    (["simulate", "lenslet_5um", "--mass", "175"], ["--mass = 175 kg", "175 g"]),
    (["simulate", "lenslet_5um", "--bandwidth", "1e9"], ["--bandwidth = 1e+09 Hz"]),
    (["simulate"], ["TOOLPATH"]),
    (["simulate", "lenslet_5um", "--bogus"], ["--bogus"]),
    (["bogus"], ["bogus"]),
    (["face", "flat_facing", "--radius", "1"], ["writes about", "TB", "--radius",
                                                "--force"]),
    (["face", "flat_facing", "--radius", "1e-3", "--pitch", "2e-3"],
     ["--pitch = 0.002 m", "0.002 mm = 2e-06 m"]),
    (["noise", "--mass", "75"], ["--mass = 75 kg", "75 g"]),
])
def test_flag_mistakes_are_one_line_exit_1(argv, words, tmp_path, capsys):
    out = tmp_path / "o"
    assert main([*argv, "--out", str(out)] if argv[0] != "bogus" else argv) == 1
    err = _one_error_line(capsys)
    for w in words:
        assert w in err
    assert not out.exists()


def test_help_still_exits_0(capsys):
    assert main(["--help"]) == 0
    assert main(["simulate", "--help"]) == 0
    assert "TOOLPATH" in capsys.readouterr().out


def test_output_path_under_a_file_and_foreign_folder(tmp_path, capsys,
                                                      monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("afile").write_text("x")
    assert main(["simulate", "lenslet_5um", "--out", "afile/sub"]) == 1
    assert "afile, which is a file" in _one_error_line(capsys)
    assert main(["noise", "--out", "afile"]) == 1
    assert "is a file, not a folder" in _one_error_line(capsys)
    assert main(["noise", "--out", "."]) == 1
    assert "current folder" in _one_error_line(capsys)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("precious")
    assert main(["noise", "--out", str(mine)]) == 1
    assert "servosurf did not write (thesis.tex)" in _one_error_line(capsys)
    assert (mine / "thesis.tex").read_text() == "precious"
    assert set(os.listdir(tmp_path)) == {"afile", "mine"}  # nothing left behind


def test_resource_check_refuses_and_force_passes(monkeypatch):
    from servosurf import _resources
    from servosurf.errors import ConfigError

    monkeypatch.setattr(_resources, "available_memory", lambda: 8_000_000_000)
    monkeypatch.setattr(_resources, "free_disk", lambda where: 1_000_000)
    with pytest.raises(ConfigError, match=r"needs about 9 GB of memory, more than "
                       r"the 8 GB available; lower x \(or --force"):
        _resources.check_resources("run", memory=9e9, remedy="lower x")
    with pytest.raises(ConfigError, match=r"writes about 2 MB, more than the 1 MB"):
        _resources.check_resources("run", memory=1e9, disk=2e6)
    est = _resources.check_resources("run", memory=9e9, disk=2e6, force=True)
    assert est["memory_bytes"] == 9e9 and est["disk_free_bytes"] == 1_000_000


def test_unit_slip_closed_forms():
    from servosurf._validation import check_plausible, unit_slip
    from servosurf.errors import ConfigError

    assert unit_slip(10, "m", 1e-9, 5e-3) == "10 um = 1e-05 m"
    assert unit_slip(1e30, "m", 1e-9, 5e-3) == ""  # no usual unit brings it in
    assert unit_slip(15000, "rev/s", 1e-3, 2000) == "15000 rpm = 250 rev/s"
    assert unit_slip(1.0, "GPa", 1e7, 1e11) == ""  # no slips known for that unit
    assert check_plausible(0.5e-3, name="k", unit="m", low=1e-7, high=0.05) == 0.5e-3
    with pytest.raises(ConfigError, match=r"^k = 3 m \(what\) is outside the "
                       r"plausible range 1e-07\.\.0\.05 m; values are SI \(m\): did "
                       r"you mean 3 mm = 0\.003 m\?$"):  # nearest the typical 0.5 mm
        check_plausible(3, name="k", unit="m", low=1e-7, high=0.05, what="what",
                        typical=0.5e-3)


# ------------------------------------------------------- say what happens


def test_simulate_prints_result_and_q_silences(small_lens, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["simulate", str(small_lens), "--out", str(out), "--no-render"]) == 0
    text = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert text.startswith("simulate small_lens: 64 x 64 px at 2 um, 1448 Hz")
    assert (f"max form error      {summary['form_error_max_m'] * 1e9:.3g} nm"
            in text)
    assert f"wrote {out}{os.sep} (" in text and "summary.json" in text
    for flags in (["-q", "simulate", str(small_lens)],
                  ["simulate", str(small_lens), "-q"]):
        assert main([*flags, "--out", str(out), "--no-render"]) == 0
        assert capsys.readouterr().out == ""
    assert main(["simulate", str(small_lens), "--out", str(out), "--no-render",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["files"]["map"] == str(
        out / "surface.datx")  # final paths, not the temporary folder's


def test_compare_identify_psd_print_results(small_lens, tmp_path, capsys):
    sim = tmp_path / "sim"
    assert main(["-q", "simulate", str(small_lens), "--out", str(sim),
                 "--no-render", "--format", "npz"]) == 0
    capsys.readouterr()
    cmp_out = tmp_path / "cmp"
    assert main(["compare", str(sim / "surface.npz"), "--simulated",
                 str(sim / "surface.npz"), "--out", str(cmp_out)]) == 0
    text = capsys.readouterr().out
    data = json.loads((cmp_out / "compare.json").read_text())
    assert text.startswith(f"compare {sim / 'surface.npz'} with")
    assert f"{data['fit_percent']:.1f} %" in text and "RMS / PV residual" in text

    from servosurf.servo import load_machine, open_loop_frf

    f = np.geomspace(100, 20e3, 60)
    h = open_loop_frf(load_machine(None), f)
    csv = tmp_path / "frf.csv"
    csv.write_text("frequency_hz,real,imag\n" + "\n".join(
        f"{float(a)!r},{float(b.real)!r},{float(b.imag)!r}"
        for a, b in zip(f, h, strict=True)) + "\n")
    assert main(["identify", str(csv), "--out", str(tmp_path / "id"),
                 "--param", "mechanics.m1"]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"identify {csv}: grey-box fit")
    assert "% -> " in text and "mechanics.m1" in text and " kg" in text

    rng = np.random.default_rng(3)  # seeded white record
    rec = tmp_path / "rec.csv"
    t = np.arange(8192) / 1e4
    rec.write_text("time_s,value\n" + "\n".join(
        f"{float(a)!r},{float(b)!r}"
        for a, b in zip(t, 1e-9 * rng.standard_normal(t.size), strict=True)))
    assert main(["psd", str(rec), "--out", str(tmp_path / "p.csv"),
                 "--nperseg", "1024"]) == 0
    text = capsys.readouterr().out
    # df = fs / nperseg = 1e4 / 1024 Hz
    assert "at 10000 Hz" in text and "df 9.766 Hz" in text
    assert f"wrote {tmp_path / 'p.csv'}" in text


def test_compile_notice_once_and_disk_cache_seen(tmp_path, monkeypatch, capsys):
    """A fresh kernel is announced once; a disk-cached one is not."""
    import subprocess
    import sys

    from servosurf.kernels import _notice
    from servosurf.kernels._config import CACHE

    if not CACHE:
        pytest.skip("SERVOSURF_NUMBA_CACHE=0: no disk cache to find")
    mod = tmp_path / "tiny_kernel.py"
    mod.write_text("from numba import njit\n\n@njit(cache=True)\n"
                   "def add(a, b):\n    return a + b\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    import tiny_kernel

    monkeypatch.setattr(_notice, "_ANNOUNCED", set())
    monkeypatch.setattr(_notice, "COMPILE_SECONDS", {"tiny kernel": 12.0})
    quiet = _progress.is_quiet()
    _progress.set_quiet(False)
    try:
        assert _notice.needs_compilation(tiny_kernel.add)
        assert _notice.compile_notice(tiny_kernel.add, "tiny kernel")
        assert not _notice.compile_notice(tiny_kernel.add, "tiny kernel")  # once
        assert tiny_kernel.add(1, 2) == 3  # compiles and writes the disk cache
        assert not _notice.needs_compilation(tiny_kernel.add)
    finally:
        _progress.set_quiet(quiet)
    err = capsys.readouterr().err
    assert err.count("compiling the tiny kernel") == 1 and "about 12 s" in err
    code = ("import tiny_kernel; from servosurf.kernels._notice import "
            "needs_compilation as n; print(n(tiny_kernel.add))")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path),
                                                         *sys.path])}
    env.pop("NUMBA_CACHE_DIR", None)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True,
                         text=True, env=env, cwd=tmp_path, check=True)
    assert res.stdout.strip() == "False"  # a new process finds the disk cache


# ------------------------------------------------------ whole runs or nothing


@pytest.mark.parametrize("fault", [OSError(errno.ENOSPC, "No space left on device"),
                                   KeyboardInterrupt()], ids=["disk-full", "ctrl-c"])
def test_interrupted_run_leaves_previous_results(fault, small_lens, tmp_path,
                                                 capsys, monkeypatch):
    out = tmp_path / "res"
    assert main(["-q", "simulate", str(small_lens), "--out", str(out),
                 "--no-render", "--seed", "0"]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert json.loads(before["summary.json"])["settings"]["seed"] == 0

    from servosurf.viz import _surface_plots

    real = _surface_plots.plot_spectrum

    def broken(*a, **k):  # the new map and two figures exist by now
        assert any(p.name == "surface.datx" for p in Path(a[3]).parent.iterdir())
        raise fault

    monkeypatch.setattr(_surface_plots, "plot_spectrum", broken)
    rc = main(["-q", "simulate", str(small_lens), "--out", str(out), "--no-render",
               "--seed", "6"])
    assert rc == (130 if isinstance(fault, KeyboardInterrupt) else 1)
    capsys.readouterr()
    after = {p.name: p.read_bytes() for p in out.iterdir()}
    assert after == before  # seed 0 everywhere, byte for byte
    assert sorted(os.listdir(tmp_path)) == sorted(["res", "small_lens.toml"])
    monkeypatch.setattr(_surface_plots, "plot_spectrum", real)
    assert main(["-q", "simulate", str(small_lens), "--out", str(out),
                 "--no-render", "--seed", "6"]) == 0
    assert json.loads((out / "summary.json").read_text())["settings"]["seed"] == 6
    assert sorted(os.listdir(tmp_path)) == sorted(["res", "small_lens.toml"])


def test_compare_pixel_sizes_a_nanometre_apart():
    """0.549 um (the interferometer model's pixel) against 0.55 um (the field):
    resampled onto one grid, not refused (np.isclose's default atol of 1e-8 took
    them for equal, and registration then refused the pair)."""
    from servosurf.report._compare import compare_surfaces

    y, x = np.mgrid[0:120, 0:160]
    a = Surface(1e-9 * np.sin(2 * np.pi * x / 40.0), 0.549e-6, 0.549e-6)
    b = Surface(1e-9 * np.sin(2 * np.pi * x * 0.549 / 0.55 / 40.0), 0.55e-6,
                0.55e-6)
    out = compare_surfaces(a, b)
    assert out["pixel_m"] == [0.55e-6, 0.55e-6]
    assert out["rms_residual_m"] < 0.1e-9  # the same sine on both grids


def test_warnings_are_one_line(small_lens, tmp_path, capsys):
    """A ToolpathWarning reads as one line naming the command, not a source line."""
    import warnings

    text = small_lens.read_text()
    assert "clearance-angle-deg = 15.0" in text
    sharp = tmp_path / "sharp.toml"  # 5 degree clearance: the 8.4 degree slope rubs
    sharp.write_text(text.replace("clearance-angle-deg = 15.0",
                                  "clearance-angle-deg = 5.0"))
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(["-q", "simulate", str(sharp), "--out", str(tmp_path / "w"),
                     "--no-render"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err and all(line.startswith("servosurf simulate: warning: toolpath "
                                       "slope") for line in err)
    assert not any(".py:" in line for line in err)
