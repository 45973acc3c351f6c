"""Extract the ``.datx`` content from HDF5 bytes, optionally in a helper process.

libhdf5 can loop forever, exhaust memory or crash (segmentation fault) on damaged
files, and none of that can be caught in Python. The ``.datx`` reader therefore
runs :func:`extract` in one long-lived helper interpreter (started on first use,
restarted after a failure, stopped at exit) under an address-space limit, and waits
for it with a timeout. A file that hangs or crashes the helper is reported as
:class:`~servosurf.errors.CorruptedFileError`.

This file is also the helper's program: it is run by path (``python -P _hdf5.py``)
and must import nothing but the standard library, numpy and h5py at module level
(no relative imports outside functions the helper never calls).

Protocol on the helper's stdin/stdout: 8-byte little-endian length, then a pickle.
The helper first sends ``b"ready"``; each request ``data`` (bytes) gets
``("ok", extracted)``, ``("bad", what, expected)`` or ``("damaged", message)``.
Set ``SERVOSURF_HDF5_ISOLATION=0`` to extract in-process (faster for trusted files,
unsafe for damaged ones).
"""

from __future__ import annotations

import atexit
import os
import pickle
import queue
import struct
import subprocess
import sys
import tempfile
import threading
from io import BytesIO
from typing import Any

__all__ = ["extract", "extract_isolated", "ExtractError", "shutdown", "TIMEOUT"]

#: Seconds the helper may take per file, plus 1 s per 10 MB of file.
TIMEOUT: float = 30.0
#: Address space granted to the helper beyond its current size, in bytes, plus
#: :data:`MEMORY_PER_BYTE` bytes per byte of file (a legitimate file needs a few
#: times its size; damaged ones can ask libhdf5 for gigabytes).
MEMORY_HEADROOM: int = 2**30
MEMORY_PER_BYTE: int = 32

#: Attributes of the height dataset the reader uses.
DATASET_ATTRS = (
    "Unit",
    "No Data",
    "X Converter",
    "Y Converter",
    "Z Converter",
    "Wavelength",
    "Interferometric Scale Factor",
    "Obliquity Factor",
    "Coordinates",
    "servosurf.origin",
    "servosurf.nominal_wavelength",
)
#: Attribute-group keys the reader uses, by name suffix.
GROUP_ATTRS = (
    "System Type",
    "System Serial Number",
    "Objective",
    "Software Info Name",
    "Software Info Version",
    "Comment",
    "Wavelength:Value",
    "Time Stamp",
)
_GROUP_PREFIXES = (
    "Data Context.Data Attributes.",
    "Surface Data Context.Data Attributes.",
    "",
)
_OWN_KEY = "servosurf.metadata"
_MAX_METADATA_ROWS = 100_000
_MAX_LIST = 4096
_READY = b"ready"
_LEN = struct.Struct("<Q")


class ExtractError(Exception):
    """The HDF5 file is readable but lacks what a ``.datx`` needs: (what, expected)."""


# ---------------------------------------------------------------- extraction
def _plain(v: Any) -> Any:
    """numpy/h5py attribute value -> str, float, int, list or dict (picklable)."""
    import numpy as np

    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, str | int | float | bool) or v is None:
        return v
    if isinstance(v, np.void) and v.dtype.names:
        return {n: _plain(v[n]) for n in v.dtype.names}
    if isinstance(v, np.ndarray):
        flat = v.ravel()[:_MAX_LIST]
        if v.dtype.names:
            return [_plain(x) for x in flat]
        if v.dtype.kind in "fiub":
            return [float(x) for x in flat]
        if v.dtype.kind in "OSU":
            return [_plain(x) for x in flat]
        return None
    if isinstance(v, np.generic):
        return _plain(v.item())
    return None


def _first_str(v: Any) -> str | None:
    v = _plain(v)
    while isinstance(v, list):
        if not v:
            return None
        v = v[0]
    return v if isinstance(v, str) else None


def _read_attr(obj: Any, key: str) -> Any:
    try:
        if key not in obj.attrs:
            return None
        return _plain(obj.attrs[key])
    except (OSError, RuntimeError, ValueError, KeyError, TypeError, IndexError):
        return None


def _metadata_table(f: Any) -> dict[str, dict[str, str]]:
    ds = f.get("MetaData")
    names = getattr(getattr(ds, "dtype", None), "names", None)
    if not names or not {"Source", "Link", "Destination"} <= set(names) or ds.ndim != 1:
        return {}
    if ds.shape[0] > _MAX_METADATA_ROWS:
        return {}
    table: dict[str, dict[str, str]] = {}
    for row in ds[()]:
        src, link, dest = (
            _first_str(row[k]) for k in ("Source", "Link", "Destination")
        )
        if src is not None and link is not None and dest is not None:
            table.setdefault(src, {})[link] = dest
    return table


def _locate(f: Any) -> tuple[Any, Any]:
    """(surface dataset, attribute group or None) via /MetaData, else fallbacks."""
    import h5py

    table = _metadata_table(f)
    surface = group = None
    meas = table.get("Root", {}).get("Measurement")
    if meas is not None:
        links = table.get(meas, {})
        s = links.get("Surface")
        if s is not None:
            path = table.get(s, {}).get("Path", s if s.startswith("/") else None)
            if path is not None and isinstance(f.get(path), h5py.Dataset):
                surface = f[path]
        a = links.get("Attributes")
        if a is not None and isinstance(f.get(a), h5py.Group):
            group = f[a]
    if surface is None:
        for path in ("/Measurement/Surface", "/Data/Surface"):
            obj = f.get(path)
            if isinstance(obj, h5py.Dataset):
                surface = obj
                break
            if isinstance(obj, h5py.Group):
                sets = [k for k in obj if isinstance(obj.get(k), h5py.Dataset)]
                if sets:
                    surface = obj[sets[0]]
                    break
    if surface is None:
        raise ExtractError(
            "HDF5 file has no surface dataset",
            "a /MetaData link Root -> Measurement -> Surface, /Measurement/Surface or "
            "/Data/Surface/<dataset>",
        )
    if group is None:
        grp = f.get("Attributes")
        if isinstance(grp, h5py.Group):
            subs = [
                k for k in grp if k != "System" and isinstance(grp.get(k), h5py.Group)
            ]
            if subs:
                group = grp[subs[-1]]
    return surface, group


def extract(data: bytes) -> dict[str, Any]:
    """Open HDF5 bytes with h5py and return what the ``.datx`` reader needs.

    Parameters
    ----------
    data : bytes
        Whole file.

    Returns
    -------
    dict
        ``z`` (float64 array as stored, no unit conversion), ``dataset`` (its path),
        ``attrs`` (the :data:`DATASET_ATTRS` present, as plain values) and ``group``
        (the :data:`GROUP_ATTRS` found in the attribute group, keyed by suffix, plus
        ``servosurf.metadata``).

    Raises
    ------
    ExtractError
        No usable surface dataset.
    OSError, RuntimeError, ValueError, ...
        Whatever h5py raises on a damaged file.
    """
    import h5py
    import numpy as np

    with h5py.File(BytesIO(data), "r") as f:
        ds, group = _locate(f)
        if ds.ndim != 2 or ds.dtype.kind not in "fiu" or 0 in ds.shape:
            raise ExtractError(
                f"surface dataset {ds.name} has shape {ds.shape} and type {ds.dtype}",
                "a non-empty 2-D numeric array",
            )
        nbytes = float(np.prod(ds.shape, dtype=np.float64)) * 8
        if nbytes > max(1100.0 * len(data), 2.0**20):
            raise ExtractError(
                f"surface dataset claims {ds.shape[0]}x{ds.shape[1]} values in a "
                f"{len(data)}-byte file",
                "a size the file can hold",
            )
        z = np.asarray(ds[()], dtype=np.float64)
        attrs = {k: v for k in DATASET_ATTRS if (v := _read_attr(ds, k)) is not None}
        gattrs: dict[str, Any] = {}
        if group is not None:
            try:
                keys = set(group.attrs.keys())
            except (OSError, RuntimeError, ValueError, KeyError, TypeError):
                keys = set()
            for suffix in GROUP_ATTRS:
                for prefix in _GROUP_PREFIXES:
                    if prefix + suffix in keys:
                        v = _read_attr(group, prefix + suffix)
                        if v is not None:
                            gattrs[suffix] = v
                        break
            if _OWN_KEY in keys:
                gattrs[_OWN_KEY] = _read_attr(group, _OWN_KEY)
        return {"z": z, "dataset": ds.name, "attrs": attrs, "group": gattrs}


# ------------------------------------------------------------- helper process
def _limit_memory(extra: int) -> None:
    try:
        import resource
    except ImportError:  # pragma: no cover - not POSIX
        return
    try:
        with open("/proc/self/statm") as fh:
            vm = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        vm = 2 * 2**30
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    want = vm + MEMORY_HEADROOM + extra
    if hard != resource.RLIM_INFINITY:
        want = min(want, hard)
    try:
        resource.setrlimit(resource.RLIMIT_AS, (want, hard))
    except (ValueError, OSError):  # pragma: no cover - platform refuses
        pass


def main() -> None:
    """Run the helper loop: answer requests from stdin on stdout until end of input."""
    stdin, stdout = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr  # stray prints must not corrupt the protocol
    import h5py  # noqa: F401 - fail early (reported by the parent) if missing

    def send(obj: Any) -> None:
        body = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
        stdout.write(_LEN.pack(len(body)) + body)
        stdout.flush()

    stdout.write(_LEN.pack(len(_READY)) + _READY)
    stdout.flush()
    while True:
        head = stdin.read(_LEN.size)
        if len(head) < _LEN.size:
            return
        (n,) = _LEN.unpack(head)
        data = stdin.read(n)
        if len(data) < n:
            return
        _limit_memory(MEMORY_PER_BYTE * len(data))
        try:
            send(("ok", extract(data)))
        except ExtractError as exc:
            send(("bad", *exc.args))
        except MemoryError:
            send(("damaged", "parsing needs more memory than the file can justify"))
        except Exception as exc:  # h5py raises many types on damaged files
            text = str(exc).splitlines()[0][:200] if str(exc) else ""
            send(("damaged", f"{type(exc).__name__}: {text}"))


class _Helper:
    """The helper process and a reader thread that queues its replies."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.proc: subprocess.Popen | None = None
        self.replies: queue.Queue[bytes | None] = queue.Queue()
        self.thread: threading.Thread | None = None
        self.stderr: Any = None

    def _start(self) -> None:
        from ..errors import FileFormatError

        env = dict(os.environ)
        env.setdefault("OPENBLAS_NUM_THREADS", "1")
        env.setdefault("OMP_NUM_THREADS", "1")
        self.stderr = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(
            [sys.executable, "-P", os.path.abspath(__file__)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self.stderr,
            env=env,
        )
        self.replies = queue.Queue()
        self.thread = threading.Thread(
            target=_pump,
            args=(self.proc, self.replies),
            name="servosurf-hdf5",
            daemon=True,
        )
        self.thread.start()
        try:
            hello = self.replies.get(timeout=120.0)
        except queue.Empty:
            hello = None
        if hello != _READY:
            detail = self._stop()
            raise FileFormatError(f"cannot start the HDF5 reader process ({detail})")

    def _stop(self) -> str:
        """Kill the helper and describe how it ended."""
        proc, self.proc = self.proc, None
        if proc is None:
            return "not running"
        if proc.poll() is None:
            proc.kill()
        rc = proc.wait()
        for pipe in (proc.stdin, proc.stdout):
            if pipe is not None:
                try:
                    pipe.close()
                except OSError:
                    pass
        if self.thread is not None:
            self.thread.join(timeout=5.0)
            self.thread = None
        err = b""
        if self.stderr is not None:
            try:
                self.stderr.seek(0)
                err = self.stderr.read()[-400:]
            finally:
                self.stderr.close()
                self.stderr = None
        last = err.decode("utf-8", "replace").strip().splitlines()[-1:] if err else []
        how = f"killed by signal {-rc}" if rc < 0 else f"exit status {rc}"
        return how + (f": {last[0]}" if last else "")

    def close(self) -> None:
        with self.lock:
            proc = self.proc
            if proc is None:
                return
            try:
                assert proc.stdin is not None
                proc.stdin.close()
                proc.wait(timeout=5.0)
            except (OSError, subprocess.TimeoutExpired):
                pass
            self._stop()

    def call(self, data: bytes, name: str, timeout: float) -> tuple:
        from ..errors import CorruptedFileError

        def fail(what: str) -> CorruptedFileError:
            return CorruptedFileError(f"{name}: {what}; expected a readable .datx file")

        with self.lock:
            if self.proc is None or self.proc.poll() is not None:
                if self.proc is not None:
                    self._stop()
                self._start()
            proc = self.proc
            assert proc is not None and proc.stdin is not None
            try:
                proc.stdin.write(_LEN.pack(len(data)) + data)
                proc.stdin.flush()
            except OSError:
                raise fail(
                    f"the HDF5 reader process ended early ({self._stop()})"
                ) from None
            try:
                reply = self.replies.get(timeout=timeout)
            except queue.Empty:
                self._stop()
                raise fail(
                    f"libhdf5 did not finish parsing within {timeout:.0f} s "
                    "(damaged file)"
                ) from None
            if reply is None:
                raise fail(f"libhdf5 failed on this file ({self._stop()})")
            return pickle.loads(reply)


def _pump(proc: subprocess.Popen, replies: queue.Queue) -> None:
    """Reader thread: queue each framed reply, then None at end of stream."""
    out = proc.stdout
    assert out is not None
    try:
        while True:
            head = out.read(_LEN.size)
            if len(head) < _LEN.size:
                break
            (n,) = _LEN.unpack(head)
            body = out.read(n)
            if len(body) < n:
                break
            replies.put(body)
    except (OSError, ValueError):
        pass
    replies.put(None)


_HELPER = _Helper()
atexit.register(_HELPER.close)


def shutdown() -> None:
    """Stop the helper process (the next isolated read starts a new one)."""
    _HELPER.close()


def extract_isolated(data: bytes, name: str) -> dict[str, Any]:
    """Run :func:`extract` in the helper process.

    Parameters
    ----------
    data : bytes
        Whole HDF5 file.
    name : str
        File name for messages.

    Returns
    -------
    dict
        As :func:`extract`.

    Raises
    ------
    ExtractError
        As :func:`extract`.
    CorruptedFileError
        h5py failed, or libhdf5 hung, crashed or exceeded its memory allowance.
    """
    from ..errors import CorruptedFileError

    reply = _HELPER.call(data, name, TIMEOUT + len(data) / 10e6)
    if reply[0] == "ok":
        return reply[1]
    if reply[0] == "bad":
        raise ExtractError(*reply[1:])
    raise CorruptedFileError(
        f"{name}: HDF5 structure is damaged ({reply[1]}); "
        "expected a readable .datx file"
    )


if __name__ == "__main__":
    main()
