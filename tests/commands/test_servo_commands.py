"""CLI: machines, noise, paper; user errors give one line and exit status 1."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from servosurf.cli import main

PNG = b"\x89PNG\r\n\x1a\n"


def test_help_imports_nothing_heavy():
    code = (
        "import sys; from servosurf.cli import build_parser; build_parser(); "
        "heavy = [m for m in ('numba', 'matplotlib', 'pyvista', 'scipy') "
        "if m in sys.modules];"
        "print(heavy)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"


def test_machines_lists_builtin(capsys):
    assert main(["machines", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["machines"][0]["name"] == "seed-prototype"


def test_paper_json_rows_within(capsys):
    assert main(["paper", "--json", "--only", "servo"]) == 0
    data = json.loads(capsys.readouterr().out)
    rows = data["rows"]
    assert len(rows) >= 13
    for r in rows:
        assert set(r) >= {
            "quantity",
            "paper",
            "servosurf",
            "unit",
            "tolerance",
            "within",
        }
        assert r["within"], r


def test_noise_writes_figures_and_summary(tmp_path, capsys):
    out = tmp_path / "noise"
    rc = main(
        [
            "noise",
            "--mass",
            "0.175",
            "--bandwidth",
            "468",
            "--bandwidths",
            "300",
            "468",
            "900",
            "--out",
            str(out),
            "--json",
        ]
    )
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    assert data["masses"][0]["stable"]
    assert 0.1e-9 < data["masses"][0]["rms_real_m"] < 1e-9
    for name in (
        "loop_bode",
        "cas",
        "rms_vs_bandwidth",
        "error_spectra",
        "power_shares",
        "disturbance_frfs",
    ):
        assert (out / f"{name}.png").read_bytes()[:8] == PNG
    assert json.loads((out / "summary.json").read_text())["bandwidth_hz"] == 468


@pytest.mark.parametrize(
    "argv, match",
    [
        (["noise", "--machine", "missing.toml"], "no such file"),
        (["noise", "--mass", "-1"], "--mass"),
        (["noise", "--disturbances", "nope"], "unknown disturbance calibration"),
        (["paper", "--only", "nope"], "unknown group"),
        # nothing listens on port 1 of this machine: connection refused
        (["noise", "--scheduler", "tcp://127.0.0.1:1"], "no dask scheduler"),
        (["noise", "--scheduler", "local", "--workers", "0"], "--workers"),
    ],
)
def test_user_errors_one_line(argv, match, capsys, tmp_path):
    argv = argv + (["--out", str(tmp_path / "o")] if argv[0] == "noise" else [])
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0]
    assert "Traceback" not in err[0]


def test_bad_machine_key_via_subprocess(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[mechanics]\nk9 = 1.0\n")
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "servosurf",
            "-q",
            "noise",
            "--machine",
            str(bad),
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 1
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "mechanics.k9" in lines[0]
