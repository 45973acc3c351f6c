"""Recording readers: following error, FRFs, cuts, maps and profiles in SI units.

Files are written here with plain ``csv``/``numpy`` code (the oracle) and read back
with :func:`servosurf.io.read_recording`; errors name the file and the column.
"""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.io import (
    RECORDING_KINDS,
    read_frf_csv,
    read_recording,
    write_frf_csv,
    write_surface,
)
from servosurf.metrology import Surface

FS = 199.6e3  # Hz


def _write_fe(path, t, fmt, *, bom=False, fe=None, extra=None):
    """``time_s,following_error_m[,...]`` CSV with times printed as ``fmt``."""
    rng = np.random.default_rng(11)
    fe = 1e-9 * rng.standard_normal(t.size) if fe is None else fe
    cols = ["time_s", "following_error_m", *(extra or {})]
    rows = [[f"{a:{fmt}}", f"{b:.6g}"] for a, b in zip(t, fe, strict=True)]
    for name, vals in (extra or {}).items():
        for r, v in zip(rows, vals, strict=True):
            r.append(f"{v:.9g}")
    text = ",".join(cols) + "\n" + "\n".join(",".join(r) for r in rows) + "\n"
    path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode())
    return path


def test_kinds():
    assert RECORDING_KINDS == (
        "following-error",
        "frf-open-loop",
        "frf-closed-loop",
        "frf-force",
        "cut",
        "surface",
        "profile",
    )


def test_csv_times_printed_with_six_digits_and_a_bom_are_read(tmp_path):
    # an independent exporter: Excel-style BOM, times as %.6g (at 0.16 s the
    # rounding is 1e-7 s, 2 % of the 5 us step)
    t = np.arange(32768) / FS
    rec = read_recording(
        _write_fe(tmp_path / "fe.csv", t, ".6g", bom=True), "following-error"
    )
    assert len(rec["records"]) == 1 and rec["records"][0]["fe"].size == t.size
    assert rec["fs"] == pytest.approx(FS, rel=1e-6, abs=0.0)


def test_csv_with_a_missing_sample_is_a_user_error(tmp_path):
    t = np.delete(np.arange(4096) / FS, 2000)
    with pytest.raises(ConfigError, match="uniformly sampled"):
        read_recording(_write_fe(tmp_path / "fe.csv", t, ".9g"), "following-error")


def test_csv_records_split_where_time_restarts_or_record_changes(tmp_path):
    t1 = np.arange(100) / FS
    fe = np.arange(300) * 1e-12
    # record 1 and 2: time restarts; record 3 continues the time of record 2 but
    # the record column changes
    t = np.concatenate([t1, t1, t1 + 100 / FS])
    rec_col = np.repeat([0, 1, 2], 100)
    cmd = np.linspace(0, 1e-6, 300)
    p = _write_fe(
        tmp_path / "fe.csv",
        t,
        ".9g",
        fe=fe,
        extra={"record": rec_col, "command_m": cmd},
    )
    out = read_recording(p, "following-error")
    assert len(out["records"]) == 3
    for i, r in enumerate(out["records"]):
        np.testing.assert_allclose(r["fe"], fe[100 * i : 100 * (i + 1)], rtol=1e-6)
        np.testing.assert_allclose(
            r["command"], cmd[100 * i : 100 * (i + 1)], rtol=1e-8
        )
        assert r["t0"] == pytest.approx(t[100 * i])
        assert "force" not in r
    assert out["fs"] == pytest.approx(FS, rel=1e-8)


def test_npz_following_error_with_records(tmp_path):
    fe = np.arange(2 * 64, dtype=float).reshape(2, 64) * 1e-12
    force = -fe * 1e3
    np.savez(
        tmp_path / "fe.npz", following_error_m=fe, fs_hz=np.array(5e3), force_n=force
    )
    out = read_recording(tmp_path / "fe.npz", "following-error")
    assert out["fs"] == 5e3 and len(out["records"]) == 2
    np.testing.assert_array_equal(out["records"][1]["fe"], fe[1])
    np.testing.assert_array_equal(out["records"][1]["force"], force[1])
    np.savez(
        tmp_path / "bad.npz",
        following_error_m=fe,
        fs_hz=np.array(5e3),
        force_n=force[:, :10],
    )
    with pytest.raises(ConfigError, match=r"bad\.npz: force_n shape"):
        read_recording(tmp_path / "bad.npz", "following-error")
    np.savez(tmp_path / "nofs.npz", following_error_m=fe)
    with pytest.raises(ConfigError, match="fs_hz"):
        read_recording(tmp_path / "nofs.npz", "following-error")


def test_bad_header_names_the_file_and_the_columns(tmp_path):
    p = tmp_path / "cut.csv"
    p.write_text("time_s,force\n" + "\n".join(f"{i},{i}" for i in range(10)) + "\n")
    with pytest.raises(ConfigError) as exc:
        read_recording(p, "cut")
    msg = str(exc.value)
    assert str(p) in msg and "time_s,force_n,following_error_m" in msg
    assert "\n" not in msg


def test_cut_csv(tmp_path):
    t = np.arange(50) / 1e4
    p = tmp_path / "cut.csv"
    rows = (f"{a!r},{a * 2e-6!r},{a * 3!r}" for a in t.tolist())
    p.write_text(
        "# a comment\nTime_s, following_error_m ,force_n\n" + "\n".join(rows) + "\n"
    )
    out = read_recording(p, "cut")
    assert out["fs"] == pytest.approx(1e4)
    np.testing.assert_array_equal(out["t"], t)
    np.testing.assert_array_equal(out["fe"], t * 2e-6)
    np.testing.assert_array_equal(out["force"], t * 3)


def test_frf_round_trip_and_zero_values(tmp_path):
    f = np.geomspace(10, 1e4, 40)
    h = 1.0 / (1.0 + 1j * f / 300.0)
    write_frf_csv(tmp_path / "frf.csv", f, h)
    out = read_recording(tmp_path / "frf.csv", "frf-open-loop")
    np.testing.assert_allclose(out["freq"], f, rtol=1e-9)
    np.testing.assert_allclose(out["frf"], h, rtol=1e-9)
    f2, h2 = read_frf_csv(tmp_path / "frf.csv")
    np.testing.assert_array_equal(f2, out["freq"])
    write_frf_csv(tmp_path / "zero.csv", f, np.where(f > 1e3, 0, h))
    with pytest.raises(ConfigError, match=r"zero\.csv: FRF values must be non-zero"):
        read_recording(tmp_path / "zero.csv", "frf-force")


def test_surface_npz_and_any_map_format(tmp_path):
    rng = np.random.default_rng(2)
    z = rng.normal(0, 1e-8, (8, 12))
    np.savez(tmp_path / "map.npz", z=z, dx=np.array(2e-6), dy=3e-6, x0=-1e-5)
    out = read_recording(tmp_path / "map.npz", "surface")
    assert (out["dx"], out["dy"], out["x0"]) == (2e-6, 3e-6, -1e-5) and "y0" not in out
    np.testing.assert_array_equal(out["z"], z)
    write_surface(Surface(z, 2e-6, 2e-6), tmp_path / "map.x3p")
    out = read_recording(tmp_path / "map.x3p", "surface")
    np.testing.assert_allclose(out["z"], z, atol=1e-12)
    assert out["dx"] == pytest.approx(2e-6)
    np.savez(tmp_path / "flat.npz", z=z[0], dx=1e-6, dy=1e-6)
    with pytest.raises(ConfigError, match=r"flat\.npz: z must be a 2-D map"):
        read_recording(tmp_path / "flat.npz", "surface")


def test_profile_npz(tmp_path):
    np.savez(tmp_path / "p.npz", z=np.arange(20.0) * 1e-9, dx=1e-6)
    out = read_recording(tmp_path / "p.npz", "profile")
    assert out["dx"] == 1e-6 and out["z"].shape == (20,) and "x0" not in out
    np.savez(tmp_path / "short.npz", z=np.arange(5.0), dx=1e-6)
    with pytest.raises(ConfigError, match=">= 8 samples"):
        read_recording(tmp_path / "short.npz", "profile")


def test_unknown_kind(tmp_path):
    with pytest.raises(ConfigError, match="unknown recording kind 'accel'"):
        read_recording(tmp_path / "x.csv", "accel")
