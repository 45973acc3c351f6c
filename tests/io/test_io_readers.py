"""Readers against real instrument files and the reference table of SOURCES.md.

Every real file is read from its path and from a BytesIO buffer; the result must
match the values Gwyddion, SurfaceTopography and prysm give (SOURCES.md), and the
heights must agree point by point with an independent reader where one exists.
"""

from __future__ import annotations

import io
import warnings

import numpy as np
import pytest

from servosurf.errors import UnsupportedFileFormatError
from servosurf.io import formats, read_any, read_profile, read_surface
from servosurf.metrology import Profile, Surface

#: SOURCES.md gives pixel sizes and Sq to 6 significant digits: compare to 1e-4.
REF_RTOL = 1e-4
#: z range is given to 4 significant digits (e.g. 50.11 um), invalid to 0.1 %.
ZRANGE_RTOL = 2e-3
INVALID_ATOL = 0.0006
#: Independent readers agree with ours to float32 header precision.
INDEPENDENT_RTOL = 1e-6

# file: (format, rows, cols, dx_um, dy_um, invalid, zmin_um, zmax_um, sa_nm, sq_nm,
#        sq_plane_nm) -- from /work/shared/data/zygo/SOURCES.md
REFERENCE = {
    "newview_20x_mirau_mp8.1_metropro-1.dat": (
        "metropro_dat",
        480,
        640,
        1.09825,
        1.09825,
        0.0,
        50.11,
        51.47,
        64.3152,
        75.2882,
        13.3350,
    ),
    "newview_100x_mirau_mp8.1_05_C1S01.dat": (
        "metropro_dat",
        480,
        640,
        0.10963,
        0.10963,
        0.0,
        4.241,
        4.589,
        72.6267,
        86.4682,
        81.1547,
    ),
    "mx_export_hdrfmt1_nolatres_20191018_flat01.dat": (
        "metropro_dat",
        345,
        346,
        None,
        None,
        0.215,
        -0.1975,
        0.1301,
        41.4773,
        54.9766,
        54.9766,
    ),
    "newview_100x_05_C1S01_EDITEDHEADER.asc": (
        "zygo_ascii",
        480,
        640,
        1.0963,
        1.0963,
        0.0,
        4.241,
        4.589,
        72.6267,
        86.4682,
        81.1547,
    ),
    "gpi_mp8.3.3_zygo_test.datx": (
        "datx",
        259,
        33,
        1000.0,
        1000.0,
        0.091,
        -0.1465,
        0.3066,
        69.5196,
        80.8177,
        80.1964,
    ),
    "st_x3p-2_mountainsmap.x3p": (
        "x3p",
        650,
        650,
        0.127657,
        0.314582,
        0.0,
        -0.3144,
        0.2399,
        61.9547,
        77.2803,
        77.1930,
    ),
}
PROFILE_CSV = "nexview_nx2_diamond_turned_1016-WLI-2D.csv"


def _open(path, how):
    if how == "path":
        return path
    return io.BytesIO(path.read_bytes())


@pytest.fixture(scope="module")
def surfaces(zygo_dir):
    """Each reference file read once from its path (the slow part of this module)."""
    return {name: read_surface(zygo_dir / name) for name in REFERENCE}


def test_every_registered_reader_has_a_real_file():
    readers = {f.name for f in formats() if f.readable}
    # formtracer: the real contour of ../shared/data/upm_sts (test_formtracer.py)
    covered = {v[0] for v in REFERENCE.values()} | {"mx_profile_csv", "formtracer"}
    # zygo_xyz and npz have no public instrument file; they are covered by
    # synthetic files (test_io_synthetic.py) and writer round trips.
    assert readers - covered == {"zygo_xyz", "npz"}


@pytest.mark.parametrize("how", ["path", "bytesio"])
@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_reference_values(zygo_dir, name, how):
    fmt, rows, cols, dx, dy, invalid, zmin, zmax, sa, sq, sqp = REFERENCE[name]
    obj, used = read_any(_open(zygo_dir / name, how))
    assert used == fmt
    assert isinstance(obj, Surface)
    assert obj.shape == (rows, cols)
    if dx is None:
        assert obj.dx is None and obj.dy is None  # lateral_res 0: uncalibrated
    else:
        np.testing.assert_allclose(obj.dx, dx * 1e-6, rtol=REF_RTOL)
        np.testing.assert_allclose(obj.dy, dy * 1e-6, rtol=REF_RTOL)
    np.testing.assert_allclose(obj.invalid_fraction, invalid, atol=INVALID_ATOL)
    v = obj.z[np.isfinite(obj.z)]
    np.testing.assert_allclose(
        [v.min(), v.max()], [zmin * 1e-6, zmax * 1e-6], rtol=ZRANGE_RTOL, atol=1e-10
    )  # 0.1 nm
    np.testing.assert_allclose(obj.sa(), sa * 1e-9, rtol=REF_RTOL)
    np.testing.assert_allclose(obj.sq(), sq * 1e-9, rtol=REF_RTOL)
    np.testing.assert_allclose(obj.level().sq(), sqp * 1e-9, rtol=REF_RTOL)
    assert obj.metadata["source_format"] == fmt


def test_format_can_be_forced_by_name_and_suffix(zygo_dir):
    p = zygo_dir / "newview_20x_mirau_mp8.1_metropro-1.dat"
    a = read_surface(io.BytesIO(p.read_bytes()), format="metropro_dat")
    b = read_surface(io.BytesIO(p.read_bytes()), format=".dat")
    np.testing.assert_array_equal(a.z, b.z)
    with pytest.raises(UnsupportedFileFormatError, match="no reader for format 'tiff'"):
        read_surface(p, format="tiff")


def test_metadata_of_real_files(surfaces):
    md = surfaces["newview_20x_mirau_mp8.1_metropro-1.dat"].metadata
    assert md["objective"] == "20X  Mirau"
    assert md["zoom"] == "0.5X"
    assert md["software"] == "MetroPro 8.1.5"
    np.testing.assert_allclose(md["wavelength"], 570e-9, rtol=1e-7)  # float32 header
    assert md["metropro"]["header_format"] == 1
    assert md["metropro"]["camera_size"] == [640, 480]
    assert md["metropro"]["intensity"]["size"] == [640, 480]
    mx = surfaces["mx_export_hdrfmt1_nolatres_20191018_flat01.dat"].metadata
    assert mx["date"].startswith("2019-10-18")  # the file name says 20191018
    assert mx["metropro"]["intensity"] is None  # no intensity block
    assert mx["metropro"]["phase_origin"] == [151, 63]  # window inside 640x480 camera
    datx = surfaces["gpi_mp8.3.3_zygo_test.datx"].metadata
    assert datx["instrument"] == "ZYGO GPI"
    assert datx["datx"]["unit"] == "Fringes"
    np.testing.assert_allclose(datx["wavelength"], 632.8e-9, rtol=1e-7)
    x3p = surfaces["st_x3p-2_mountainsmap.x3p"].metadata
    assert "MountainsMap" in x3p["instrument"].replace(" ", "")


def test_ascii_twin_matches_binary(surfaces):
    # Same phase integers; only the hand-edited lateral resolution differs.
    a = surfaces["newview_100x_05_C1S01_EDITEDHEADER.asc"]
    b = surfaces["newview_100x_mirau_mp8.1_05_C1S01.dat"]
    np.testing.assert_allclose(a.z, b.z, rtol=INDEPENDENT_RTOL)
    np.testing.assert_allclose(a.dx, 10 * b.dx, rtol=1e-4)


def _st_heights(path, fmt):
    with warnings.catch_warnings():
        # SurfaceTopography's import (NuMPI's ImportWarning about mpi4py) and its own
        # deprecations are not ours to fix.
        warnings.simplefilter("ignore")
        import SurfaceTopography as st

        t = st.read_topography(str(path), format=fmt)
        h = t.heights()
    mask = np.ma.getmaskarray(h)
    arr = np.where(mask, np.nan, np.ma.getdata(h)).T  # ST stores (x, y)
    return arr, t


@pytest.mark.parametrize(
    "name,fmt",
    [
        ("newview_20x_mirau_mp8.1_metropro-1.dat", "metropro"),
        ("mx_export_hdrfmt1_nolatres_20191018_flat01.dat", "metropro"),
        ("st_x3p-2_mountainsmap.x3p", "x3p"),
        ("ISO5436-sample4_bin.x3p", "x3p"),
    ],
)
def test_heights_match_surfacetopography(zygo_dir, name, fmt):
    ours = read_surface(zygo_dir / name)
    ref, _ = _st_heights(zygo_dir / name, fmt)
    np.testing.assert_array_equal(np.isnan(ours.z), np.isnan(ref))
    np.testing.assert_allclose(ours.z, ref, rtol=INDEPENDENT_RTOL, atol=1e-15)


def test_datx_heights_match_prysm(zygo_dir):
    read_zygo_datx = pytest.importorskip("prysm.io").read_zygo_datx

    p = zygo_dir / "gpi_mp8.3.3_zygo_test.datx"
    ours = read_surface(p)
    ref = read_zygo_datx(str(p))["phase"] * 1e-9  # prysm gives nm
    np.testing.assert_array_equal(np.isnan(ours.z), np.isnan(ref))
    np.testing.assert_allclose(ours.z, ref, rtol=INDEPENDENT_RTOL)


def test_iso_sample_values(zygo_dir):
    # ISO 5436-2 sample 4: int16 heights with z = raw * 0.001 - 0.5 m, point (x=3,
    # y=1) flagged invalid in valid.bin, x fastest in the data member.
    s = read_surface(zygo_dir / "ISO5436-sample4_bin.x3p")
    assert s.shape == (4, 4)
    np.testing.assert_allclose(s.dx, 0.016016)
    np.testing.assert_allclose(s.z[0], [0.486, 0.003, -0.808, -0.58], atol=1e-12)
    assert np.isnan(s.z[1, 3]) and np.isfinite(s.z).sum() == 15


@pytest.mark.parametrize("how", ["path", "bytesio"])
def test_profile_csv(zygo_dir, how):
    p = read_profile(_open(zygo_dir / PROFILE_CSV, how))
    assert isinstance(p, Profile)
    assert p.z.size == 962  # SOURCES.md: 962 points, 0.871 um spacing
    np.testing.assert_allclose(p.dx, 0.871050452e-6, rtol=1e-8)
    np.testing.assert_allclose(p.x0, 0.871050452310786e-6)
    assert np.isfinite(p.z).all()
    np.testing.assert_allclose(p.z[:2], [-0.0156344548055175e-6, -8.64649943417467e-11])
    assert p.metadata["slice"] == "Slice 1"


def test_profile_roughness_reference(zygo_dir):
    from servosurf.metrology import profile_roughness

    p = read_profile(zygo_dir / PROFILE_CSV)
    trimmed = profile_roughness(p, cutoff=80e-6)
    kept = profile_roughness(p, cutoff=80e-6, trim_ends=False)
    np.testing.assert_allclose(trimmed["ra_m"], 13.19e-9, rtol=1e-3)  # SOURCES.md
    np.testing.assert_allclose(kept["ra_m"], 14.6e-9, rtol=5e-3)


def test_surface_reader_returns_profile_as_one_row(zygo_dir):
    s = read_surface(zygo_dir / PROFILE_CSV)
    assert s.shape == (1, 962) and s.dx == s.dy


def test_read_profile_rejects_maps(zygo_dir):
    with pytest.raises(
        UnsupportedFileFormatError, match="480x640 surface.*expected a profile"
    ):
        read_profile(zygo_dir / "newview_20x_mirau_mp8.1_metropro-1.dat")


def test_read_profile_accepts_one_row_surface(tmp_path):
    from servosurf.io import write_surface

    s = Surface(np.arange(10.0)[None] * 1e-9, 2e-6, 2e-6, x0=4e-6)
    write_surface(s, tmp_path / "row.npz")
    p = read_profile(tmp_path / "row.npz")
    assert p.dx == 2e-6 and p.x0 == 4e-6
    np.testing.assert_array_equal(p.z, s.z[0])


def test_unknown_content_and_suffix():
    with pytest.raises(
        UnsupportedFileFormatError, match="unknown file format.*expected one of"
    ):
        read_surface(io.BytesIO(b"just some text\n1 2 3\n"))


def test_formats_listing():
    info = {f.name: f for f in formats()}
    assert set(info) == {
        "metropro_dat",
        "zygo_ascii",
        "zygo_xyz",
        "datx",
        "x3p",
        "npz",
        "mx_profile_csv",
        "formtracer",
    }
    assert {n for n, f in info.items() if f.writable} == {
        "metropro_dat",
        "zygo_xyz",
        "datx",
        "x3p",
        "npz",
    }
    assert info["mx_profile_csv"].kind == "profile"
    assert info["formtracer"].kind == "profile"
    assert info["datx"].suffixes == (".datx",)
