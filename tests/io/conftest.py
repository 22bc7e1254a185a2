"""io tests: allow pointing at the shared data folder explicitly (GONIO_SHARED_DATA), e.g. when
the checkout is a git worktree that has no ../shared beside it."""

from __future__ import annotations

import os
from pathlib import Path

import tests.conftest as _root

if os.environ.get("GONIO_SHARED_DATA"):
    _root.SHARED_DATA = Path(os.environ["GONIO_SHARED_DATA"])
