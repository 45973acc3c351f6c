"""Session-wide fixtures and paths."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("SERVOSURF_SHARED", REPO.parent / "shared"))
ZYGO = SHARED / "data" / "zygo"


@pytest.fixture(autouse=True, scope="session")
def _quiet_progress():
    """Keep progress lines out of captured CLI output, and check defaults unchanged."""
    from servosurf._progress import is_quiet, set_quiet

    before = is_quiet()
    set_quiet(True)
    yield
    set_quiet(before)


@pytest.fixture(scope="session")
def zygo_dir() -> Path:
    """Folder of real ZYGO/x3p files (skips when ../shared is absent)."""
    if not ZYGO.is_dir():
        pytest.skip(f"shared data folder {ZYGO} absent")
    return ZYGO
