"""Parse HDF5 (``.datx``) files in a separate process.

libhdf5 can loop forever, exhaust memory or crash (segmentation fault) on damaged
files, and none of that can be caught in Python. servosurf therefore hands untrusted
HDF5 content to one long-lived helper interpreter (started on first use, restarted
after a failure) that runs :func:`servosurf.io._datx.read_in_process` under an
address-space limit; the caller waits with a timeout. A file that hangs or crashes
the helper is reported as :class:`~servosurf.errors.CorruptedFileError`.

Protocol on the helper's stdin/stdout: 8-byte little-endian length, then a pickle.
Request ``(data, name)``; reply ``("ok", (z, dx, dy, x0, y0, metadata))`` or
``("err", error_class_name, message)``. The helper writes ``b"ready"`` once at
start. Set ``SERVOSURF_HDF5_ISOLATION=0`` to parse in-process instead (faster for
trusted files, unsafe for damaged ones).
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
from pathlib import Path
from typing import Any

__all__ = ["run_isolated", "main", "TIMEOUT", "shutdown"]

#: Seconds the helper may take per file, plus 1 s per 10 MB of file.
TIMEOUT: float = 30.0
#: Address space granted to the helper on top of its size at start, in bytes,
#: plus 16 bytes per byte of file.
MEMORY_HEADROOM: int = 2 * 2**30
_READY = b"ready"
_LEN = struct.Struct("<Q")


class _Helper:
    """One helper process with a reader thread that turns replies into a queue."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.proc: subprocess.Popen | None = None
        self.replies: queue.Queue[bytes | None] = queue.Queue()
        self.thread: threading.Thread | None = None
        self.stderr: Any = None

    # --------------------------------------------------------------- process
    def _start(self) -> None:
        from ..errors import FileFormatError

        root = str(Path(__file__).resolve().parents[2])  # folder holding servosurf/
        env = dict(os.environ)
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        env.setdefault("OPENBLAS_NUM_THREADS", "1")
        env.setdefault("OMP_NUM_THREADS", "1")
        env["SERVOSURF_HDF5_ISOLATION"] = "0"
        self.stderr = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(
            [sys.executable, "-c", "from servosurf.io._hdf5_worker import main; main()"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.stderr, env=env,
        )
        self.replies = queue.Queue()
        self.thread = threading.Thread(
            target=_pump, args=(self.proc, self.replies), name="servosurf-hdf5", daemon=True
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
        """Kill the helper; return a description of how it ended."""
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
        err = b""
        if self.stderr is not None:
            try:
                self.stderr.seek(0)
                err = self.stderr.read()[-300:]
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

    # --------------------------------------------------------------- request
    def call(self, data: bytes, name: str, timeout: float) -> tuple:
        from ..errors import CorruptedFileError

        with self.lock:
            if self.proc is None or self.proc.poll() is not None:
                if self.proc is not None:
                    self._stop()
                self._start()
            proc = self.proc
            assert proc is not None and proc.stdin is not None
            payload = pickle.dumps((data, name), protocol=pickle.HIGHEST_PROTOCOL)
            try:
                proc.stdin.write(_LEN.pack(len(payload)) + payload)
                proc.stdin.flush()
            except OSError:
                detail = self._stop()
                raise CorruptedFileError(
                    f"{name}: the HDF5 reader process ended before reading the file "
                    f"({detail}); expected a readable .datx file"
                ) from None
            try:
                reply = self.replies.get(timeout=timeout)
            except queue.Empty:
                self._stop()
                raise CorruptedFileError(
                    f"{name}: libhdf5 did not finish parsing within {timeout:.0f} s (the "
                    "file is probably damaged); expected a readable .datx file"
                ) from None
            if reply is None:
                detail = self._stop()
                raise CorruptedFileError(
                    f"{name}: libhdf5 failed on this file ({detail}); expected a readable "
                    ".datx file"
                )
            return pickle.loads(reply)


def _pump(proc: subprocess.Popen, replies: queue.Queue) -> None:
    """Reader thread: forward each framed reply (None at end of stream)."""
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
    """Stop the helper process (it restarts on the next isolated read)."""
    _HELPER.close()


def run_isolated(data: bytes, name: str) -> tuple:
    """Parse ``data`` with :func:`read_in_process` in the helper process.

    Parameters
    ----------
    data : bytes
        Whole HDF5 file.
    name : str
        File name for messages.

    Returns
    -------
    tuple
        ``(z, dx, dy, x0, y0, metadata)``: heights in m, pixel sizes and origin in m.

    Raises
    ------
    FileFormatError
        The error the parser raised, or :class:`CorruptedFileError` when libhdf5
        hung, crashed or ran out of its memory allowance.
    """
    from .. import errors

    timeout = TIMEOUT + len(data) / 10e6
    reply = _HELPER.call(data, name, timeout)
    if reply[0] == "ok":
        return reply[1]
    _, cls_name, message = reply
    cls = getattr(errors, cls_name, None)
    if not (isinstance(cls, type) and issubclass(cls, errors.FileFormatError)):
        cls = errors.CorruptedFileError
    raise cls(message)


# ------------------------------------------------------------------ helper side
def _limit_memory(extra: int) -> None:
    try:
        import resource
    except ImportError:  # pragma: no cover - not on POSIX
        return
    try:
        with open("/proc/self/statm") as fh:
            vm = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        vm = 2 * 2**30
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    want = vm + MEMORY_HEADROOM + extra
    if hard != resource.RLIM_INFINITY:
        want = min(want, hard)
    try:
        resource.setrlimit(resource.RLIMIT_AS, (want, hard))
    except (ValueError, OSError):  # pragma: no cover - platform refuses
        pass


def main() -> None:
    """Helper loop: read requests on stdin, answer on stdout until end of input."""
    stdin, stdout = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr  # stray prints must not corrupt the protocol
    from ..errors import FileFormatError
    from ._common import Source
    from ._datx import read_in_process

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
        data, name = pickle.loads(stdin.read(n))
        _limit_memory(16 * len(data))
        try:
            s = read_in_process(Source(data, name, ".datx"))
            send(("ok", (s.z, s.dx, s.dy, s.x0, s.y0, s.metadata)))
        except FileFormatError as exc:
            send(("err", type(exc).__name__, str(exc)))
        except MemoryError:
            send(("err", "CorruptedFileError",
                  f"{name}: parsing needs more memory than the file can justify; "
                  "expected a readable .datx file"))
        except Exception as exc:  # libhdf5/h5py raise many types on damaged files
            first = str(exc).splitlines()[0][:200] if str(exc) else ""
            send(("err", "CorruptedFileError",
                  f"{name}: HDF5 structure is damaged ({type(exc).__name__}: {first}); "
                  "expected a readable .datx file"))
