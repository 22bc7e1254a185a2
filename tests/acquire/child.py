"""``python -m gonio`` in a child process on this checkout's sources, and the progress of a run
read from its journal while the child writes it (the acquisition tests that kill, interrupt or
unplug a running acquisition)."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import time
from pathlib import Path

from tests.console_script import env

__all__ = ["acquire_cmd", "done_samples", "env", "gonio", "gonio_cmd", "run_until"]


def gonio_cmd(*args) -> list[str]:
    """The command line ``python -m gonio ARGS`` with the running interpreter."""
    return [sys.executable, "-m", "gonio", *map(str, args)]


def acquire_cmd(*args) -> list[str]:
    """``python -m gonio acquire --no-progress ARGS``."""
    return gonio_cmd("acquire", "--no-progress", *args)


def gonio(*args, **kw) -> subprocess.CompletedProcess:
    """Run ``python -m gonio ARGS`` to completion, stdout and stderr captured as text."""
    return subprocess.run(
        gonio_cmd(*args), env=env(), capture_output=True, text=True, timeout=300, **kw
    )


def done_samples(run: Path, timeout: float = 1.0) -> int:
    """Samples journaled so far in ``run`` (0 while there is no journal or it is being created).

    ``timeout`` (s): how long to wait for the writer's lock before giving up (and returning 0).
    """
    db = run / "journal.sqlite"
    if not db.exists():
        return 0
    try:
        con = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=timeout)
        try:
            return con.execute("SELECT COUNT(*) FROM samples").fetchone()[0]
        finally:
            con.close()
    except sqlite3.DatabaseError:
        return 0


def run_until(cmd, run: Path, n_done: int, sig: int, timeout: float = 60.0) -> int:
    """Run ``cmd``; send ``sig`` once ``run`` has ``n_done`` samples journaled; its exit code."""
    proc = subprocess.Popen(cmd, env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    t0 = time.monotonic()
    try:
        while proc.poll() is None and time.monotonic() - t0 < timeout:
            if done_samples(run) >= n_done:
                proc.send_signal(sig)
                break
            time.sleep(0.01)
        proc.wait(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode
