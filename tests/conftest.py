"""Shared test configuration: paths to the third-party data in ../shared/data."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# Commands run in-process by the tests (gonio.cli.main) would otherwise turn on JAX's persistent
# compilation cache for the rest of the session and write into the user's cache directory;
# tests/test_compile_cache.py checks the cache in child processes without this variable.
os.environ.setdefault("GONIO_COMPILE_CACHE", "0")

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"


def shared_file(*parts: str) -> Path:
    """Path of a file under ../shared/data, skipping the test cleanly when it is absent."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"shared data file not available: {path}")
    return path
