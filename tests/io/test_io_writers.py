"""Writers: round trips through our readers and independent ones, atomic writes,
metadata storage and the limits of each format."""

from __future__ import annotations

import io
import json
import warnings
import zipfile

import numpy as np
import pytest

from servosurf.errors import FileFormatError, UnsupportedFileFormatError
from servosurf.io import encode_surface, formats, read_surface, write_surface
from servosurf.metrology import Profile, Surface

WRITERS = sorted(f.name for f in formats() if f.writable)
SUFFIX = {
    "datx": ".datx",
    "metropro_dat": ".dat",
    "x3p": ".x3p",
    "zygo_xyz": ".xyz",
    "npz": ".npz",
}
#: Two float64 ulp: datx stores nm and xyz um (17-digit text), so the m <-> nm/um
#: scaling rounds once each way; x3p and npz store the float64 metres unchanged.
FLOAT_RTOL = 4.5e-16
#: Height resolution of each format as (rtol, atol in m); .dat quantises heights to
#: half a count of intf_scale_factor * obliquity * wavelength / R = 0.5 * 632.8 nm /
#: 32768 (9.7 pm), i.e. atol 4.8 pm.
HEIGHT_TOL = {
    "datx": (FLOAT_RTOL, 0.0),
    "zygo_xyz": (FLOAT_RTOL, 0.0),
    "x3p": (0.0, 0.0),
    "npz": (0.0, 0.0),
    "metropro_dat": (0.0, 0.5 * float(np.float32(632.8e-9)) / 32768 / 2 * 1.0001),
}
#: .dat stores lateral_res as float32.
PIXEL_RTOL = {"metropro_dat": 1e-7}
USER_MD = {
    "feed": 2.5e-6,
    "spindle_rpm": 1000,
    "note": "simulated",
    "tags": ["a", "b"],
    "wavelength": 632.8e-9,
}


def _surface(
    shape=(23, 31), dx=0.5e-6, dy=0.5e-6, seed=0, x0=1.5e-6, y0=2.0e-6
) -> Surface:
    rng = np.random.default_rng(seed)  # fixed seed: random heights, shape-only tests
    z = rng.normal(0.0, 40e-9, shape) + 1e-6
    z[3, 4] = np.nan
    z[-1, :5] = np.nan
    return Surface(z, dx, dy, metadata=dict(USER_MD), x0=x0, y0=y0)


def _check_same(fmt, back: Surface, s: Surface):
    assert back.shape == s.shape
    np.testing.assert_array_equal(np.isnan(back.z), np.isnan(s.z))
    rtol, atol = HEIGHT_TOL[fmt]
    np.testing.assert_allclose(back.z, s.z, rtol=rtol, atol=atol)
    if s.calibrated:
        np.testing.assert_allclose(
            [back.dx, back.dy], [s.dx, s.dy], rtol=PIXEL_RTOL.get(fmt, 1e-15)
        )
        np.testing.assert_allclose(
            [back.x0, back.y0], [s.x0, s.y0], rtol=PIXEL_RTOL.get(fmt, 1e-15)
        )
    else:
        assert back.dx is None and back.dy is None


@pytest.mark.parametrize("how", ["path", "bytesio"])
@pytest.mark.parametrize("fmt", WRITERS)
def test_round_trip_own_reader(tmp_path, fmt, how):
    s = _surface()
    path = tmp_path / f"s{SUFFIX[fmt]}"
    write_surface(s, path)
    back = read_surface(path if how == "path" else io.BytesIO(path.read_bytes()))
    _check_same(fmt, back, s)
    assert back.metadata["source_format"] == fmt
    np.testing.assert_allclose(back.metadata["wavelength"], 632.8e-9, rtol=1e-7)
    if fmt != "zygo_xyz":  # the XYZ header has no room for free metadata
        for k in ("feed", "spindle_rpm", "note", "tags"):
            assert back.metadata[k] == USER_MD[k]


@pytest.mark.parametrize("fmt", WRITERS)
def test_write_to_buffer_needs_format_and_equals_file(tmp_path, fmt):
    s = _surface()
    with pytest.raises(UnsupportedFileFormatError, match="format must be given"):
        write_surface(s, io.BytesIO())
    buf = io.BytesIO()
    write_surface(s, buf, format=fmt)
    back = read_surface(io.BytesIO(buf.getvalue()))
    _check_same(fmt, back, s)


@pytest.mark.parametrize("fmt", ["datx", "metropro_dat", "zygo_xyz", "npz"])
def test_uncalibrated_round_trip(tmp_path, fmt):
    s = _surface(dx=None, dy=None, x0=0.0, y0=0.0)
    write_surface(s, tmp_path / f"u{SUFFIX[fmt]}")
    _check_same(fmt, read_surface(tmp_path / f"u{SUFFIX[fmt]}"), s)


def test_x3p_needs_calibration(tmp_path):
    s = _surface(dx=None, dy=None, x0=0.0, y0=0.0)
    with pytest.raises(FileFormatError, match="cannot write x3p: .*uncalibrated"):
        write_surface(s, tmp_path / "u.x3p")
    assert not list(tmp_path.iterdir())  # nothing, not even a temporary file


@pytest.mark.parametrize("fmt", ["metropro_dat", "zygo_xyz"])
def test_square_pixel_formats_reject_rectangular_pixels(tmp_path, fmt):
    s = _surface(dx=0.5e-6, dy=0.7e-6)
    with pytest.raises(FileFormatError, match="pixels are not square"):
        write_surface(s, tmp_path / f"r{SUFFIX[fmt]}")


def test_rectangular_pixels_in_x3p_datx_npz(tmp_path):
    s = _surface(dx=0.127657e-6, dy=0.314582e-6)
    for fmt in ("x3p", "datx", "npz"):
        write_surface(s, tmp_path / f"r{SUFFIX[fmt]}")
        _check_same(fmt, read_surface(tmp_path / f"r{SUFFIX[fmt]}"), s)


def test_write_is_atomic(tmp_path):
    s = _surface()
    target = tmp_path / "keep.dat"
    target.write_bytes(b"old content")
    tall = s.replace(z=s.z * 1e6)  # metres of height: beyond the .dat int32 range
    with pytest.raises(FileFormatError, match="exceed the int32 phase range"):
        write_surface(tall, target)
    assert target.read_bytes() == b"old content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.dat"]


def test_unknown_suffix_and_options(tmp_path):
    s = _surface()
    with pytest.raises(UnsupportedFileFormatError, match="no writer for suffix '.tif'"):
        write_surface(s, tmp_path / "a.tif")
    with pytest.raises(TypeError, match="phase_ress"):
        write_surface(s, tmp_path / "a.dat", phase_ress=2)


def test_profile_in_x3p_reads_as_one_row_map(tmp_path):
    p = Profile(np.sin(np.arange(50) / 5) * 1e-8, 1e-6, x0=3e-6)
    write_surface(p, tmp_path / "p.x3p")
    back = read_surface(tmp_path / "p.x3p")
    assert back.shape == (1, 50)
    np.testing.assert_array_equal(back.z[0], p.z)


# ---------------------------------------------------------------- independent readers
def _st(path, fmt):
    with warnings.catch_warnings():
        # NuMPI's ImportWarning about mpi4py and SurfaceTopography deprecations.
        warnings.simplefilter("ignore")
        import SurfaceTopography as st

        t = st.read_topography(str(path), format=fmt)
        h = t.heights()
    z = np.where(np.ma.getmaskarray(h), np.nan, np.ma.getdata(h)).T  # ST is (x, y)
    return z, t


@pytest.mark.parametrize(
    "fmt,st_format,unit",
    [("datx", "datx", 1e-9), ("metropro_dat", "metropro", 1.0), ("x3p", "x3p", 1.0)],
)
def test_round_trip_surfacetopography(tmp_path, fmt, st_format, unit):
    s = _surface(dx=0.4e-6, dy=0.4e-6 if fmt == "metropro_dat" else 0.6e-6)
    path = tmp_path / f"s{SUFFIX[fmt]}"
    write_surface(s, path)
    z, t = _st(path, st_format)
    np.testing.assert_array_equal(np.isnan(z), np.isnan(s.z))
    rtol, atol = HEIGHT_TOL[fmt]
    np.testing.assert_allclose(z * unit, s.z, rtol=rtol, atol=atol)
    nx, ny = t.nb_grid_pts
    assert (ny, nx) == s.shape
    sx, sy = t.physical_sizes
    np.testing.assert_allclose(
        [sx * unit / nx, sy * unit / ny], [s.dx, s.dy], rtol=PIXEL_RTOL.get(fmt, 1e-12)
    )


def test_datx_round_trip_prysm(tmp_path):
    read_zygo_datx = pytest.importorskip("prysm.io").read_zygo_datx

    s = _surface()
    write_surface(s, tmp_path / "s.datx")
    d = read_zygo_datx(str(tmp_path / "s.datx"))
    z = d["phase"] * 1e-9  # prysm returns nm
    np.testing.assert_array_equal(np.isnan(z), np.isnan(s.z))
    np.testing.assert_allclose(z, s.z, rtol=FLOAT_RTOL)
    assert json.loads(d["meta"]["servosurf.metadata"])["feed"] == USER_MD["feed"]


def test_dat_round_trip_prysm(tmp_path):
    read_zygo_dat = pytest.importorskip("prysm.io").read_zygo_dat

    s = _surface()
    write_surface(s, tmp_path / "s.dat")
    d = read_zygo_dat(str(tmp_path / "s.dat"))
    np.testing.assert_allclose(
        d["phase"] * 1e-9, s.z, rtol=0, atol=HEIGHT_TOL["metropro_dat"][1]
    )


def test_xyz_round_trip_plain_text_parser(tmp_path):
    # SurfaceTopography 1.27 has no ZYGO XYZ reader (read_topography raises
    # CannotDetectFileFormat), prysm none either: parse the data lines with numpy.
    s = _surface()
    write_surface(s, tmp_path / "s.xyz")
    lines = (tmp_path / "s.xyz").read_text().splitlines()
    start = lines.index("#") + 1
    rows = [ln.replace("No Data", "nan").split() for ln in lines[start:-1]]
    xyz = np.array(rows, dtype=float)
    ox, oy = 3, 4  # x0 / dx, y0 / dy of _surface()
    z = np.full(s.shape, np.inf)
    z[xyz[:, 1].astype(int) - oy, xyz[:, 0].astype(int) - ox] = xyz[:, 2] * 1e-6
    np.testing.assert_allclose(z, s.z, rtol=FLOAT_RTOL)


def test_npz_round_trip_surfacetopography(tmp_path):
    # SurfaceTopography's NPZReader takes the "z" member as the height channel but
    # cannot know servosurf's dx/dy members: they are given, and checked via numpy
    # in test_npz_round_trip_numpy.
    s = _surface()
    write_surface(s, tmp_path / "s.npz")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # NuMPI ImportWarning, ST deprecations
        import SurfaceTopography as st

        r = st.open_topography(str(tmp_path / "s.npz"))
        t = r.topography(physical_sizes=(1.0, 1.0))
        h = np.ma.filled(t.heights(), np.nan)
    assert type(r).__name__ == "NPZReader"
    np.testing.assert_array_equal(h, s.z)


def test_xyz_surfacetopography_cannot_read(tmp_path):
    write_surface(_surface(), tmp_path / "s.xyz")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import SurfaceTopography as st

        try:
            st.read_topography(str(tmp_path / "s.xyz"))
        except Exception as exc:  # CannotDetectFileFormat and friends
            pytest.skip(
                f"SurfaceTopography {st.__version__} has no ZYGO XYZ reader "
                f"({type(exc).__name__}); test_xyz_round_trip_plain_text_parser checks "
                "the file independently"
            )
    pytest.fail("SurfaceTopography now reads ZYGO XYZ: compare its heights here")


def test_npz_round_trip_numpy(tmp_path):
    s = _surface()
    write_surface(s, tmp_path / "s.npz")
    with np.load(tmp_path / "s.npz", allow_pickle=False) as d:
        np.testing.assert_array_equal(d["z"], s.z)
        assert float(d["dx"]) == s.dx and float(d["dy"]) == s.dy
        assert json.loads(str(d["metadata"]))["note"] == "simulated"


def test_x3p_archive_layout(tmp_path):
    s = _surface()
    data = encode_surface(s, "x3p")
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        assert set(zf.namelist()) == {
            "main.xml",
            "md5checksum.hex",
            "bindata/data.bin",
            "bindata/valid.bin",
        }
        xml = zf.read("main.xml").decode()
    assert "<Revision>ISO5436 - 2000</Revision>" in xml
    assert "<FeatureType>SUR</FeatureType>" in xml
    assert '"feed":2.5e-06' in xml.replace("&quot;", '"')


def test_dat_comment_is_truncated(tmp_path):
    s = _surface()
    s = s.replace(metadata={"long": "x" * 500})
    write_surface(s, tmp_path / "c.dat")
    raw = (tmp_path / "c.dat").read_bytes()
    assert raw[80:161].startswith(b'{"long":"xxx') and raw[161] == 0  # 81 bytes + NUL
    back = read_surface(tmp_path / "c.dat")
    assert back.metadata["comment"].startswith('{"long":"xxx')


def test_real_file_converts_to_every_writer(zygo_dir, tmp_path):
    src = read_surface(zygo_dir / "newview_20x_mirau_mp8.1_metropro-1.dat")
    for fmt in WRITERS:
        write_surface(src, tmp_path / f"c{SUFFIX[fmt]}")
        back = read_surface(tmp_path / f"c{SUFFIX[fmt]}")
        np.testing.assert_allclose(back.sq(), src.sq(), rtol=1e-9)
        if (
            fmt == "metropro_dat"
        ):  # same wavelength and phase_res: bit-identical heights
            np.testing.assert_array_equal(back.z, src.z)
        assert back.metadata.get("objective") == "20X  Mirau"
