"""CLI: ``servosurf info``, ``convert`` and ``profile`` on real and bad files."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from servosurf.cli import main
from servosurf.io import read_surface, write_surface
from servosurf.metrology import Surface

#: SOURCES.md reference values: (rows, cols, dx_um, sq_nm, sq_plane_nm).
REFERENCE = {
    "newview_20x_mirau_mp8.1_metropro-1.dat": (480, 640, 1.09825, 75.2882, 13.3350),
    "newview_100x_mirau_mp8.1_05_C1S01.dat": (480, 640, 0.10963, 86.4682, 81.1547),
    "mx_export_hdrfmt1_nolatres_20191018_flat01.dat": (
        345,
        346,
        None,
        54.9766,
        54.9766,
    ),
    "newview_100x_05_C1S01_EDITEDHEADER.asc": (480, 640, 1.0963, 86.4682, 81.1547),
    "gpi_mp8.3.3_zygo_test.datx": (259, 33, 1000.0, 80.8177, 80.1964),
    "st_x3p-2_mountainsmap.x3p": (650, 650, 0.127657, 77.2803, 77.1930),
}
#: SOURCES.md gives pixel sizes and Sq to 6 significant digits.
REF_RTOL = 1e-4
PROFILE = "nexview_nx2_diamond_turned_1016-WLI-2D.csv"
JSON_KEYS = {
    "format",
    "rows",
    "cols",
    "dx_m",
    "dy_m",
    "invalid_fraction",
    "z_min_m",
    "z_max_m",
    "sa_m",
    "sq_m",
    "sq_plane_m",
    "metadata",
}


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_info_json_real_files(zygo_dir, capsys, name):
    rows, cols, dx, sq, sqp = REFERENCE[name]
    info = _json(capsys, ["info", str(zygo_dir / name), "--json"])
    assert set(info) >= JSON_KEYS
    assert (info["rows"], info["cols"]) == (rows, cols)
    if dx is None:
        assert info["dx_m"] is None and info["dy_m"] is None
    else:
        np.testing.assert_allclose(info["dx_m"], dx * 1e-6, rtol=REF_RTOL)
    np.testing.assert_allclose(info["sq_m"], sq * 1e-9, rtol=REF_RTOL)
    np.testing.assert_allclose(info["sq_plane_m"], sqp * 1e-9, rtol=REF_RTOL)
    assert info["metadata"]["source_format"] == info["format"]


AREAL_KEYS = (
    "sa_m sq_m sp_m sv_m sz_m ssk sku sdq sdr_percent sal_m str sk_m spk_m svk_m "
    "smr1_percent smr2_percent"
).split()


def test_info_json_areal_parameters_match_surfalize(zygo_dir, capsys):
    import warnings

    surfalize = pytest.importorskip("surfalize")
    name = "newview_20x_mirau_mp8.1_metropro-1.dat"  # void-free, tilted map
    info = _json(capsys, ["info", str(zygo_dir / name), "--json"])
    areal = info["areal"]
    assert set(areal) >= set(AREAL_KEYS)
    assert areal["form"] == "mean" and areal["cutoff_m"] is None
    s = read_surface(zygo_dir / name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # surfalize: Str undefined on this map
        sf = surfalize.Surface(s.z * 1e6, s.dx * 1e6, s.dy * 1e6)  # um
        ref = {"sp_m": sf.Sp() * 1e-6, "sv_m": sf.Sv() * 1e-6, "sdq": sf.Sdq()}
        ref |= {"sk_m": sf.Sk() * 1e-6, "sal_m": sf.Sal() * 1e-6}
        assert np.isnan(sf.Str()) and areal["str"] is None  # JSON null: undefined
    # same formulas (1e-12) except Sal (interpolation, 1 %) and Sk (surfalize's
    # 10 000-class material ratio curve, 5e-3): see tests/metrology
    for key, rtol in (("sp_m", 1e-12), ("sv_m", 1e-12), ("sdq", 1e-12)):
        np.testing.assert_allclose(areal[key], ref[key], rtol=rtol, err_msg=key)
    np.testing.assert_allclose(areal["sal_m"], ref["sal_m"], rtol=1e-2)
    np.testing.assert_allclose(areal["sk_m"], ref["sk_m"], rtol=5e-3)


def test_info_text_areal_lines(zygo_dir, capsys):
    name = "mx_export_hdrfmt1_nolatres_20191018_flat01.dat"  # uncalibrated
    assert main(["info", str(zygo_dir / name)]) == 0
    out = capsys.readouterr().out
    assert "Sdq / Sdr      undefined / undefined %" in out
    assert "Sk / Spk / Svk" in out and "Smr1" in out


def test_info_text(zygo_dir, capsys):
    assert main(["info", str(zygo_dir / "newview_20x_mirau_mp8.1_metropro-1.dat")]) == 0
    out = capsys.readouterr().out
    assert "metropro_dat" in out and "480 rows x 640 cols" in out
    assert "Sa / Sq        64.3152 / 75.2882 nm" in out
    assert "Sq after plane 13.3350 nm" in out


def test_info_profile(zygo_dir, capsys):
    info = _json(capsys, ["info", str(zygo_dir / PROFILE), "--json"])
    assert info["kind"] == "profile" and info["points"] == 962
    np.testing.assert_allclose(info["dx_m"], 0.87105e-6, rtol=1e-5)
    np.testing.assert_allclose(info["length_m"], 962 * info["dx_m"])


def test_info_uncalibrated_text(zygo_dir, capsys):
    assert (
        main(["info", str(zygo_dir / "mx_export_hdrfmt1_nolatres_20191018_flat01.dat")])
        == 0
    )
    assert "pixel uncalibrated" in capsys.readouterr().out


def test_profile_reference(zygo_dir, capsys):
    res = _json(capsys, ["profile", str(zygo_dir / PROFILE), "--json"])
    assert res["cutoff_m"] == pytest.approx(80e-6)  # ISO 4288: Ra < 0.02 um -> 0.08 mm
    assert res["cutoff_rule"] == "ISO 4288" and res["ends_trimmed"] is True
    np.testing.assert_allclose(res["ra_m"], 13.19e-9, rtol=1e-3)  # SOURCES.md
    assert {"ra_m", "rq_m", "rz_m", "cutoff_m", "ends_trimmed"} <= set(res)
    kept = _json(
        capsys,
        [
            "profile",
            str(zygo_dir / PROFILE),
            "--cutoff",
            "8e-5",
            "--keep-ends",
            "--json",
        ],
    )
    assert kept["ends_trimmed"] is False and kept["cutoff_rule"] == "given"
    np.testing.assert_allclose(kept["ra_m"], 14.6e-9, rtol=5e-3)  # SOURCES.md


def test_profile_text(zygo_dir, capsys):
    assert main(["profile", str(zygo_dir / PROFILE)]) == 0
    out = capsys.readouterr().out
    assert "cut-off        80 um (ISO 4288), ends trimmed by 80 um each" in out
    assert "Ra             13.18" in out


def test_profile_bad_cutoff(zygo_dir, capsys):
    assert main(["profile", str(zygo_dir / PROFILE), "--cutoff", "-1"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--cutoff must be > 0" in err


def test_profile_of_a_map_is_an_error(zygo_dir, capsys):
    assert (
        main(["profile", str(zygo_dir / "newview_20x_mirau_mp8.1_metropro-1.dat")]) == 1
    )
    assert "expected a profile" in capsys.readouterr().err


@pytest.mark.parametrize("suffix", [".datx", ".dat", ".x3p", ".xyz", ".npz"])
def test_convert_real_file(zygo_dir, tmp_path, capsys, suffix):
    src = zygo_dir / "newview_20x_mirau_mp8.1_metropro-1.dat"
    out = tmp_path / f"out{suffix}"
    assert main(["convert", str(src), str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    a, b = read_surface(src), read_surface(out)
    np.testing.assert_allclose(b.z, a.z, rtol=1e-12)
    np.testing.assert_allclose(b.dx, a.dx, rtol=1e-7)


def test_convert_format_flag_and_chain(zygo_dir, tmp_path, capsys):
    src = zygo_dir / "st_x3p-2_mountainsmap.x3p"
    assert main(["convert", str(src), str(tmp_path / "a.bin"), "--format", "datx"]) == 0
    assert main(["convert", str(tmp_path / "a.bin"), str(tmp_path / "b.npz")]) == 0
    capsys.readouterr()
    a, b = read_surface(src), read_surface(tmp_path / "b.npz")
    np.testing.assert_allclose(b.z, a.z, rtol=5e-16)
    assert (b.dx, b.dy) == pytest.approx((a.dx, a.dy), rel=1e-15, abs=0.0)


def test_convert_errors(zygo_dir, tmp_path, capsys):
    src = zygo_dir / "st_x3p-2_mountainsmap.x3p"  # rectangular pixels
    assert main(["convert", str(src), str(tmp_path / "a.dat")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pixels are not square" in err
    assert not (tmp_path / "a.dat").exists()
    assert main(["convert", str(src), str(tmp_path / "a.tif")]) == 1
    assert "no writer for suffix '.tif'" in capsys.readouterr().err
    assert main(["convert", str(src), str(src)]) == 1
    assert "is the input file" in capsys.readouterr().err


@pytest.mark.parametrize(
    "content,fragment",
    [
        (b"\x88\x1b\x03\x6f" + b"\0" * 100, "inside the MetroPro header"),
        (b"PK\x03\x04garbage", "not a readable zip archive"),
        (b"hello", "magic number"),
    ],
)
def test_bad_file_one_line_exit_1(tmp_path, capsys, content, fragment):
    suffix = {b"P": ".x3p", b"h": ".dat"}.get(content[:1], ".dat")
    bad = tmp_path / f"bad{suffix}"
    bad.write_bytes(content)
    assert main(["info", str(bad)]) == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("servosurf info: error: ")
    assert str(bad) in lines[0] and fragment in lines[0] and "expected" in lines[0]


def test_missing_file(tmp_path, capsys):
    assert main(["info", str(tmp_path / "nope.dat")]) == 1
    assert "No such file" in capsys.readouterr().err


def test_all_nan_map_is_reported(tmp_path, capsys):
    write_surface(Surface(np.full((2, 3), np.nan), 1e-6, 1e-6), tmp_path / "n.npz")
    assert main(["info", str(tmp_path / "n.npz")]) == 1
    assert "all 6 pixels of the 2x3 map are invalid" in capsys.readouterr().err


def test_subprocess_bad_file_no_traceback(zygo_dir, tmp_path):
    bad = tmp_path / "bad.datx"
    bad.write_bytes((zygo_dir / "gpi_mp8.3.3_zygo_test.datx").read_bytes()[:5000])
    out = subprocess.run(
        [sys.executable, "-m", "servosurf", "info", str(bad), "--json"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 1 and out.stdout == ""
    assert out.stderr.count("\n") == 1 and "Traceback" not in out.stderr
    assert (
        out.stderr.startswith("servosurf info: error: ")
        and "file is truncated" in out.stderr
    )
