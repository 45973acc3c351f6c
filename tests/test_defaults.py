"""The process knobs: one defaults mapping, its reset, a scoped override, and the
scoped numba/BLAS/malloc settings that library code uses (never set for good)."""

from __future__ import annotations

import pytest

import servosurf
from servosurf import _defaults, defaults, defaults_override, reset_defaults
from servosurf._progress import is_quiet

#: The documented defaults (servosurf/_defaults.py docstring), environment unset.
DOCUMENTED = {
    "numba_cache": True,
    "numba_threads": None,
    "quiet": False,
    "blas_threads": 1,
    "malloc_threshold_bytes": 1 << 30,
}


@pytest.fixture
def restore_defaults():
    """Put every knob back after a test that resets or sets them."""
    before = dict(defaults)
    yield
    defaults.clear()
    defaults.update(before)


def test_reset_gives_the_documented_values(monkeypatch, restore_defaults):
    monkeypatch.delenv("SERVOSURF_NUMBA_CACHE", raising=False)
    monkeypatch.delenv("SERVOSURF_QUIET", raising=False)
    defaults["blas_threads"] = 3
    defaults["quiet"] = True
    reset_defaults()
    assert dict(defaults) == DOCUMENTED
    assert not is_quiet()


@pytest.mark.parametrize(("var", "value", "key", "expected"), [
    ("SERVOSURF_NUMBA_CACHE", "0", "numba_cache", False),
    ("SERVOSURF_NUMBA_CACHE", "off", "numba_cache", False),
    ("SERVOSURF_NUMBA_CACHE", "1", "numba_cache", True),
    ("SERVOSURF_QUIET", "1", "quiet", True),
    ("SERVOSURF_QUIET", "0", "quiet", False),
])
def test_environment_sets_the_initial_value(monkeypatch, restore_defaults, var,
                                            value, key, expected):
    monkeypatch.setenv(var, value)
    reset_defaults()
    assert defaults[key] is expected


def test_override_is_scoped_and_restored_on_error():
    before = dict(defaults)
    with defaults_override(blas_threads=2, quiet=False) as d:
        assert d is defaults
        assert defaults["blas_threads"] == 2 and not is_quiet()
    assert dict(defaults) == before
    with pytest.raises(RuntimeError), defaults_override(numba_threads=1):
        assert defaults["numba_threads"] == 1
        raise RuntimeError("inside")
    assert dict(defaults) == before


def test_unknown_knob_names_the_close_match():
    with pytest.raises(TypeError, match="Did you mean: quiet"):
        with defaults_override(quite=True):
            pass
    with pytest.raises(TypeError, match="blas_threads"):
        servosurf.set_defaults(blas_thread=2)


@pytest.mark.parametrize(("key", "value"), [
    ("quiet", 1), ("numba_cache", "yes"), ("blas_threads", 0),
    ("numba_threads", 1.5), ("malloc_threshold_bytes", True),
])
def test_bad_values_are_refused(key, value):
    before = dict(defaults)
    with pytest.raises(ValueError, match=key):
        servosurf.set_defaults(**{key: value})
    assert dict(defaults) == before


def test_kernels_read_the_cache_knob():
    from servosurf.kernels._config import CACHE

    assert CACHE is defaults["numba_cache"]


def test_numba_threads_restores_the_thread_count():
    import numba

    before = numba.get_num_threads()
    with _defaults.numba_threads(1):
        assert numba.get_num_threads() == 1
    assert numba.get_num_threads() == before
    with defaults_override(numba_threads=1), _defaults.numba_threads():
        assert numba.get_num_threads() == 1
    assert numba.get_num_threads() == before
    from servosurf.errors import ConfigError

    with pytest.raises(ConfigError, match="n_threads"):
        with _defaults.numba_threads(numba.config.NUMBA_NUM_THREADS + 1):
            pass


def test_malloc_reuse_sets_and_restores_the_thresholds(monkeypatch):
    """Only the outermost block sets glibc's thresholds, and sets them back."""
    calls = []
    monkeypatch.setattr(_defaults, "_mallopt",
                        lambda: lambda param, value: calls.append((param, value)) or 1)
    monkeypatch.delenv("MALLOC_MMAP_THRESHOLD_", raising=False)
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    with _defaults.malloc_reuse(1 << 20) as ok:
        assert ok
        with _defaults.malloc_reuse(1 << 20):
            pass
        # M_MMAP_THRESHOLD is -3, M_TRIM_THRESHOLD is -1 (glibc malloc.h)
        assert calls == [(-3, 1 << 20), (-1, 1 << 20)]
    assert calls[2:] == [(-3, 128 * 1024), (-1, 65536)]
    calls.clear()
    with defaults_override(malloc_threshold_bytes=None), _defaults.malloc_reuse():
        pass
    assert calls == []


def test_blas_threads_restores_openblas(monkeypatch):
    """The ctypes fallback sets the BLAS thread count and sets it back."""
    import builtins

    real_import = builtins.__import__

    def no_threadpoolctl(name, *a, **k):
        if name == "threadpoolctl":
            raise ImportError(name)
        return real_import(name, *a, **k)

    state = {"n": 4}
    monkeypatch.setattr(builtins, "__import__", no_threadpoolctl)
    monkeypatch.setattr(_defaults, "_openblas_handles", lambda: [
        (lambda n: state.__setitem__("n", n.value), lambda: state["n"])])
    with _defaults.blas_threads(1):
        assert state["n"] == 1
    assert state["n"] == 4
    with defaults_override(blas_threads=None), _defaults.blas_threads():
        assert state["n"] == 4


def test_progress_reads_the_quiet_knob(capsys):
    from servosurf._progress import note

    with defaults_override(quiet=False):
        note("hello")
    with defaults_override(quiet=True):
        note("silent")
    err = capsys.readouterr().err
    assert "hello" in err and "silent" not in err
