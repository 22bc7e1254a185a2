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


# ru_maxrss is not a program's own peak on Linux: exec keeps the larger of the process's high-water
# mark and that of the address space it replaced, so a child forked from a pytest worker that
# once held gigabytes reports them. VmHWM belongs to the address space built after exec; the
# child reads it at exit (normal exit or sys.exit, which every one-line refusal takes).
PEAK_HOOK = (
    "import atexit, sys\n"
    "def _peak(path=sys.argv.pop(1)):\n"
    "    with open('/proc/self/status') as f:\n"
    "        kib = next(int(l.split()[1]) for l in f if l.startswith('VmHWM:'))\n"
    "    with open(path, 'w') as f:\n"
    "        f.write(str(kib * 1024))\n"
    "atexit.register(_peak)\n"
)


def peak_memory(path: Path) -> int:
    """Peak resident memory in bytes that a child started with :data:`PEAK_HOOK` wrote to
    ``path`` as it exited."""
    return int(Path(path).read_text())


def run_measuring_peak(
    *args, tmp_path: Path, timeout: float = 300
) -> tuple[subprocess.CompletedProcess, int]:
    """``gonio ARGS`` in a fresh interpreter on this checkout's sources: the completed process
    and the program's own peak resident memory in bytes (:data:`PEAK_HOOK`)."""
    out = tmp_path / "peak-bytes"
    code = PEAK_HOOK + (
        "import runpy\nsys.argv = ['gonio', *sys.argv[1:]]\n"
        "runpy.run_module('gonio', run_name='__main__')\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, str(out), *map(str, args)],
        env=env(),
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    return proc, peak_memory(out)
