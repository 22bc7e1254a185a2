"""gonio.locks: one holder at a time, the refusal names its PID, a killed holder's lock is taken
over, and neither an exec'd nor a forked child keeps a lock alive."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from gonio.errors import InUseError
from gonio.locks import Lock, hold_port, port_lock_path
from tests.console_script import env

HOLD = """
import sys, time
from gonio.locks import Lock
Lock(sys.argv[1], "thing").acquire()
print("held", flush=True)
time.sleep(60)
"""


def test_second_holder_is_refused_naming_the_pid(tmp_path):
    path = tmp_path / "x.lock"
    with Lock(path, "run folder R", "wait") as first:
        assert first.held and (tmp_path / "x.lock.pid").read_text().split() == [str(os.getpid())]
        with pytest.raises(InUseError) as info:
            Lock(path, "run folder R", "wait").acquire()
        msg = str(info.value)
        assert msg == f"run folder R is in use by process {os.getpid()} (lock {path}); wait"
        assert not os.get_inheritable(first._fd)  # close-on-exec
    assert not (tmp_path / "x.lock.pid").exists() and path.exists()
    with Lock(path, "run folder R") as again:  # released: free again
        assert again.stale_pid is None


def test_killed_holder_is_recognised_and_taken_over(tmp_path):
    path = tmp_path / "x.lock"
    child = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(path)], env=env(), stdout=subprocess.PIPE, text=True
    )
    try:
        assert child.stdout.readline().strip() == "held"
        with pytest.raises(InUseError, match=f"in use by process {child.pid} "):
            Lock(path, "thing").acquire()
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=10)
    # its PID file stays behind, stale: the lock is free and says whose it was
    assert (tmp_path / "x.lock.pid").read_text().split() == [str(child.pid)]
    with Lock(path, "thing") as lock:
        assert lock.stale_pid == child.pid
        assert (tmp_path / "x.lock.pid").read_text().split() == [str(os.getpid())]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork on this platform")
@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")  # the child only sleeps
def test_forked_child_does_not_keep_the_lock(tmp_path):
    path = tmp_path / "x.lock"
    lock = Lock(path, "thing").acquire()
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child: it outlives the holder's release
        os.close(r)
        os.write(w, b"1")
        time.sleep(30)
        os._exit(0)
    try:
        os.close(w)
        assert os.read(r, 1) == b"1"
        lock.release()
        with Lock(path, "thing"):  # free although the forked child still lives
            pass
    finally:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        os.close(r)


def test_port_lock_is_keyed_by_the_real_path(tmp_path, monkeypatch):
    monkeypatch.setenv("GONIO_LOCK_DIR", str(tmp_path / "locks"))
    dev = tmp_path / "ttyUSB0"
    dev.touch()
    link = tmp_path / "by-id"
    link.symlink_to(dev)
    assert port_lock_path(link) == port_lock_path(dev)
    assert port_lock_path(dev).parent == tmp_path / "locks"
    with hold_port(dev), pytest.raises(InUseError, match=f"serial port {link} is in use by"):
        hold_port(link).acquire()
