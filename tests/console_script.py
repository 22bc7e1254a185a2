"""Running the installed ``gonio`` console script (the one ``pip install`` writes beside the
interpreter) on this checkout's sources, as a user's shell would."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

SRC = str(Path(__file__).resolve().parents[1] / "src")


def script() -> str:
    """Path of the ``gonio`` console script of the running interpreter (skips when absent)."""
    path = Path(sys.executable).parent / "gonio"
    if not path.is_file():
        pytest.skip(f"no gonio console script beside {sys.executable}")
    return str(path)


def env(**extra: str) -> dict[str, str]:
    """The environment with this checkout's sources first on the path."""
    e = dict(os.environ)
    e["PYTHONPATH"] = SRC + os.pathsep + e.get("PYTHONPATH", "")
    e["JAX_PLATFORMS"] = "cpu"
    e.update(extra)
    return e


def run(*args, columns: int | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """``gonio ARGS`` with stdout and stderr captured (a pipe: not a terminal)."""
    extra = {} if columns is None else {"COLUMNS": str(columns)}
    return subprocess.run(
        [script(), *map(str, args)],
        env=env(**extra),
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def assert_clean(proc: subprocess.CompletedProcess) -> None:
    """Exit status 0 and no traceback nor warning on stderr."""
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr
    assert proc.returncode == 0, proc.stderr
