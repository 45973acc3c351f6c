"""Session-wide fixtures and paths."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# tests/reference/naive.py is imported as ``reference.naive`` by kernel tests
sys.path.insert(0, str(Path(__file__).resolve().parent))
SHARED = Path(os.environ.get("SERVOSURF_SHARED", REPO.parent / "shared"))
ZYGO = SHARED / "data" / "zygo"
UPM = SHARED / "data" / "upm_sts"


@pytest.fixture(autouse=True, scope="session")
def _defaults_unchanged():
    """Keep progress lines out of captured output; assert no test (and no library
    call) left a process knob of ``servosurf.defaults`` changed (python-control's
    ``control_defaults``)."""
    from servosurf import defaults, set_defaults

    before = dict(defaults)
    set_defaults(quiet=True)
    yield
    after = dict(defaults)
    set_defaults(quiet=before["quiet"])
    assert after == {**before, "quiet": True}, "servosurf.defaults changed"


@pytest.fixture(scope="session")
def zygo_dir() -> Path:
    """Folder of real ZYGO/x3p files (skips when ../shared is absent)."""
    if not ZYGO.is_dir():
        pytest.skip(f"shared data folder {ZYGO} absent")
    return ZYGO


@pytest.fixture(scope="session")
def upm_dir() -> Path:
    """Folder of the real slow-tool-servo cut files (skips when ../shared is absent)."""
    if not UPM.is_dir():
        pytest.skip(f"shared data folder {UPM} absent")
    return UPM
