"""Helpers shared by the format modules: sources, errors, metadata and size guards.

Every reader works on the complete file content held in memory (``bytes``), so
sizes read from a header can always be checked against the real length before
anything is allocated.
"""

from __future__ import annotations

import datetime as _dt
import json
import lzma
import math
import os
import struct
import zipfile
import zlib
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..errors import CorruptedFileError, FileFormatError, UnsupportedFileFormatError
from ..metrology import Profile, Surface

__all__ = [
    "Source",
    "load_source",
    "corrupt",
    "check_pixel_size",
    "make_surface",
    "jsonable",
    "metadata_json",
    "parse_metadata_json",
    "iso_date",
    "timestamp_from_iso",
    "zip_member",
    "open_zip",
    "zip_archive",
    "as_surface",
    "decode_text",
    "writer_error",
    "unsupported",
    "pixel_origin",
    "SOFTWARE_NAME",
    "software_label",
    "software_version_numbers",
    "written_by_servosurf",
]

#: Name written in the software fields of every file servosurf writes, so that a
#: simulated map is never taken for an instrument's measurement.
SOFTWARE_NAME = "servosurf"

#: Earliest plausible acquisition time (1980-01-01 UTC) in seconds since the epoch.
#: Older time stamps are unset or garbage (Mx writes MATLAB day numbers there).
_EARLIEST_TIMESTAMP = 315532800

#: Largest uncompressed zip member accepted, in bytes (2 GiB).
MAX_MEMBER_BYTES = 2**31

#: Deflate cannot compress by more than about 1032:1.
_MAX_DEFLATE_RATIO = 1100

#: What :mod:`zipfile` raises on damaged archives (encrypted members raise
#: RuntimeError, unknown compression NotImplementedError).
_ZIP_ERRORS = (
    zipfile.BadZipFile,
    zipfile.LargeZipFile,
    OSError,
    EOFError,
    ValueError,
    NotImplementedError,
    RuntimeError,
    IndexError,
    OverflowError,
    UnicodeDecodeError,
    zlib.error,
    struct.error,
    lzma.LZMAError,
)


@dataclass(frozen=True)
class Source:
    """The complete content of a file and a name to use in messages.

    Parameters
    ----------
    data : bytes
        File content.
    name : str
        Path or ``"<buffer>"``; used in error messages only.
    suffix : str
        Lower-case suffix with the dot (``".dat"``), or ``""`` when unknown.
    """

    data: bytes
    name: str
    suffix: str


def load_source(source: str | os.PathLike | IO[bytes] | bytes) -> Source:
    """Read a path, a binary buffer or bytes into a :class:`Source`.

    Parameters
    ----------
    source : str, path-like, binary file-like or bytes
        Where the file comes from. Buffers are read from their current position.

    Returns
    -------
    Source
        The content, a display name and the suffix.

    Raises
    ------
    FileNotFoundError, IsADirectoryError, PermissionError
        When a path cannot be opened.
    TypeError
        When ``source`` is neither a path, a binary buffer nor bytes.
    """
    if isinstance(source, str | os.PathLike):
        path = Path(source)
        return Source(path.read_bytes(), str(path), path.suffix.lower())
    if isinstance(source, bytes | bytearray | memoryview):
        return Source(bytes(source), "<buffer>", "")
    read = getattr(source, "read", None)
    if read is None:
        raise TypeError(
            "source must be a path, a binary file-like object or bytes, "
            f"got {type(source).__name__}"
        )
    data = read()
    if isinstance(data, str):
        raise TypeError("source buffer must be opened in binary mode (got text)")
    name = getattr(source, "name", None)
    if isinstance(name, str | os.PathLike):
        return Source(bytes(data), str(name), Path(name).suffix.lower())
    return Source(bytes(data), "<buffer>", "")


def corrupt(name: str, what: str, expected: str) -> CorruptedFileError:
    """Build the one-line error for an inconsistent file.

    Parameters
    ----------
    name : str
        File name (or ``"<buffer>"``).
    what : str
        What is wrong, with the actual value.
    expected : str
        What a valid file has.

    Returns
    -------
    CorruptedFileError
        Ready to raise.
    """
    return CorruptedFileError(f"{name}: {what}; expected {expected}")


def check_pixel_size(
    value: float | None, name: str, what: str, *, zero_means_uncalibrated: bool
) -> float | None:
    """Validate a pixel size read from a file.

    Parameters
    ----------
    value : float or None
        Pixel size in m as read (None when the file has none).
    name : str
        File name for messages.
    what : str
        Field name for messages (``"lateral_res"``).
    zero_means_uncalibrated : bool
        When True a value of exactly 0 returns None (uncalibrated); otherwise 0 is
        an error.

    Returns
    -------
    float or None
        The pixel size in m, or None when uncalibrated.

    Raises
    ------
    CorruptedFileError
        For negative, non-finite or (unless allowed) zero values.
    """
    if value is None:
        return None
    v = float(value)
    if v == 0.0 and zero_means_uncalibrated:
        return None
    if not math.isfinite(v) or v <= 0.0:
        expected = "a positive pixel size in m"
        if zero_means_uncalibrated:
            expected += " (or 0 for uncalibrated)"
        raise corrupt(name, f"pixel size {what} is {v!r}", expected)
    return v


def make_surface(
    z: np.ndarray,
    dx: float | None,
    dy: float | None,
    metadata: dict[str, Any],
    name: str,
    *,
    x0: float = 0.0,
    y0: float = 0.0,
) -> Surface:
    """Build a :class:`Surface`, rejecting maps without a single valid pixel.

    Parameters
    ----------
    z : ndarray of shape (ny, nx)
        Heights in m with NaN for invalid pixels.
    dx, dy : float or None
        Pixel sizes in m (None when uncalibrated).
    metadata : dict
        JSON-serialisable metadata.
    name : str
        File name for messages.
    x0, y0 : float, default: 0.0
        Position of pixel (0, 0) in m.

    Returns
    -------
    Surface
        The surface.

    Raises
    ------
    CorruptedFileError
        When no pixel is valid or the heights are not finite where valid.
    """
    z = np.asarray(z, dtype=np.float64)
    z[np.isinf(z)] = np.nan
    if z.ndim != 2 or z.size == 0:
        raise corrupt(name, f"height map has shape {z.shape}", "a non-empty 2-D map")
    if not np.isfinite(z).any():
        raise corrupt(
            name,
            f"all {z.size} pixels of the {z.shape[0]}x{z.shape[1]} map are invalid",
            "at least one valid height",
        )
    x0 = float(x0) if math.isfinite(x0) else 0.0
    y0 = float(y0) if math.isfinite(y0) else 0.0
    return Surface(z, dx, dy, metadata=jsonable(metadata), x0=x0, y0=y0)


# ---------------------------------------------------------------- metadata
def software_label() -> str:
    """``"servosurf <version>"``: the software string servosurf writes."""
    from .._version import __version__

    return f"{SOFTWARE_NAME} {__version__}"


def software_version_numbers() -> tuple[int, int, int]:
    """(major, minor, patch) of servosurf's version, for numeric header fields."""
    from .._version import __version__

    parts = [int(p) if p.isdigit() else 0 for p in __version__.split(".")[:3]]
    return tuple((parts + [0, 0, 0])[:3])  # type: ignore[return-value]


def written_by_servosurf(software: str | None) -> bool:
    """True when a software field names servosurf (a file servosurf wrote)."""
    return isinstance(software, str) and software.strip().lower().startswith(
        SOFTWARE_NAME
    )


def jsonable(obj: Any) -> Any:
    """Return ``obj`` with numpy values, bytes and non-finite floats made JSON-safe."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, bytes):
        return obj.decode("utf-8", errors="replace")
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, Path):
        return str(obj)
    if obj is None or isinstance(obj, bool | int | float | str):
        return obj
    return str(obj)


def metadata_json(metadata: dict[str, Any], *, exclude: tuple[str, ...] = ()) -> str:
    """Serialise metadata to compact JSON, leaving out ``exclude`` keys."""
    md = {k: v for k, v in jsonable(metadata).items() if k not in exclude}
    return json.dumps(md, separators=(",", ":"), sort_keys=True, allow_nan=False)


def parse_metadata_json(text: str) -> dict[str, Any] | None:
    """Return the dict encoded in ``text``, or None when it is not a JSON object."""
    text = text.strip()
    if not text.startswith("{"):
        return None
    try:
        value = json.loads(text)
    except (ValueError, RecursionError):
        return None
    return value if isinstance(value, dict) else None


def iso_date(timestamp: float) -> str | None:
    """ISO 8601 UTC date of a Unix time stamp in s, or None when unset/implausible."""
    try:
        t = float(timestamp)
    except (TypeError, ValueError):
        return None
    if not math.isfinite(t) or t < _EARLIEST_TIMESTAMP or t > 32503680000:  # 3000 AD
        return None
    d = _dt.datetime.fromtimestamp(t, tz=_dt.UTC)
    return d.isoformat().replace("+00:00", "Z")


def timestamp_from_iso(text: Any) -> int | None:
    """Unix time in s of an ISO 8601 date (naive dates are taken as UTC), or None."""
    if not isinstance(text, str):
        return None
    try:
        d = _dt.datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    except ValueError:
        return None
    if d.tzinfo is None:
        d = d.replace(tzinfo=_dt.UTC)
    return int(d.timestamp())


def decode_text(data: bytes) -> str:
    """Decode text as UTF-8, falling back to Latin-1 (never fails)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


# ------------------------------------------------------------- zip helpers
def zip_member(
    zf: zipfile.ZipFile, member: str, name: str, *, expected_size: int | None = None
) -> bytes:
    """Read one member of a zip archive after checking its declared size.

    Parameters
    ----------
    zf : zipfile.ZipFile
        Open archive.
    member : str
        Member name.
    name : str
        Archive file name for messages.
    expected_size : int, optional
        Exact uncompressed size in bytes the caller needs.

    Returns
    -------
    bytes
        The member content.

    Raises
    ------
    CorruptedFileError
        Missing member, wrong or implausible size, bad CRC or compression data.
    """
    try:
        info = zf.getinfo(member)
    except KeyError:
        raise corrupt(
            name, f"archive member {member!r} is missing", "it to exist"
        ) from None
    if expected_size is not None and info.file_size != expected_size:
        raise corrupt(
            name,
            f"archive member {member!r} has {info.file_size} bytes",
            f"{expected_size} bytes",
        )
    limit = MAX_MEMBER_BYTES
    if info.compress_type == zipfile.ZIP_STORED:
        limit = min(limit, info.compress_size)
    else:
        limit = min(limit, max(info.compress_size, 1) * _MAX_DEFLATE_RATIO)
    if info.file_size > limit:
        raise corrupt(
            name,
            f"archive member {member!r} claims {info.file_size} bytes from "
            f"{info.compress_size} stored bytes",
            "a size the stored data can hold",
        )
    try:
        return zf.read(info)
    except _ZIP_ERRORS as exc:
        raise corrupt(
            name,
            f"archive member {member!r} cannot be read ({exc})",
            "an intact zip archive",
        ) from None


#: Time stamp of every member of a zip archive servosurf writes (the DOS epoch,
#: 1980-01-01 00:00:00): a fixed value, so identical content gives identical bytes.
ZIP_DATE_TIME: tuple[int, int, int, int, int, int] = (1980, 1, 1, 0, 0, 0)


def zip_archive(members: dict[str, bytes], *, compress: bool = True) -> bytes:
    """Build a reproducible zip archive: same members, same bytes.

    :mod:`zipfile` stamps members written by name with the current local time;
    here every member gets :data:`ZIP_DATE_TIME`, Unix attributes ``0644`` and a
    fixed creator system, in the order given.

    Parameters
    ----------
    members : dict of str to bytes
        Member names and contents, written in this order.
    compress : bool, default: True
        Deflate the members (zlib's default level); stored otherwise.

    Returns
    -------
    bytes
        The archive.
    """
    out = BytesIO()
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    with zipfile.ZipFile(out, "w") as zf:
        for member, content in members.items():
            info = zipfile.ZipInfo(member, date_time=ZIP_DATE_TIME)
            info.compress_type = method
            info.create_system = 3  # Unix, whatever the platform writing
            info.external_attr = 0o644 << 16
            zf.writestr(info, content)
    return out.getvalue()


def open_zip(data: bytes, name: str, what: str) -> zipfile.ZipFile:
    """Open ``data`` as a zip archive or raise :class:`CorruptedFileError`."""
    try:
        return zipfile.ZipFile(BytesIO(data))
    except _ZIP_ERRORS as exc:
        raise corrupt(name, f"not a readable zip archive ({exc})", what) from None


def as_surface(obj: Surface | Profile) -> Surface:
    """Return a :class:`Surface`; a :class:`Profile` becomes one row, ``dy = dx``."""
    if isinstance(obj, Surface):
        return obj
    if isinstance(obj, Profile):
        md = dict(obj.metadata)
        md.setdefault("kind", "profile")
        return Surface(obj.z[None, :], obj.dx, obj.dx, metadata=md, x0=obj.x0)
    raise TypeError(f"expected a Surface or Profile, got {type(obj).__name__}")


def pixel_origin(surface: Surface) -> tuple[int, int]:
    """(column, row) of pixel (0, 0) on a camera grid, from ``x0/dx`` and ``y0/dy``.

    Returns (0, 0) unless the surface is calibrated and both offsets are
    non-negative whole multiples of the pixel size (as readers of formats with a
    phase window produce them).
    """
    if not surface.calibrated:
        return 0, 0
    assert surface.dx is not None and surface.dy is not None
    out = []
    for off, step in ((surface.x0, surface.dx), (surface.y0, surface.dy)):
        n = off / step
        k = round(n)
        if not (0 <= k < 32768) or abs(n - k) > 1e-6:
            return 0, 0
        out.append(int(k))
    return out[0], out[1]


def writer_error(fmt: str, what: str, remedy: str = "") -> FileFormatError:
    """Build the error raised when a surface cannot be stored in a format."""
    msg = f"cannot write {fmt}: {what}"
    if remedy:
        msg += f"; {remedy}"
    return FileFormatError(msg)


def unsupported(name: str, what: str, expected: str) -> UnsupportedFileFormatError:
    """Build the error for a valid file using a feature servosurf does not read."""
    return UnsupportedFileFormatError(f"{name}: {what}; expected {expected}")
