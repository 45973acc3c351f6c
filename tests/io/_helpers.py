"""Builders of small synthetic interferometer files, independent of servosurf's writers.

The MetroPro header is laid out here from the field table of the MetroPro Reference
Guide (offsets written out again, not imported from ``servosurf.io``), so a wrong
offset in the reader cannot hide behind the same mistake in the writer.
"""

from __future__ import annotations

import struct

import numpy as np

MAGIC = {1: 0x881B036F, 2: 0x881B0370, 3: 0x881B0371}
R = {0: 4096, 1: 32768, 2: 131072}
NO_DATA = 2147483640


def metropro_dat(
    raw: np.ndarray,
    *,
    header_format: int = 1,
    phase_res: int = 1,
    sign: int = 0,
    wavelength: float = 632.8e-9,
    intf_scale_factor: float = 0.5,
    obliquity_factor: float = 1.0,
    lateral_res: float = 1e-6,
    origin: tuple[int, int] = (0, 0),
    camera: tuple[int, int] | None = None,
    intensity: np.ndarray | None = None,
    time_stamp: int = 1_600_000_000,
    comment: bytes = b"synthetic",
    objective: bytes = b"50X Mirau",
) -> bytes:
    """A MetroPro .dat file holding the int32 phase array ``raw`` (rows from top)."""
    ny, nx = raw.shape
    hsize = 4096 if header_format == 3 else 834
    h = bytearray(hsize)
    if intensity is None:
        nb = aw = ah = 0
        inten = b""
    else:
        inten_arr = intensity if intensity.ndim == 3 else intensity[None]
        nb, ah, aw = inten_arr.shape
        inten = inten_arr.astype(">u2").tobytes()
    cam = camera or (origin[0] + nx, origin[1] + ny)
    fields = [
        (0, ">I", MAGIC[header_format]),
        (4, ">H", header_format),
        (6, ">I", hsize),
        (10, ">h", 1),  # MetroPro
        (42, ">h", 9),
        (44, ">h", 1),
        (46, ">h", 0),
        (52, ">H", aw),
        (54, ">H", ah),
        (56, ">H", nb),
        (58, ">h", 255),
        (60, ">I", len(inten)),
        (64, ">h", origin[0]),
        (66, ">h", origin[1]),
        (68, ">H", nx),
        (70, ">H", ny),
        (72, ">I", 4 * nx * ny),
        (76, ">i", time_stamp),
        (164, ">f", intf_scale_factor),
        (168, ">f", wavelength),
        (176, ">f", obliquity_factor),
        (184, ">f", lateral_res),
        (218, ">h", phase_res),
        (232, ">h", sign),
        (234, ">h", cam[0]),
        (236, ">h", cam[1]),
        (360, ">f", 1.0),
    ]
    for off, fmt, v in fields:
        struct.pack_into(fmt, h, off, v)
    h[80 : 80 + len(comment)] = comment
    h[246 : 246 + len(objective)] = objective
    return bytes(h) + inten + np.asarray(raw, dtype=">i4").tobytes()


def expected_heights(
    raw: np.ndarray,
    *,
    phase_res: int = 1,
    sign: int = 0,
    wavelength: float = 632.8e-9,
    intf_scale_factor: float = 0.5,
    obliquity_factor: float = 1.0,
) -> np.ndarray:
    """Heights in m that a reader must return for ``raw`` (float32 header values)."""
    f32 = lambda v: float(np.float32(v))  # noqa: E731 - header fields are float32
    scale = (
        f32(intf_scale_factor) * f32(obliquity_factor) * f32(wavelength) / R[phase_res]
    )
    z = raw.astype(np.float64) * (-scale if sign else scale)
    z[raw >= NO_DATA] = np.nan
    return z


def zygo_ascii(
    raw: np.ndarray,
    *,
    lateral_res: float = 1e-6,
    wavelength: float = 632.8e-9,
    phase_res: int = 1,
    sign: int = 0,
    origin: tuple[int, int] = (0, 0),
    intensity: bool = True,
    title: str = "Zygo ASCII Data File - Format 2",
) -> bytes:
    """A MetroPro ASCII file with phase integers ``raw``."""
    ny, nx = raw.shape
    nb = 1 if intensity else 0
    lines = [
        title,
        '1 9 1 0 "Mon Jan 01 00:00:00 2024"',
        f"0 0 {nx if intensity else 0} {ny if intensity else 0} {nb} 255",
        f"{origin[0]} {origin[1]} {nx} {ny}",
        '"a comment"',
        '""',
        '""',
        f"0 0.5 {wavelength!r} 0 1 0 {lateral_res!r} 1600000000",
        f'{origin[0] + nx} {origin[1] + ny} 28 0 1234 0 "50X Mirau"',
        "2 0 0 0 0 0 0 3.25 1 0",
        f"{phase_res} 16 7 1 60 0 0 {sign} 0",
        '0 ""',
        "1 0",
        '"   1X  "',
        "#",
    ]
    inten = " ".join(str(i % 200) for i in range(nx * ny * nb))
    phase = "\n".join(" ".join(str(int(v)) for v in row) for row in raw)
    return ("\n".join(lines) + "\n" + inten + "\n#\n" + phase + "\n#\n").encode()


def zygo_xyz(z_um: np.ndarray, *, lateral_res: float = 1e-6, origin=(0, 0)) -> bytes:
    """A ZYGO XYZ file; NaN heights are written as ``No Data``."""
    ny, nx = z_um.shape
    lines = [
        "Zygo XYZ Data File - Format 1",
        '1 9 1 0 "Mon Jan 01 00:00:00 2024"',
        "0 0 0 0 0 0",
        f"{origin[0]} {origin[1]} {nx} {ny}",
        '""',
        '""',
        '""',
        f"0 0.5 6.328e-07 0 1 0 {lateral_res!r} 1600000000",
        f'{origin[0] + nx} {origin[1] + ny} 0 0 0 0 "20X"',
        "0 0 0 0 0 0 0 0 0 0",
        "1 0 0 0 0 0 0 0 0",
        '0 ""',
        "1 0",
        '""',
        "#",
    ]
    for i in range(ny):
        for j in range(nx):
            v = z_um[i, j]
            lines.append(
                f"{origin[0] + j} {origin[1] + i} "
                + ("No Data" if np.isnan(v) else repr(float(v)))
            )
    lines.append("#")
    return ("\n".join(lines) + "\n").encode()
