"""Exclusive locks between processes: a run folder for the acquisition writing it, a serial port
for the process driving it.

A lock is an ``flock(2)`` on a lock file, with the holder's PID in a PID file beside it
(``LOCK.pid``). A second process that finds the lock held refuses at once with
:class:`gonio.errors.InUseError`, naming the holder's PID. The kernel releases an ``flock``
when its holder ends in any way (SIGKILL included), so a PID file left by a killed process is
recognised as stale (the lock is free although the file names a PID): the next process takes
the lock over and rewrites the file (:attr:`Lock.stale_pid` says whose it was). The lock file
itself is never removed, so two processes can never hold locks on two different files of one
name. Its descriptor is close-on-exec, and a child forked by the holder (``multiprocessing``'s
fork start method) closes its copy at once (:func:`os.register_at_fork`), so a worker process
never keeps a lock alive after its holder ends.

Serial ports are locked in one folder shared by every gonio process of the machine, keyed by
the port's real path (``/dev/serial/by-id/...`` and the ``/dev/ttyUSB0`` it links to are one
port): :func:`port_lock_path`.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import tempfile
import time
from pathlib import Path
from typing import Self

from gonio.errors import InUseError

#: folder of the serial ports' lock files unless ``GONIO_LOCK_DIR`` names another
PORT_LOCK_DIR = "/run/lock/gonio"

_HELD: dict[int, Lock] = {}  # descriptor -> lock held by this process


def _close_inherited() -> None:
    """In a forked child: drop the copies of the parent's lock descriptors (the parent's locks
    stay held by the parent, and end with it)."""
    for fd in list(_HELD):
        with contextlib.suppress(OSError):
            os.close(fd)
    _HELD.clear()


os.register_at_fork(after_in_child=_close_inherited)


class Lock:
    """An exclusive lock on ``path`` with the holder's PID in ``path.pid``.

    Parameters
    ----------
    path : the lock file (created if missing, never removed).
    what : what it protects, as the refusal names it (``"run folder RUN"``, ``"serial port
        /dev/ttyUSB0"``).
    hint : what the refused user can do, appended to the refusal.

    Use as a context manager, or :meth:`acquire` / :meth:`release`.
    """

    def __init__(self, path: str | os.PathLike, what: str, hint: str = "") -> None:
        self.path = Path(path)
        self.pid_path = self.path.with_name(self.path.name + ".pid")
        self.what = what
        self.hint = hint
        self.stale_pid: int | None = None
        self._fd = -1

    @property
    def held(self) -> bool:
        return self._fd >= 0

    def acquire(self) -> Self:
        """Take the lock, or raise InUseError naming the holder's PID."""
        for _ in range(5):  # the lock file replaced between open and flock: open it again
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
            except PermissionError:  # another user's lock file: flock needs no write access
                fd = os.open(self.path, os.O_RDONLY | os.O_CLOEXEC)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                raise self._refusal() from None
            except BaseException:
                os.close(fd)
                raise
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except OSError:
                same = False
            if same:
                break
            os.close(fd)
        else:  # pragma: no cover - a lock file replaced five times in a row
            raise InUseError(f"{self.what}: its lock file {self.path} keeps being replaced")
        self._fd = fd
        _HELD[fd] = self
        old = _read_pid(self.pid_path)
        if old is not None and old != os.getpid():
            self.stale_pid = old  # its holder ended without releasing: killed
        self._write_pid()
        return self

    def _write_pid(self) -> None:
        """The PID file, replaced atomically; a failure (a full disk) only costs the PID in a
        later refusal, the lock holds without it."""
        try:
            fd, tmp = tempfile.mkstemp(prefix=f".{self.pid_path.name}.", dir=self.path.parent)
            try:
                os.write(fd, f"{os.getpid()}\n".encode())
                os.fchmod(fd, 0o644)
            finally:
                os.close(fd)
            os.replace(tmp, self.pid_path)
        except OSError:
            with contextlib.suppress(OSError, UnboundLocalError):
                os.unlink(tmp)

    def _refusal(self) -> InUseError:
        # the holder may have taken the lock an instant ago and not yet written its PID
        pid = None
        for _ in range(25):
            pid = _read_pid(self.pid_path)
            if pid is not None and _alive(pid):
                break
            time.sleep(0.02)
        who = f"process {pid}" if pid is not None else "another process (no PID recorded)"
        tail = f"; {self.hint}" if self.hint else ""
        return InUseError(f"{self.what} is in use by {who} (lock {self.path}){tail}")

    def moved(self, folder: str | os.PathLike) -> None:
        """The lock file's folder was renamed to ``folder`` (the lock goes with it)."""
        self.path = Path(folder) / self.path.name
        self.pid_path = Path(folder) / self.pid_path.name

    def release(self) -> None:
        """Remove the PID file and release the lock (no-op when not held)."""
        if self._fd < 0:
            return
        if _read_pid(self.pid_path) == os.getpid():
            with contextlib.suppress(OSError):
                self.pid_path.unlink()
        _HELD.pop(self._fd, None)
        with contextlib.suppress(OSError):
            os.close(self._fd)  # closing the last descriptor releases the flock
        self._fd = -1

    def __enter__(self) -> Self:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


def _read_pid(path: Path) -> int | None:
    try:
        text = path.read_text(encoding="ascii", errors="replace").split()
        return int(text[0]) if text and text[0].isdigit() else None
    except (OSError, ValueError):
        return None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def port_lock_path(port: str | os.PathLike) -> Path:
    """The lock file of serial port ``port``: named after its real path (symbolic links
    resolved), in ``GONIO_LOCK_DIR`` when set, else :data:`PORT_LOCK_DIR` (created sticky and
    writable by everyone, as ``/run/lock`` is), else a ``gonio-locks`` folder in the
    temporary directory."""
    name = os.path.realpath(port).strip("/").replace("/", "_") + ".lock"
    env = os.environ.get("GONIO_LOCK_DIR")
    folders = (
        [Path(env)] if env else [Path(PORT_LOCK_DIR), Path(tempfile.gettempdir(), "gonio-locks")]
    )
    for folder in folders:
        try:
            if not folder.is_dir():
                folder.mkdir(parents=True, exist_ok=True)
                folder.chmod(0o1777)
            if os.access(folder, os.W_OK | os.X_OK):
                return folder / name
        except OSError:
            continue
    return folders[-1] / name  # unusable: opening it says why


def hold_port(port: str | os.PathLike) -> Lock:
    """The (not yet acquired) lock of serial port ``port`` (:func:`port_lock_path`)."""
    return Lock(
        port_lock_path(port),
        f"serial port {port}",
        "one process drives a port: wait for it to end, or stop it",
    )


__all__ = ["PORT_LOCK_DIR", "Lock", "hold_port", "port_lock_path"]
