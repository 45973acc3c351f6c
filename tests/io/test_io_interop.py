"""Files servosurf writes, as other software reads them (issue 17 item 5, issue 20).

Oracles: surfalize (checks the .x3p MD5 checksums), prysm (.datx pixel size,
.dat header fields), SurfaceTopography (.dat/.datx heights), :mod:`hashlib`,
:mod:`xml.etree`, :mod:`zipfile` and :mod:`h5py` reading the bytes directly, and a
real Mx ``.datx`` for the attribute layout.
"""

from __future__ import annotations

import hashlib
import io
import re
import subprocess
import sys
import time
import warnings
import xml.etree.ElementTree as ET
import zipfile
from unittest import mock

import numpy as np
import pytest

from servosurf.errors import CorruptedFileError
from servosurf.io import (
    encode_surface,
    formats,
    read_any,
    read_profile,
    read_surface,
    write_surface,
)
from servosurf.metrology import Profile, Surface

WRITERS = sorted(f.name for f in formats() if f.writable)
SUFFIX = {
    "datx": ".datx",
    "metropro_dat": ".dat",
    "x3p": ".x3p",
    "zygo_xyz": ".xyz",
    "npz": ".npz",
}
HEX32 = re.compile(r"[0-9a-f]{32}")
#: surfalize works in um: scaling m -> um -> m rounds once each way (two ulp).
UM_RTOL = 4.5e-16


def _surface(voids: bool = True, seed: int = 0) -> Surface:
    rng = np.random.default_rng(seed)  # fixed seed: arbitrary heights
    z = rng.normal(0.0, 30e-9, (17, 23))
    if voids:
        z[2, 3] = np.nan
        z[-1, :4] = np.nan
    return Surface(z, 0.5e-6, 0.5e-6, metadata={"note": "simulated"}, x0=1e-6)


def _profile() -> Profile:
    rng = np.random.default_rng(1)  # fixed seed: arbitrary heights
    z = rng.normal(0.0, 10e-9, 57)
    z[5] = np.nan
    return Profile(z, 0.25e-6, metadata={"note": "a trace"}, x0=3e-6)


def _members(data: bytes) -> dict[str, bytes]:
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        return {n: zf.read(n) for n in zf.namelist()}


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _find(root: ET.Element, path: str) -> ET.Element:
    e = root
    for part in path.split("/"):
        e = next(c for c in e if _local(c.tag) == part)
    return e


# ------------------------------------------------------------------------ .x3p
def test_x3p_checksums_are_lower_case_md5_of_the_members():
    m = _members(encode_surface(_surface(), "x3p"))
    line = m["md5checksum.hex"].decode("ascii")
    # md5sum's format: 32 lower-case hex digits, " *", the file name
    assert re.fullmatch(r"[0-9a-f]{32} \*main\.xml\n", line)
    assert line[:32] == hashlib.md5(m["main.xml"]).hexdigest()
    root = ET.fromstring(m["main.xml"])
    link = _find(root, "Record3/DataLink")
    data_md5 = _find(link, "MD5ChecksumPointData").text
    valid_md5 = _find(link, "MD5ChecksumValidPoints").text
    assert HEX32.fullmatch(data_md5) and HEX32.fullmatch(valid_md5)
    assert data_md5 == hashlib.md5(m["bindata/data.bin"]).hexdigest()
    assert valid_md5 == hashlib.md5(m["bindata/valid.bin"]).hexdigest()


@pytest.mark.parametrize("voids", [False, True])
def test_x3p_read_by_surfalize(tmp_path, voids):
    surfalize = pytest.importorskip("surfalize")
    s = _surface(voids=voids)
    write_surface(s, tmp_path / "s.x3p")
    sf = surfalize.Surface.load(tmp_path / "s.x3p")  # verifies the main.xml MD5
    np.testing.assert_array_equal(np.isnan(sf.data), np.isnan(s.z))
    np.testing.assert_allclose(sf.data * 1e-6, s.z, rtol=UM_RTOL)
    np.testing.assert_allclose(
        [sf.step_x * 1e-6, sf.step_y * 1e-6], [s.dx, s.dy], rtol=UM_RTOL
    )


def test_x3p_profile_is_written_as_prf():
    p = _profile()
    m = _members(encode_surface(p, "x3p"))
    root = ET.fromstring(m["main.xml"])
    assert _find(root, "Record1/FeatureType").text == "PRF"
    dims = [int(_find(root, f"Record3/MatrixDimension/Size{a}").text) for a in "XYZ"]
    assert dims == [p.z.size, 1, 1]  # ISO 5436-2: a profile is an N x 1 x M matrix
    assert float(_find(root, "Record1/Axes/CX/Increment").text) == p.dx
    assert float(_find(root, "Record1/Axes/CX/Offset").text) == p.x0
    z = np.frombuffer(m["bindata/data.bin"], dtype="<f8")
    np.testing.assert_array_equal(z, p.z)
    bits = np.frombuffer(m["bindata/valid.bin"], np.uint8)
    valid = np.unpackbits(bits, count=p.z.size, bitorder="little")
    np.testing.assert_array_equal(valid.astype(bool), np.isfinite(p.z))


def test_x3p_profile_reads_back_as_profile(tmp_path):
    p = _profile()
    write_surface(p, tmp_path / "p.x3p")
    back, fmt = read_any(tmp_path / "p.x3p")
    assert fmt == "x3p" and isinstance(back, Profile)
    assert (back.dx, back.x0) == (p.dx, p.x0)
    np.testing.assert_array_equal(back.z, p.z)
    assert back.metadata["note"] == "a trace" and back.metadata["kind"] == "profile"
    assert read_profile(tmp_path / "p.x3p").z.size == p.z.size
    one_row = read_surface(tmp_path / "p.x3p")  # a profile read as a map: one row
    assert one_row.shape == (1, p.z.size)


def test_x3p_profile_is_a_profile_to_surfalize(tmp_path):
    # surfalize reads surfaces only: it must see FeatureType PRF and refuse
    surfalize = pytest.importorskip("surfalize")
    write_surface(_profile(), tmp_path / "p.x3p")
    with pytest.raises(Exception, match="PRF"):
        surfalize.Surface.load(tmp_path / "p.x3p")


def test_x3p_prf_with_several_rows_is_refused(tmp_path):
    m = _members(encode_surface(_surface(voids=False), "x3p"))
    xml = m["main.xml"].replace(b"<FeatureType>SUR<", b"<FeatureType>PRF<")
    m["main.xml"] = xml
    m["md5checksum.hex"] = f"{hashlib.md5(xml).hexdigest()} *main.xml\n".encode()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, content in m.items():
            zf.writestr(name, content)
    with pytest.raises(CorruptedFileError, match="PRF but SizeY is 17"):
        read_any(buf.getvalue())


# ----------------------------------------------------------------------- .datx
def _h5_attrs(path) -> dict[str, dict]:
    import h5py

    out: dict[str, dict] = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: out.update({name: dict(obj.attrs)}))
        out["/"] = dict(f.attrs)
    return out


def test_datx_pixel_size_found_by_prysm(tmp_path):
    prysm_interf = pytest.importorskip("prysm.interferogram")
    s = _surface().replace(dx=0.8e-6, dy=0.8e-6)
    write_surface(s, tmp_path / "s.datx")
    i = prysm_interf.Interferogram.from_zygo_dat(str(tmp_path / "s.datx"))
    assert i.dx == pytest.approx(s.dx * 1e3, rel=1e-15)  # prysm: mm


def test_datx_resolution_attributes_as_in_a_real_mx_file(zygo_dir, tmp_path):
    real = _h5_attrs(zygo_dir / "gpi_mp8.3.3_zygo_test.datx")
    write_surface(_surface(), tmp_path / "s.datx")
    ours = _h5_attrs(tmp_path / "s.datx")

    def group(attrs: dict[str, dict]) -> dict:
        # the attribute group of the measurement: Attributes/{GUID}
        (key,) = [k for k in attrs if re.fullmatch(r"Attributes/\{[0-9A-F-]+\}", k)]
        return attrs[key]

    keys = (
        "Data Context.Lateral Resolution",
        "Data Context.Lateral Resolution:Value",
        "Data Context.Lateral Resolution:Unit",
        "Data Context.Data Attributes.Resolution:Value",
        "Data Context.Data Attributes.Resolution:Unit",
    )
    for key in keys:
        assert key in group(real)  # the layout Mx writes ...
        assert key in group(ours), key  # ... is the layout written
        assert group(ours)[key].dtype.kind == group(real)[key].dtype.kind
    assert group(ours)["Data Context.Lateral Resolution:Value"][0] == 0.5e-6
    assert group(ours)["Data Context.Lateral Resolution"]["Value"][0] == 0.5e-6
    assert group(ours)["Data Context.Lateral Resolution:Unit"][0] == "Meters"


def _float_attrs(attrs: dict[str, dict]):
    for obj, values in attrs.items():
        for key, v in values.items():
            a = np.asarray(v)
            if a.dtype.kind == "f":
                yield obj, key, a
            elif a.dtype.names and "Value" in a.dtype.names:
                yield obj, key, a["Value"]


@pytest.mark.parametrize("wavelength", [None, 5.7e-7])
def test_datx_has_no_nan_and_keeps_a_given_wavelength(tmp_path, wavelength):
    md = {} if wavelength is None else {"wavelength": wavelength}
    s = _surface().replace(metadata=md)
    write_surface(s, tmp_path / "s.datx")
    for obj, key, a in _float_attrs(_h5_attrs(tmp_path / "s.datx")):
        assert np.isfinite(a).all(), f"{obj} {key} = {a}"
    attrs = _h5_attrs(tmp_path / "s.datx")
    (ds,) = [v for k, v in attrs.items() if k.startswith("Data/Surface/")]
    assert ds["Wavelength"][0] > 0
    back = read_surface(tmp_path / "s.datx")
    assert back.metadata.get("wavelength") == wavelength  # no invented wavelength


def test_datx_read_by_prysm_without_nan_wavelength(tmp_path):
    read_zygo_datx = pytest.importorskip("prysm.io").read_zygo_datx
    write_surface(_surface().replace(metadata={}), tmp_path / "s.datx")
    meta = read_zygo_datx(str(tmp_path / "s.datx"))["meta"]
    assert np.isfinite(meta["Wavelength"]) and meta["Lateral Resolution"] == 0.5e-6
    assert meta["Software Info Name"] == "servosurf"


# ---------------------------------------------------------- .dat / .xyz labels
def test_dat_is_labelled_servosurf_not_zygo(tmp_path):
    read_zygo_dat = pytest.importorskip("prysm.io").read_zygo_dat
    s = _surface()
    write_surface(s, tmp_path / "s.dat")
    meta = read_zygo_dat(str(tmp_path / "s.dat"))["meta"]
    assert meta["swtype"] == 0  # not MetroPro (1), MetroBASIC (2) or d2bug (3)
    assert meta["swdate"].startswith("servosurf ")
    back = read_surface(tmp_path / "s.dat")
    assert "instrument" not in back.metadata
    assert back.metadata["software"].startswith("servosurf ")


def test_dat_still_read_by_surfacetopography(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # NuMPI / SurfaceTopography import warnings
        st = pytest.importorskip("SurfaceTopography")
        s = _surface()
        write_surface(s, tmp_path / "s.dat")
        t = st.read_topography(str(tmp_path / "s.dat"), format="metropro")
        h = t.heights()
    z = np.where(np.ma.getmaskarray(h), np.nan, np.ma.getdata(h)).T  # ST is (x, y)
    np.testing.assert_array_equal(np.isnan(z), np.isnan(s.z))
    # .dat quantises heights to 0.5 * 632.8 nm / 32768 per count: atol half a count
    np.testing.assert_allclose(z, s.z, rtol=0, atol=0.5 * 632.8e-9 / 32768 / 2 * 1.001)


def test_xyz_is_labelled_servosurf_not_zygo(tmp_path):
    write_surface(_surface(), tmp_path / "s.xyz")
    lines = (tmp_path / "s.xyz").read_text().splitlines()
    assert lines[0] == "Zygo XYZ Data File - Format 1"  # the format's magic stays
    sw_type, *_, sw_name = re.findall(r'"[^"]*"|\S+', lines[1])
    assert sw_type == "0" and sw_name.strip('"').startswith("servosurf ")
    back = read_surface(tmp_path / "s.xyz")
    assert "instrument" not in back.metadata
    assert back.metadata["software"].startswith("servosurf ")


def test_real_zygo_files_are_still_zygo(zygo_dir):
    for name in (
        "newview_20x_mirau_mp8.1_metropro-1.dat",
        "mx_export_hdrfmt1_nolatres_20191018_flat01.dat",
        "newview_100x_05_C1S01_EDITEDHEADER.asc",
    ):
        assert read_surface(zygo_dir / name).metadata["instrument"] == "ZYGO", name


def test_converted_measurement_keeps_its_instrument(zygo_dir, tmp_path):
    src = read_surface(zygo_dir / "newview_20x_mirau_mp8.1_metropro-1.dat")
    write_surface(src, tmp_path / "c.dat")
    back = read_surface(tmp_path / "c.dat")
    assert back.metadata["instrument"] == "ZYGO"  # from the comment JSON
    assert back.metadata["software"].startswith("servosurf ")  # who wrote the file


# ------------------------------------------------------------ reproducibility
@pytest.mark.parametrize("fmt", WRITERS)
def test_same_surface_same_bytes_whatever_the_clock(fmt):
    s = _surface()
    # zipfile stamps members with time.localtime(time.time()): two clocks a year
    # apart must not change the bytes (HDF5's C clock: see the subprocess test)
    with mock.patch("time.time", return_value=1.6e9):
        a = encode_surface(s, fmt)
    with mock.patch("time.time", return_value=1.6e9 + 3.2e7):
        b = encode_surface(s, fmt)
    assert a == b


@pytest.mark.parametrize("fmt", WRITERS)
def test_different_surfaces_different_bytes(fmt):
    assert encode_surface(_surface(seed=0), fmt) != encode_surface(
        _surface(seed=1), fmt
    )


_WRITE_ALL = """
import sys, numpy as np
from servosurf.io import write_surface
from servosurf.metrology import Surface
z = np.random.default_rng(0).normal(0.0, 30e-9, (17, 23)); z[2, 3] = np.nan
s = Surface(z, 0.5e-6, 0.5e-6, metadata={"note": "simulated"})
for fmt, suffix in %r:
    write_surface(s, sys.argv[1] + "/s" + suffix, format=fmt)
"""


def test_identical_runs_write_identical_files(tmp_path):
    """Two separate processes, more than a second apart (HDF5 and zip clocks)."""
    script = _WRITE_ALL % [(f, SUFFIX[f]) for f in WRITERS]
    outs = []
    for run in ("a", "b"):
        d = tmp_path / run
        d.mkdir()
        subprocess.run([sys.executable, "-c", script, str(d)], check=True)
        outs.append(d)
        time.sleep(1.1)  # HDF5 times have 1 s resolution
    for fmt in WRITERS:
        a = (outs[0] / f"s{SUFFIX[fmt]}").read_bytes()
        b = (outs[1] / f"s{SUFFIX[fmt]}").read_bytes()
        assert a == b, fmt
