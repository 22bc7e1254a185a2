"""A pool of long-lived fuzz workers with a per-case time limit and a memory watchdog.

A fresh interpreter per case would spend most of its time importing JAX; instead each worker
(:mod:`tests.fuzz.worker`) serves cases one after another. The parent gives every case
:data:`CASE_TIMEOUT_S` seconds of the worker's CPU time (user + system, all threads, from
``/proc/PID/stat``), and :data:`CASE_WALL_S` seconds of wall time for a case that waits without
computing; it polls those and the worker's resident set size (``VmRSS`` in ``/proc/PID/status``)
every :data:`POLL_S` seconds. A worker over :data:`RSS_BUDGET_BYTES` or past either time is
killed (SIGKILL: libhdf5 loops do not answer SIGINT), the case is recorded as ``memory`` or
``hang``, and a new worker is started. The limit is on work, not on wall time, because a case
that compiles new kernels (an RGL mutant with other tensor shapes: about 5 CPU s) takes three to
four times that on a machine loaded by other work, and a wall-time limit then fails it.
RLIMIT_AS is not used: JAX reserves far more address space than it ever touches, and an
address-space limit breaks it at import.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: CPU seconds a case may use (a load takes well under one; a compile about 5).
CASE_TIMEOUT_S = float(os.environ.get("GONIO_FUZZ_TIMEOUT_S", "20"))
#: Wall seconds a case may take whatever CPU it used (a case blocked on a lock or a sleep).
CASE_WALL_S = float(os.environ.get("GONIO_FUZZ_WALL_S", "180"))
#: Resident memory a worker may reach (JAX and gonio take about 0.4 GiB of it).
RSS_BUDGET_BYTES = int(float(os.environ.get("GONIO_FUZZ_RSS_GIB", "2")) * (1 << 30))
POLL_S = 0.05
_START_TIMEOUT_S = 300.0


def rss_bytes(pid: int) -> int:
    """Resident set size of ``pid`` from /proc (0 if the process is gone)."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except (FileNotFoundError, ProcessLookupError):
        pass
    return 0


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of ``pid`` and all its threads, s, from /proc (0 if gone)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            fields = fh.read().rpartition(")")[2].split()
    except (FileNotFoundError, ProcessLookupError):
        return 0.0
    return (int(fields[11]) + int(fields[12])) / _CLOCK_TICKS  # utime, stime (fields 14, 15)


_CLOCK_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


@dataclass
class Verdict:
    outcome: str  # "error", "load", "fail", "hang", "memory", "crash"
    detail: str
    seconds: float
    peak_rss: int
    cpu_seconds: float = 0.0  # the worker's CPU time on the case (not set for a restart)


class Worker:
    """One worker process; :meth:`run` judges a case or kills and restarts the worker."""

    def __init__(
        self,
        warm: list[tuple[str, str]],
        timeout_s: float = CASE_TIMEOUT_S,
        rss_budget: int = RSS_BUDGET_BYTES,
        wall_timeout_s: float = CASE_WALL_S,
    ) -> None:
        self.warm = warm
        self.timeout_s = timeout_s  # CPU seconds per case
        self.wall_timeout_s = wall_timeout_s
        self.rss_budget = rss_budget
        self.proc: subprocess.Popen | None = None
        self.restarts = 0
        self._start()

    def _start(self) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), str(ROOT)])
        env.setdefault("JAX_PLATFORMS", "cpu")
        env["PYTHONFAULTHANDLER"] = "0"
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tests.fuzz.worker", json.dumps(self.warm)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            cwd=ROOT,
            env=env,
            text=True,
            bufsize=1,
        )
        line = self._read_line(_START_TIMEOUT_S)
        if line is None or "ready" not in line:
            self.close()
            raise RuntimeError(f"fuzz worker did not start: {line!r}")

    def _read_line(self, timeout: float) -> str | None:
        assert self.proc is not None and self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        return self.proc.stdout.readline() if ready else None

    def run(self, kind: str, path: str) -> Verdict:
        assert self.proc is not None and self.proc.stdin is not None
        t0 = time.monotonic()
        cpu0 = cpu_seconds(self.proc.pid)
        peak = 0
        try:
            self.proc.stdin.write(json.dumps({"kind": kind, "path": path}) + "\n")
            self.proc.stdin.flush()
        except BrokenPipeError:
            return self._restart("crash", "worker died before the case", t0, peak)
        assert self.proc.stdout is not None
        while True:
            ready, _, _ = select.select([self.proc.stdout], [], [], POLL_S)
            if ready:
                line = self.proc.stdout.readline()
                if not line:
                    code = self.proc.wait()
                    return self._restart("crash", f"worker died (exit {code})", t0, peak)
                v = json.loads(line)
                peak = max(peak, rss_bytes(self.proc.pid))
                cpu = cpu_seconds(self.proc.pid) - cpu0
                return Verdict(v["outcome"], v["detail"], time.monotonic() - t0, peak, cpu)
            peak = max(peak, rss_bytes(self.proc.pid))
            if peak > self.rss_budget:
                return self._restart(
                    "memory", f"worker RSS {peak / 2**30:.2f} GiB over the budget", t0, peak
                )
            cpu = cpu_seconds(self.proc.pid) - cpu0
            if cpu > self.timeout_s:
                return self._restart("hang", f"no answer after {cpu:.0f} s of CPU time", t0, peak)
            if time.monotonic() - t0 > self.wall_timeout_s:
                return self._restart(
                    "hang", f"no answer in {self.wall_timeout_s:.0f} s (CPU {cpu:.1f} s)", t0, peak
                )

    def _restart(self, outcome: str, detail: str, t0: float, peak: int) -> Verdict:
        self.close()
        self.restarts += 1
        v = Verdict(outcome, detail, time.monotonic() - t0, peak)
        self._start()
        return v

    def close(self) -> None:
        if self.proc is None:
            return
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        self.proc.wait()
        for stream in (self.proc.stdin, self.proc.stdout):
            if stream is not None:
                try:
                    stream.close()
                except BrokenPipeError:
                    pass
        self.proc = None
