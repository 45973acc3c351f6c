"""Shared fixtures of the diagnose tests."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "discovery"


@pytest.fixture(scope="session")
def discovery():
    """Importer of the discovery benchmark's modules (``benchmarks/discovery``)."""
    if str(BENCH) not in sys.path:
        sys.path.insert(0, str(BENCH))
    return importlib.import_module
