"""Synthetic files exercising every branch of the ZYGO readers: phase_res 0/1/2, the
sign field, header format 3, a phase window smaller than the camera, files with and
without intensity, ASCII and XYZ variants."""

from __future__ import annotations

import io
import warnings

import numpy as np
import pytest

from servosurf.io import encode_surface, read_surface
from servosurf.metrology import Surface

from ._helpers import NO_DATA, expected_heights, metropro_dat, zygo_ascii, zygo_xyz

#: Our heights use the float32 header values exactly like the reference formula;
#: only the order of the float64 multiplications may differ.
FORMULA_RTOL = 1e-15


def _raw(shape=(5, 7), seed=3):
    rng = np.random.default_rng(seed)  # fixed seed; any phase integers will do
    raw = rng.integers(-200_000, 200_000, size=shape).astype(np.int64)
    raw[1, 2] = NO_DATA
    raw[-1, -1] = NO_DATA + 5  # anything >= 2147483640 is no data
    return raw


def _st_dat(data: bytes, tmp_path):
    """Heights from SurfaceTopography's MetroPro reader (rows, cols) in m."""
    path = tmp_path / "st.dat"
    path.write_bytes(data)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # NuMPI ImportWarning, ST deprecations
        import SurfaceTopography as st

        h = st.read_topography(str(path), format="metropro").heights()
    return np.where(np.ma.getmaskarray(h), np.nan, np.ma.getdata(h)).T


@pytest.mark.parametrize("header_format", [1, 2, 3])
@pytest.mark.parametrize("phase_res", [0, 1, 2])
@pytest.mark.parametrize("sign", [0, 1])
def test_dat_heights(header_format, phase_res, sign, tmp_path):
    raw = _raw()
    data = metropro_dat(
        raw,
        header_format=header_format,
        phase_res=phase_res,
        sign=sign,
        wavelength=570e-9,
    )
    s = read_surface(io.BytesIO(data))
    want = expected_heights(raw, phase_res=phase_res, sign=sign, wavelength=570e-9)
    np.testing.assert_allclose(s.z, want, rtol=FORMULA_RTOL)
    assert s.metadata["metropro"]["header_format"] == header_format
    assert s.metadata["metropro"]["phase_res"] == phase_res
    if phase_res == 2 and header_format == 1:
        # Independent check of the synthetic layout on one representative case.
        np.testing.assert_allclose(_st_dat(data, tmp_path), want, rtol=1e-12)


def test_phase_res_scales_by_the_documented_factors():
    raw = np.full((2, 2), 131072)
    z = [
        read_surface(io.BytesIO(metropro_dat(raw, phase_res=pr))).z[0, 0]
        for pr in (0, 1, 2)
    ]
    lam = float(np.float32(632.8e-9)) * 0.5
    np.testing.assert_allclose(z, [lam * 32, lam * 4, lam], rtol=FORMULA_RTOL)


def test_window_smaller_than_camera_and_intensity(tmp_path):
    raw = _raw((6, 4))
    inten = np.arange(2 * 10 * 12).reshape(2, 10, 12)  # 2 buckets, 12x10 camera
    data = metropro_dat(
        raw, origin=(5, 3), camera=(12, 10), intensity=inten, lateral_res=2e-6
    )
    s = read_surface(io.BytesIO(data))
    assert s.shape == (6, 4)
    np.testing.assert_allclose([s.x0, s.y0], [5 * 2e-6, 3 * 2e-6], rtol=1e-7)
    md = s.metadata["metropro"]
    assert md["phase_origin"] == [5, 3] and md["camera_size"] == [12, 10]
    assert md["intensity"] == {
        "buckets": 2,
        "size": [12, 10],
        "origin": [0, 0],
        "range": 255,
    }
    np.testing.assert_allclose(s.z, expected_heights(raw), rtol=FORMULA_RTOL)
    np.testing.assert_allclose(_st_dat(data, tmp_path), s.z, rtol=1e-12)


def test_without_intensity_and_uncalibrated():
    raw = _raw()
    s = read_surface(io.BytesIO(metropro_dat(raw, lateral_res=0.0)))
    assert s.dx is None and s.dy is None and (s.x0, s.y0) == (0.0, 0.0)
    assert s.metadata["metropro"]["intensity"] is None
    assert s.metadata["date"] == "2020-09-13T12:26:40Z"  # time_stamp 1.6e9 s
    assert (
        s.metadata["objective"] == "50X Mirau" and s.metadata["comment"] == "synthetic"
    )


@pytest.mark.parametrize("header_format", [1, 2, 3])
@pytest.mark.parametrize("phase_res", [0, 1, 2])
def test_dat_writer_options(header_format, phase_res):
    rng = np.random.default_rng(5)  # fixed seed; any heights within range
    s = Surface(rng.normal(0, 1e-7, (4, 6)), 1e-6, 1e-6)
    for sign in (False, True):
        data = encode_surface(
            s,
            "metropro_dat",
            header_format=header_format,
            phase_res=phase_res,
            sign=sign,
        )
        assert len(data) == (4096 if header_format == 3 else 834) + 4 * 24
        back = read_surface(io.BytesIO(data))
        q = (
            0.5
            * float(np.float32(632.8e-9))
            / {0: 4096, 1: 32768, 2: 131072}[phase_res]
        )
        np.testing.assert_allclose(back.z, s.z, atol=q / 2 * 1.0001)
        assert back.metadata["metropro"]["sign"] == int(sign)


def test_dat_writer_window_and_intensity():
    s = Surface(np.zeros((3, 4)), 1e-6, 1e-6)
    data = encode_surface(
        s,
        "metropro_dat",
        phase_origin=(2, 1),
        camera_size=(10, 8),
        intensity=np.ones((8, 10)),
    )
    back = read_surface(io.BytesIO(data))
    md = back.metadata["metropro"]
    assert md["phase_origin"] == [2, 1] and md["camera_size"] == [10, 8]
    assert md["intensity"]["size"] == [10, 8]


@pytest.mark.parametrize("intensity", [True, False])
@pytest.mark.parametrize("sign", [0, 1])
def test_ascii(intensity, sign):
    raw = _raw((3, 5))
    data = zygo_ascii(raw, intensity=intensity, sign=sign, phase_res=0, origin=(2, 7))
    s = read_surface(io.BytesIO(data))
    np.testing.assert_allclose(
        s.z, expected_heights(raw, phase_res=0, sign=sign), rtol=1e-7
    )  # text wavelength vs float32 in the formula
    np.testing.assert_allclose([s.dx, s.x0, s.y0], [1e-6, 2e-6, 7e-6])
    assert s.metadata["objective"] == "50X Mirau"
    assert s.metadata["software"] == "MetroPro 9.1.0"


def test_xyz_with_no_data_and_window():
    z = np.arange(12, dtype=float).reshape(3, 4) * 0.01
    z[1, 1] = np.nan
    s = read_surface(io.BytesIO(zygo_xyz(z, origin=(10, 20), lateral_res=0.5e-6)))
    np.testing.assert_allclose(s.z, z * 1e-6)
    assert np.isnan(s.z[1, 1])
    np.testing.assert_allclose([s.x0, s.y0], [5e-6, 10e-6])


def test_xyz_missing_points_are_invalid():
    z = np.ones((3, 3))
    text = zygo_xyz(z).decode().splitlines()
    del text[text.index("#") + 1 + 4]  # drop pixel (row 1, col 1), the 5th line
    s = read_surface(io.BytesIO(("\n".join(text) + "\n").encode()))
    assert np.isnan(s.z[1, 1]) and np.isfinite(s.z).sum() == 8
