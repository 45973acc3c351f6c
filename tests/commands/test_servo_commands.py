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


@pytest.fixture(scope="module")
def paper_servo():
    """``servosurf paper --json --only servo --only cut`` once for the module."""
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["-q", "paper", "--json", "--only", "servo", "--only", "cut"]) == 0
    return json.loads(buf.getvalue())


def test_paper_rows_have_roles_from_the_machine_provenance(paper_servo):
    """Every row has a role; exactly the figures the built-in machine's
    [provenance] names are targets, and the targets hold (a stale calibration
    fails here); the predictions are free to fail."""
    from servosurf.calibration import FIGURES
    from servosurf.report import ROLES
    from servosurf.servo import load_machine

    machine = load_machine()
    named = set()
    for key, label in machine.provenance:
        if label.startswith("target:") and not key.startswith("alternative-"):
            named |= set(label[7:].split(" ")[0].split(";")[0].split(","))
    named.add("deviation_max")  # the workpiece's thrust-pressure target
    rows = paper_servo["rows"]
    assert {r["role"] for r in rows} <= set(ROLES)
    keys = {r["key"] for r in rows}
    assert named <= keys
    for r in rows:
        assert set(r) >= {"quantity", "paper", "servosurf", "unit", "tolerance",
                          "within", "role", "key", "kind", "where", "note"}
        assert r["key"] in FIGURES
        assert (r["role"] == "target") == (r["key"] in named), r["key"]
        if r["role"] == "target":
            assert r["within"], r
        if not r["within"]:
            assert r["note"], r  # a failing prediction says what might explain it
    assert any(r["role"] == "prediction" and not r["within"] for r in rows)


def test_paper_cross_predictions_cover_both_sections(paper_servo):
    from servosurf.calibration import DISTURBANCE_FIGURES

    cp = paper_servo["cross_predictions"]
    names = [s["disturbances"] for s in cp["sets"]]
    assert {"section-5.2", "section-3.3"} <= set(names)
    assert sum(s["default"] for s in cp["sets"]) == 1
    for s in cp["sets"]:
        assert [e["figure"] for e in s["figures"]] == list(DISTURBANCE_FIGURES)
        assert {e["role"] for e in s["figures"]} <= {"target", "prediction"}
        assert any(e["role"] == "target" for e in s["figures"])
    # section 3.3's real errors: 0.155 nm at 0.175 kg, both readings reported
    s33 = next(s for s in cp["sets"] if s["disturbances"] == "section-3.3")
    e = next(x for x in s33["figures"] if x["figure"] == "real_rms_0175_s33")
    assert "value_other_reading" in e


def test_paper_mechanisms_name_the_pole_and_the_tuning_failure(paper_servo):
    st = {m["added_mass_on"]: m for m in paper_servo["mechanisms"]["stability"]}
    assert st["m1"]["kind"] == "unstable"
    assert st["m1"]["critical_pole"]["mode"].startswith("appendage mode")
    assert abs(st["m1"]["critical_pole"]["frequency_hz"] - 11.7e3) < 0.3e3
    assert st["m2"]["kind"] == "untunable"  # no instability: a tuning failure
    ov = paper_servo["mechanisms"]["overshoot"]
    # the carrier sensor sees the overshoot as the tool does: not the 34 nm
    assert ov["sensor_overshoot_m"] > 2.5 * 34e-9
    assert abs(ov["sensor_overshoot_m"] / ov["tool_overshoot_m"] - 1) < 0.1


def test_noise_and_paper_report_one_optimal_bandwidth(paper_servo, tmp_path, capsys):
    """The refined optimum, the same number in `noise` and `paper`."""
    rc = main(["-q", "noise", "--mass", "0.175", "--bandwidths", "300", "468", "900",
               "--out", str(tmp_path / "n"), "--json"])
    assert rc == 0
    study = json.loads(capsys.readouterr().out)["study"]
    rows = {r["key"]: r for r in paper_servo["rows"]}
    assert study["optimal_following_bandwidth_hz"][0] == (
        rows["optimum_following_0175"]["servosurf"]
    )
    assert study["optimal_bandwidth_hz"][0] == rows["optimum_real_0175"]["servosurf"]
    assert study["optimal_bandwidth_hz"][0] not in (300.0, 468.0, 900.0)


# The reduced calibration re-run that `servosurf paper` prints is checked where the
# README runs it: tests/commands/test_wheel_install.py (`servosurf paper`: every
# constant within COMPARE_RTOL). It costs 150 s and ran three times.


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


@pytest.mark.slow
def test_paper_surface_rows_come_from_the_multi_seed_study(capsys):
    """The peak rows come from the mean spectrum with each peak's seed fraction;
    the form rows from the fitted registration; aliases are removed."""
    assert main(["-q", "paper", "--json", "--only", "surface", "--seeds", "3"]) == 0
    data = json.loads(capsys.readouterr().out)
    rows = {r["key"]: r for r in data["rows"]}
    s5 = data["surfaces"]["lenslet_5um"]
    assert s5["seeds"] == [0, 1, 2]
    phys = [p for p in s5["peaks"] if not p["alias"]]
    nearest = min(phys, key=lambda p: abs(p["freq_per_m"] - 170e3))
    assert rows["lens5_peak_170"]["servosurf"] == nearest["freq_per_m"]
    assert "of the seeds" in rows["lens5_peak_170"]["setup"]
    form = s5["form"]["fitted/servosurf"]
    assert rows["form_error_max"]["servosurf"] == form["max_central_m"]
    assert form["max_central_m"] < form["max_rim_m"]
    assert rows["air_cut_ratio"]["role"] == "check"
    assert all(not p["alias"] or p["alias_kind"] for p in s5["peaks"])
