"""Bad files give one clear error each: the file, what is wrong, what was expected."""

from __future__ import annotations

import io
import struct
import zipfile

import numpy as np
import pytest

from servosurf.errors import (
    CorruptedFileError,
    ServosurfError,
    UnsupportedFileFormatError,
)
from servosurf.io import encode_surface, read_profile, read_surface
from servosurf.metrology import Surface

from ._helpers import NO_DATA, metropro_dat, zygo_ascii, zygo_xyz


def _surface() -> Surface:
    rng = np.random.default_rng(2)  # fixed seed; content is irrelevant
    return Surface(rng.normal(0, 1e-8, (8, 9)), 1e-6, 1e-6, metadata={"k": 1})


def _write(tmp_path, name: str, data: bytes):
    p = tmp_path / name
    p.write_bytes(data)
    return p


def _expect(path, cls, *fragments):
    """Read ``path`` and check the error class and message."""
    with pytest.raises(cls) as info:
        read_surface(path)
    msg = str(info.value)
    assert "\n" not in msg  # one line
    assert str(path) in msg and "expected" in msg
    for f in fragments:
        assert f in msg, msg
    return msg


# ----------------------------------------------------------------- truncation
@pytest.mark.parametrize(
    "fmt,suffix,cut,fragment",
    [
        ("metropro_dat", ".dat", 500, "inside the MetroPro header"),
        ("metropro_dat", ".dat", 900, "file is truncated"),
        ("datx", ".datx", 4000, "file is truncated"),
        ("x3p", ".x3p", 300, "not a readable zip archive"),
        ("npz", ".npz", 300, "not a readable zip archive"),
        ("zygo_xyz", ".xyz", -40, "closing '#'"),
    ],
)
def test_truncated(tmp_path, fmt, suffix, cut, fragment):
    data = encode_surface(_surface(), fmt)
    _expect(_write(tmp_path, "t" + suffix, data[:cut]), CorruptedFileError, fragment)


def test_truncated_real_dat(zygo_dir, tmp_path):
    data = (zygo_dir / "newview_20x_mirau_mp8.1_metropro-1.dat").read_bytes()
    msg = _expect(
        _write(tmp_path, "t.dat", data[:-1000]),
        CorruptedFileError,
        "header (834) + intensity (614400) + phase (1228800) need 1844034",
    )
    assert "expected at least 1844034 bytes" in msg


def test_truncated_ascii(tmp_path):
    data = zygo_ascii(np.arange(12).reshape(3, 4))
    cut = data[: data.rindex(b"#") - 4] + b"\n#\n"
    _expect(
        _write(tmp_path, "t.asc", cut),
        CorruptedFileError,
        "phase block has 11 values",
        "12 (from the header)",
    )


# -------------------------------------------------------------- wrong magic
def test_wrong_magic(tmp_path):
    data = bytearray(metropro_dat(np.zeros((2, 2), dtype=np.int64)))
    data[0:4] = b"\x88\x1b\x03\x99"
    _expect(
        _write(tmp_path, "m.dat", bytes(data)),
        CorruptedFileError,
        "magic number is 0x881B0399",
        "0x881B036F",
    )


def test_wrong_magic_without_suffix_is_unsupported():
    with pytest.raises(UnsupportedFileFormatError, match="unknown file format"):
        read_surface(io.BytesIO(b"\x00" * 2000))


def test_ascii_title_required(tmp_path):
    data = zygo_ascii(np.zeros((2, 2), dtype=np.int64), title="Some ASCII Data File")
    _expect(_write(tmp_path, "a.asc", data), CorruptedFileError, "Zygo ASCII Data File")


# ------------------------------------------------------- inconsistent headers
def _patch(data: bytes, offset: int, fmt: str, value) -> bytes:
    b = bytearray(data)
    struct.pack_into(fmt, b, offset, value)
    return bytes(b)


@pytest.mark.parametrize(
    "offset,fmt,value,fragment",
    [
        (6, ">I", 4096, "header_size is 4096 bytes for header format 1"),
        (4, ">H", 3, "header_format is 3 but the magic number is that of format 1"),
        (72, ">I", 99, "cn_n_bytes is 99 for a 2x3 phase window"),
        (60, ">I", 8, "ac_n_bytes is 8 for 0 intensity frame(s)"),
        (70, ">H", 0, "phase window is 2x0 pixels"),
        (218, ">h", 7, "phase_res is 7"),
        (168, ">f", 0.0, "wavelength_in is 0.0"),
        (184, ">f", -1e-6, "pixel size lateral_res is"),
        (184, ">f", float("nan"), "pixel size lateral_res is nan"),
    ],
)
def test_inconsistent_dat_header(tmp_path, offset, fmt, value, fragment):
    data = _patch(metropro_dat(np.zeros((3, 2), dtype=np.int64)), offset, fmt, value)
    _expect(_write(tmp_path, "h.dat", data), CorruptedFileError, fragment)


def test_ascii_bad_number(tmp_path):
    data = zygo_ascii(np.zeros((2, 2), dtype=np.int64)).replace(
        b"0 0.5 ", b"0 0.5x ", 1
    )
    _expect(
        _write(tmp_path, "n.asc", data),
        CorruptedFileError,
        "header line 8 field intf_scale_factor is '0.5x'",
    )


# ------------------------------------------------------------ NaN-only maps
@pytest.mark.parametrize(
    "fmt,suffix", [("x3p", ".x3p"), ("npz", ".npz"), ("datx", ".datx")]
)
def test_nan_only_written(tmp_path, fmt, suffix):
    s = Surface(np.full((3, 4), np.nan), 1e-6, 1e-6)
    _expect(
        _write(tmp_path, "n" + suffix, encode_surface(s, fmt)),
        CorruptedFileError,
        "all 12 pixels of the 3x4 map are invalid",
        "at least one valid height",
    )


def test_nan_only_dat(tmp_path):
    data = metropro_dat(np.full((3, 4), NO_DATA, dtype=np.int64))
    _expect(_write(tmp_path, "n.dat", data), CorruptedFileError, "all 12 pixels")


def test_nan_only_xyz(tmp_path):
    data = zygo_xyz(np.full((2, 2), np.nan))
    _expect(_write(tmp_path, "n.xyz", data), CorruptedFileError, "all 4 pixels")


# ------------------------------------------------------ bad pixel sizes
def _x3p_with(xml_edit, tmp_path, name="p.x3p"):
    data = encode_surface(_surface(), "x3p")
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as src, zipfile.ZipFile(out, "w") as dst:
        for item in src.namelist():
            content = src.read(item)
            if item == "main.xml":
                content = xml_edit(content.decode()).encode()
            dst.writestr(item, content)
    return _write(tmp_path, name, out.getvalue())


@pytest.mark.parametrize("value", ["0.0", "-1e-06"])
def test_x3p_bad_increment(tmp_path, value):
    path = _x3p_with(
        lambda x: x.replace(
            "<Increment>1e-06</Increment>", f"<Increment>{value}</Increment>", 1
        ),
        tmp_path,
    )
    _expect(
        path, CorruptedFileError, "pixel size CX/Increment is", "a positive pixel size"
    )


def test_npz_zero_pixel(tmp_path):
    buf = io.BytesIO()
    np.savez(buf, z=np.zeros((2, 2)), dx=np.float64(0.0), dy=np.float64(1e-6))
    _expect(
        _write(tmp_path, "z.npz", buf.getvalue()),
        CorruptedFileError,
        "pixel size dx is 0.0",
    )


def test_datx_negative_pixel(tmp_path):
    import h5py

    path = tmp_path / "neg.datx"
    path.write_bytes(encode_surface(_surface(), "datx"))
    with h5py.File(path, "r+") as f:
        ds = f["Data/Surface"][next(iter(f["Data/Surface"]))]
        conv = ds.attrs["X Converter"]
        conv[0]["Parameters"][1] = -1e-6
        ds.attrs["X Converter"] = conv
    _expect(path, CorruptedFileError, "pixel size X Converter is -1e-06")


# ------------------------------------------------------- containers
def test_hdf5_without_surface(tmp_path):
    import h5py

    path = tmp_path / "empty.datx"
    with h5py.File(path, "w") as f:
        f.create_group("Data/Other")
        f["Data/Other/x"] = np.zeros(3)
    _expect(
        path, CorruptedFileError, "HDF5 file has no surface dataset", "/MetaData link"
    )


def test_datx_surface_of_wrong_shape(tmp_path):
    import h5py

    path = tmp_path / "one_d.datx"
    with h5py.File(path, "w") as f:
        f["Measurement/Surface"] = np.zeros(10)
    _expect(
        path, CorruptedFileError, "has shape (10,)", "a non-empty 2-D numeric array"
    )


def test_x3p_without_main_xml(tmp_path):
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr("bindata/data.bin", b"\0" * 8)
    _expect(
        _write(tmp_path, "nomain.x3p", out.getvalue()),
        CorruptedFileError,
        "archive has no main.xml",
    )


def test_x3p_member_size_mismatch(tmp_path):
    path = _x3p_with(
        lambda x: x.replace("<SizeX>9</SizeX>", "<SizeX>90000</SizeX>"), tmp_path
    )
    _expect(
        path, CorruptedFileError, "'bindata/data.bin' has 576 bytes", "5760000 bytes"
    )


def test_x3p_dtd_rejected(tmp_path):
    path = _x3p_with(
        lambda x: x.replace(
            "<p:ISO5436_2", "<!DOCTYPE x [<!ENTITY a 'b'>]><p:ISO5436_2", 1
        ),
        tmp_path,
    )
    _expect(path, UnsupportedFileFormatError, "DTD or entities")


def test_npz_without_z(tmp_path):
    buf = io.BytesIO()
    np.savez(buf, dx=np.float64(1.0))
    _expect(
        _write(tmp_path, "noz.npz", buf.getvalue()),
        CorruptedFileError,
        "archive has no z.npy",
    )


def test_npz_object_arrays_refused(tmp_path):
    buf = io.BytesIO()
    np.savez(
        buf,
        z=np.array([[{"a": 1}]], dtype=object),
        dx=np.float64(1.0),
        dy=np.float64(1.0),
    )
    _expect(
        _write(tmp_path, "obj.npz", buf.getvalue()),
        CorruptedFileError,
        "object arrays are not accepted",
    )


def test_csv_bad_rows(tmp_path):
    path = _write(tmp_path, "p.csv", b"X ,Y ,Slice\n1.0,0.1,Slice 1\n2.0,abc,Slice 1\n")
    with pytest.raises(
        CorruptedFileError, match=r"line 3 Y is 'abc'.*expected a number"
    ):
        read_profile(path)
    path = _write(tmp_path, "q.csv", b"X ,Y ,Slice\n1.0,0.1,Slice 1\n1.0,0.2,Slice 1\n")
    with pytest.raises(CorruptedFileError, match="increasing X positions"):
        read_profile(path)


def test_errors_are_servosurf_errors():
    assert issubclass(CorruptedFileError, ServosurfError)
    assert issubclass(UnsupportedFileFormatError, ServosurfError)
