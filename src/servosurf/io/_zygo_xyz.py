"""ZYGO XYZ data files (``.xyz``, "Zygo XYZ Data File - Format 1").

The header is the MetroPro text header (see ``_zygo_ascii``), followed by a ``#``
line and one line per pixel, ``x y z``: camera column and row (integers) and the
height in micrometres, or ``x y No Data`` for an invalid pixel. A final ``#`` line
closes the data. The pixel size is the header's CameraRes (m per pixel).
"""

from __future__ import annotations

import numpy as np

from ..metrology import Surface
from ._common import (
    Source,
    check_pixel_size,
    corrupt,
    decode_text,
    make_surface,
    pixel_origin,
    software_label,
    software_version_numbers,
    timestamp_from_iso,
    writer_error,
)
from ._registry import register_reader, register_writer
from ._zygo_ascii import header_metadata, parse_ascii_header, split_ascii

__all__ = ["read_zygo_xyz", "encode_zygo_xyz"]

XYZ_MAGIC = b"Zygo XYZ Data File"
_NATIVE_KEYS = (
    "wavelength",
    "objective",
    "date",
    "source_format",
    "metropro",
    "instrument",
    "software",
    "comment",
    "zoom",
)


@register_reader(
    "zygo_xyz",
    description="ZYGO XYZ data (.xyz): pixel column, row and height in um",
    suffixes=(".xyz",),
    magic=(XYZ_MAGIC,),
)
def read_zygo_xyz(source: Source) -> Surface:
    """Read a ZYGO XYZ file.

    Parameters
    ----------
    source : Source
        Loaded file.

    Returns
    -------
    Surface
        Heights in m (NaN for "No Data" and for pixels not listed), pixel size from
        CameraRes in m (None when 0), shape from the header's phase window.
    """
    name = source.name
    if not source.data.startswith(XYZ_MAGIC):
        raise corrupt(
            name, f"file starts with {source.data[:24]!r}", f"{XYZ_MAGIC.decode()!r}"
        )
    header, blocks = split_ascii(decode_text(source.data))
    h = parse_ascii_header(header, name, required_lines=7)
    if not blocks:
        raise corrupt(name, "no '#' line ends the header", "a '#' line before the data")
    if len(blocks) < 2:
        raise corrupt(
            name,
            "file ends without the closing '#' line (truncated)",
            "a '#' line after the last data line",
        )
    text = blocks[0].replace("No Data", "nan").replace("no data", "nan")
    tokens = text.split()
    if len(tokens) % 3:
        raise corrupt(name, f"data block has {len(tokens)} values", "x y z triplets")
    try:
        xyz = np.array(tokens, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        bad = next((t for t in tokens if not _is_number(t)), tokens[0])
        raise corrupt(
            name, f"data block holds {bad[:30]!r}", "numbers or 'No Data'"
        ) from None
    if xyz.shape[0] == 0:
        raise corrupt(name, "data block is empty", "one line per pixel")
    x, y = xyz[:, 0], xyz[:, 1]
    if not (np.isfinite(x).all() and np.isfinite(y).all()) or (
        np.any(x != np.round(x)) or np.any(y != np.round(y))
    ):
        raise corrupt(name, "pixel coordinates are not all integers", "integer x and y")
    xi, yi = x.astype(np.int64), y.astype(np.int64)
    ox, oy = h.get("cn_org_x", 0), h.get("cn_org_y", 0)
    nx, ny = h.get("cn_width", 0), h.get("cn_height", 0)
    if nx == 0 or ny == 0:  # no window in the header: take the bounding box
        ox, oy = int(xi.min()), int(yi.min())
        nx, ny = int(xi.max()) - ox + 1, int(yi.max()) - oy + 1
    if nx * ny > 64 * xyz.shape[0] + 4096:
        raise corrupt(
            name,
            f"phase window {nx}x{ny} is far larger than the {xyz.shape[0]} "
            "points listed",
            "about one line per pixel",
        )
    col, row = xi - ox, yi - oy
    if col.min() < 0 or row.min() < 0 or col.max() >= nx or row.max() >= ny:
        col, row = xi, yi  # some exporters write window-relative coordinates
        if col.min() < 0 or row.min() < 0 or col.max() >= nx or row.max() >= ny:
            raise corrupt(
                name,
                f"pixel coordinates x {xi.min()}..{xi.max()}, "
                f"y {yi.min()}..{yi.max()} fall outside the {nx}x{ny} phase "
                f"window at ({ox}, {oy})",
                "coordinates inside the window",
            )
    z = np.full((ny, nx), np.nan)
    z[row, col] = xyz[:, 2] / 1e6
    dx = check_pixel_size(
        h.get("lateral_res", 0.0), name, "CameraRes", zero_means_uncalibrated=True
    )
    md = header_metadata(h)
    md["source_format"] = "zygo_xyz"
    x0 = ox * dx if dx else 0.0
    y0 = oy * dx if dx else 0.0
    return make_surface(z, dx, dx, md, name, x0=x0, y0=y0)


def _is_number(t: str) -> bool:
    try:
        float(t)
    except ValueError:
        return False
    return True


def _q(text: str, size: int) -> str:
    """Quote a header string (no quotes or newlines inside, at most ``size`` chars)."""
    clean = "".join(c if c.isprintable() and c != '"' else "'" for c in text)
    return '"' + clean[:size] + '"'


@register_writer(
    "zygo_xyz",
    description="ZYGO XYZ data (.xyz): pixel column, row and height in um",
    suffixes=(".xyz",),
)
def encode_zygo_xyz(surface: Surface) -> bytes:
    """Encode a surface as a ZYGO XYZ file.

    Heights are written in micrometres with 17 significant digits (float64
    round trip); invalid pixels as ``No Data``. The header's software fields say
    servosurf (type 0, ``"servosurf <version>"``), not MetroPro; the same surface
    gives the same bytes.

    Parameters
    ----------
    surface : Surface
        Heights in m; ``dx`` must equal ``dy`` (one CameraRes field).

    Returns
    -------
    bytes
        The file content (ASCII).

    Raises
    ------
    FileFormatError
        Non-square pixels.
    """
    md = surface.metadata
    ny, nx = surface.shape
    ox, oy = pixel_origin(surface)
    if surface.calibrated:
        assert surface.dx is not None and surface.dy is not None
        if abs(surface.dx - surface.dy) > 1e-9 * max(surface.dx, surface.dy):
            raise writer_error(
                "zygo_xyz",
                f"pixels are not square (dx={surface.dx!r} m, dy={surface.dy!r} m)",
                "the XYZ header stores one CameraRes; use .x3p or .datx",
            )
        res = surface.dx
    else:
        res = 0.0
    wl = md.get("wavelength")
    wl = float(wl) if isinstance(wl, int | float) and wl > 0 else 632.8e-9
    ts = timestamp_from_iso(md.get("date")) or 0
    comment = md.get("comment") if isinstance(md.get("comment"), str) else ""
    obj = md.get("objective") if isinstance(md.get("objective"), str) else ""
    zoom = md.get("zoom") if isinstance(md.get("zoom"), str) else ""
    # The header has no room for free-form metadata: only the comment string,
    # objective, zoom, wavelength, pixel size and date are kept. Software type 0
    # (not MetroPro) and the software string "servosurf <version>": the file is
    # not labelled as a ZYGO instrument's.
    maj, mnr, bug = software_version_numbers()
    lines = [
        "Zygo XYZ Data File - Format 1",
        f"0 {maj} {mnr} {bug} {_q(software_label(), 29)}",
        "0 0 0 0 0 0",
        f"{ox} {oy} {nx} {ny}",
        _q(comment, 81),
        _q("", 39),
        _q("", 39),
        f"0 0.5 {wl!r} 0 1 0 {res!r} {ts}",
        f"{ox + nx} {oy + ny} 0 0 0 0 {_q(obj, 11)}",
        "0 0 0 0 0 0 0 0 0 0",
        "1 0 0 0 0 0 0 0 0",
        '0 ""',
        "1 0",
        _q(zoom, 7),
        "#",
    ]
    cols = np.tile(np.arange(nx) + ox, ny)
    rows = np.repeat(np.arange(ny) + oy, nx)
    vals = (surface.z * 1e6).ravel()
    body = [
        f"{c} {r} {v!r}" if v == v else f"{c} {r} No Data"
        for c, r, v in zip(cols.tolist(), rows.tolist(), vals.tolist(), strict=True)
    ]
    return ("\n".join(lines + body + ["#"]) + "\n").encode("ascii")
