"""Reader and writer registry: formats register themselves by suffix and magic bytes.

A format module calls :func:`register_reader` / :func:`register_writer` at import
time. Detection trusts the content first (magic bytes, then an optional ``sniff``
callable that tells apart formats sharing a container, e.g. zip), and falls back on
the suffix. A file that claims a format by its suffix but fails that format's checks
gets the format's own :class:`~servosurf.errors.CorruptedFileError`, which says what
is wrong.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Literal

import numpy as np

from ..errors import FileFormatError, UnsupportedFileFormatError
from ..metrology._surface import Profile, Surface
from ._common import Source, as_surface, load_source

__all__ = [
    "FormatInfo",
    "register_reader",
    "register_writer",
    "formats",
    "detect_format",
    "read_any",
    "read_surface",
    "read_profile",
    "write_surface",
]

Kind = Literal["surface", "profile"]
ReadFn = Callable[[Source], Surface | Profile]
EncodeFn = Callable[..., bytes]


@dataclass(frozen=True)
class FormatInfo:
    """Description of one registered file format.

    Parameters
    ----------
    name : str
        Format name accepted by ``format=`` (``"metropro_dat"``, ``"x3p"``, ...).
    description : str
        One-line human description.
    suffixes : tuple of str
        File suffixes with the dot, lower case.
    kind : {"surface", "profile"}
        What the reader returns.
    readable, writable : bool
        Whether a reader / writer is registered.
    """

    name: str
    description: str
    suffixes: tuple[str, ...]
    kind: Kind
    readable: bool
    writable: bool


@dataclass(frozen=True)
class _Reader:
    name: str
    description: str
    suffixes: tuple[str, ...]
    magic: tuple[bytes, ...]
    sniff: Callable[[bytes], bool] | None
    kind: Kind
    read: ReadFn


@dataclass(frozen=True)
class _Writer:
    name: str
    description: str
    suffixes: tuple[str, ...]
    encode: EncodeFn
    profiles: bool


_READERS: dict[str, _Reader] = {}
_WRITERS: dict[str, _Writer] = {}


def register_reader(
    name: str,
    *,
    description: str,
    suffixes: tuple[str, ...],
    magic: tuple[bytes, ...] = (),
    sniff: Callable[[bytes], bool] | None = None,
    kind: Kind = "surface",
) -> Callable[[ReadFn], ReadFn]:
    """Register ``read(source: Source) -> Surface | Profile`` as a reader (decorator).

    Parameters
    ----------
    name : str
        Format name.
    description : str
        One-line description.
    suffixes : tuple of str
        Suffixes with the dot (``(".dat",)``).
    magic : tuple of bytes, default: ()
        Prefixes any of which identifies the format from the first bytes.
    sniff : callable, optional
        ``sniff(data) -> bool`` refining a magic match (or replacing it when
        ``magic`` is empty); must never raise.
    kind : {"surface", "profile"}, default: "surface"
        What ``read`` returns.

    Returns
    -------
    callable
        The decorator (returns the function unchanged).
    """

    def deco(fn: ReadFn) -> ReadFn:
        _READERS[name] = _Reader(
            name,
            description,
            tuple(s.lower() for s in suffixes),
            magic,
            sniff,
            kind,
            fn,
        )
        return fn

    return deco


def register_writer(
    name: str,
    *,
    description: str,
    suffixes: tuple[str, ...],
    profiles: bool = False,
) -> Callable[[EncodeFn], EncodeFn]:
    """Register ``encode(surface, **options) -> bytes`` as a writer (decorator).

    Parameters
    ----------
    name : str
        Format name.
    description : str
        One-line description.
    suffixes : tuple of str
        Suffixes with the dot.
    profiles : bool, default: False
        The format stores profiles as profiles: ``encode`` receives a
        :class:`Profile` unchanged. Otherwise a profile is passed as a one-row
        :class:`Surface` with ``dy = dx``.

    Returns
    -------
    callable
        The decorator (returns the function unchanged).
    """

    def deco(fn: EncodeFn) -> EncodeFn:
        _WRITERS[name] = _Writer(
            name, description, tuple(s.lower() for s in suffixes), fn, profiles
        )
        return fn

    return deco


def formats() -> list[FormatInfo]:
    """List every registered file format.

    Returns
    -------
    list of FormatInfo
        One entry per format name, readers first in registration order.
    """
    names = list(dict.fromkeys([*_READERS, *_WRITERS]))
    out = []
    for n in names:
        r, w = _READERS.get(n), _WRITERS.get(n)
        ref = r or w
        assert ref is not None
        out.append(
            FormatInfo(
                name=n,
                description=ref.description,
                suffixes=ref.suffixes,
                kind=r.kind if r else "surface",
                readable=r is not None,
                writable=w is not None,
            )
        )
    return out


def _resolve_name(fmt: str, table: dict[str, Any], what: str) -> str:
    key = fmt.strip().lower()
    if key in table:
        return key
    suffix = key if key.startswith(".") else "." + key
    for n, entry in table.items():
        if suffix in entry.suffixes:
            return n
    names = ", ".join(sorted(table))
    raise UnsupportedFileFormatError(
        f"no {what} for format {fmt!r}; expected one of: {names} (or their suffixes)"
    )


def _match_magic(data: bytes) -> list[str]:
    hits = []
    for r in _READERS.values():
        if r.magic and not any(data.startswith(m) for m in r.magic):
            continue
        if not r.magic and r.sniff is None:
            continue
        if r.sniff is not None and not r.sniff(data):
            continue
        hits.append(r.name)
    return hits


def detect_format(source: Source) -> str:
    """Return the reader name for ``source``: magic bytes first, then the suffix.

    Parameters
    ----------
    source : Source
        Loaded file content.

    Returns
    -------
    str
        A registered reader name.

    Raises
    ------
    UnsupportedFileFormatError
        When neither the content nor the suffix identifies a known format.
    """
    hits = _match_magic(source.data)
    if len(hits) == 1:
        return hits[0]
    by_suffix = [r.name for r in _READERS.values() if source.suffix in r.suffixes]
    for n in by_suffix:
        if not hits or n in hits:
            return n
    if hits:
        return hits[0]
    known = ", ".join(f"{r.name} ({'/'.join(r.suffixes)})" for r in _READERS.values())
    head = source.data[:8]
    raise UnsupportedFileFormatError(
        f"{source.name}: unknown file format (suffix {source.suffix or 'none'!r}, "
        f"first bytes {head!r}); expected one of: {known}"
    )


def read_any(
    source: str | os.PathLike | IO[bytes] | bytes, *, format: str | None = None
) -> tuple[Surface | Profile, str]:
    """Read a surface or a profile, whichever the file holds.

    Parameters
    ----------
    source : str, path-like, binary file-like or bytes
        The file.
    format : str, optional
        Format name or suffix; detected from content and suffix when None.

    Returns
    -------
    (Surface or Profile, str)
        The data (heights in m, pixel sizes in m) and the format name used.

    Raises
    ------
    UnsupportedFileFormatError
        Unknown format.
    CorruptedFileError
        The file is truncated or inconsistent.
    """
    src = load_source(source)
    name = _resolve_name(format, _READERS, "reader") if format else detect_format(src)
    # Damaged files may hold extreme numbers; overflow to inf becomes NaN (invalid)
    # in the readers, so numpy's floating-point warnings are noise here.
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        return _READERS[name].read(src), name


def read_surface(
    source: str | os.PathLike | IO[bytes] | bytes, *, format: str | None = None
) -> Surface:
    """Read a height map from an interferometer or exchange file.

    Parameters
    ----------
    source : str, path-like, binary file-like or bytes
        Path, or a binary buffer (e.g. ``io.BytesIO``) read from its current
        position.
    format : str, optional
        Format name (see :func:`formats`) or suffix such as ``"dat"``; by default
        the format is detected from the magic bytes, then from the suffix.

    Returns
    -------
    Surface
        Heights in m (NaN where invalid), pixel sizes ``dx``/``dy`` in m (None when
        the file is laterally uncalibrated), row 0 at the top, and metadata
        (``instrument``, ``objective``, ``wavelength`` in m, ``date``, ...).

    Raises
    ------
    UnsupportedFileFormatError
        Unknown format.
    CorruptedFileError
        Truncated or inconsistent file, or a map without any valid pixel.

    See Also
    --------
    read_profile, write_surface, formats

    Notes
    -----
    A profile file (e.g. an Mx profile CSV) is returned as a one-row surface with
    ``dy = dx``.

    Examples
    --------
    >>> import io
    >>> import numpy as np
    >>> from servosurf.io import read_surface, write_surface
    >>> from servosurf.metrology import Surface
    >>> buf = io.BytesIO()
    >>> write_surface(Surface(np.zeros((2, 3)), 1e-6, 1e-6), buf, format="x3p")
    >>> s = read_surface(io.BytesIO(buf.getvalue()))
    >>> s.shape, s.dx, s.metadata["source_format"]
    ((2, 3), 1e-06, 'x3p')
    """
    obj, _ = read_any(source, format=format)
    return as_surface(obj)


def read_profile(
    source: str | os.PathLike | IO[bytes] | bytes, *, format: str | None = None
) -> Profile:
    """Read a height profile (e.g. an Mx profile CSV export).

    A surface file with a single row or column is accepted as a profile.

    Parameters
    ----------
    source : str, path-like, binary file-like or bytes
        Path or binary buffer.
    format : str, optional
        Format name or suffix; detected when None.

    Returns
    -------
    Profile
        Heights in m (NaN where invalid) at a constant step ``dx`` in m.

    Raises
    ------
    UnsupportedFileFormatError
        Unknown format, or the file holds a 2-D map (or is uncalibrated).
    CorruptedFileError
        Truncated or inconsistent file.
    """
    obj, name = read_any(source, format=format)
    if isinstance(obj, Profile):
        return obj
    ny, nx = obj.shape
    if ny == 1 or nx == 1:
        step = obj.dx if ny == 1 else obj.dy
        if step is None:
            raise UnsupportedFileFormatError(
                f"{_display(source)}: profile has no lateral calibration; "
                "expected a step in m"
            )
        x0 = obj.x0 if ny == 1 else obj.y0
        return Profile(obj.z.ravel(), step, metadata=dict(obj.metadata), x0=x0)
    raise UnsupportedFileFormatError(
        f"{_display(source)}: holds a {ny}x{nx} surface ({name}); expected a profile "
        "(an Mx profile .csv or a one-row map); servosurf info describes maps"
    )


def _display(source: Any) -> str:
    if isinstance(source, str | os.PathLike):
        return str(source)
    return str(getattr(source, "name", "<buffer>"))


def write_surface(
    surface: Surface | Profile,
    path: str | os.PathLike | IO[bytes],
    *,
    format: str | None = None,
    **options: Any,
) -> None:
    """Write a surface atomically in one of the writable formats.

    Parameters
    ----------
    surface : Surface or Profile
        Heights in m. A profile is written as a profile where the format has one
        (``.x3p``: ``FeatureType PRF``), as a one-row surface with ``dy = dx``
        elsewhere.
    path : str, path-like or binary file-like
        Destination. A path is written through a temporary file renamed at the end,
        so an error never leaves a half-written file.
    format : str, optional
        Format name or suffix; taken from the suffix of ``path`` by default
        (required for buffers).
    **options
        Format-specific keyword options (e.g. ``phase_res`` for ``metropro_dat``);
        unknown names raise ``TypeError``.

    Raises
    ------
    UnsupportedFileFormatError
        No writer for the format.
    FileFormatError
        The surface cannot be stored in that format (e.g. uncalibrated x3p).
    """
    if format is None:
        if not isinstance(path, str | os.PathLike):
            raise UnsupportedFileFormatError(
                "format must be given when writing to a buffer; expected one of: "
                + ", ".join(sorted(_WRITERS))
            )
        suffix = Path(path).suffix.lower()
        names = [w.name for w in _WRITERS.values() if suffix in w.suffixes]
        if not names:
            known = ", ".join(
                f"{w.name} ({'/'.join(w.suffixes)})" for w in _WRITERS.values()
            )
            raise UnsupportedFileFormatError(
                f"{path}: no writer for suffix {suffix or 'none'!r}; "
                f"expected one of: {known}"
            )
        name = names[0]
    else:
        name = _resolve_name(format, _WRITERS, "writer")
    data = _encode(name, surface, options)
    if not isinstance(data, bytes):  # pragma: no cover - writer contract
        raise FileFormatError(
            f"writer {name} returned {type(data).__name__}, not bytes"
        )
    if isinstance(path, str | os.PathLike):
        from .._atomic import atomic_write

        atomic_write(path, lambda p: p.write_bytes(data))
    else:
        path.write(data)


def encode_surface(surface: Surface | Profile, format: str, **options: Any) -> bytes:
    """Return the content of ``surface`` encoded in ``format`` (no file is written).

    Parameters
    ----------
    surface : Surface or Profile
        Heights in m; a profile stays a profile where the format has one, else
        it becomes a one-row surface with ``dy = dx``.
    format : str
        Writable format name or suffix (``"datx"``, ``".x3p"``, ...).
    **options
        Format-specific keyword options, as for :func:`write_surface`.

    Returns
    -------
    bytes
        The file content.

    Raises
    ------
    UnsupportedFileFormatError
        No writer for the format.
    FileFormatError
        The surface cannot be stored in that format.
    """
    name = _resolve_name(format, _WRITERS, "writer")
    return _encode(name, surface, options)


def _encode(name: str, surface: Surface | Profile, options: dict[str, Any]) -> bytes:
    writer = _WRITERS[name]
    if not (writer.profiles and isinstance(surface, Profile)):
        surface = as_surface(surface)
    return writer.encode(surface, **options)
