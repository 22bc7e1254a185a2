"""What a failed write says about where it was going: storage errors and their filesystem.

A write fails for its *storage* rather than its content when the filesystem is full
(``ENOSPC``), a quota is exhausted (``EDQUOT``), a file-size limit is reached (``EFBIG``: the
process's ``RLIMIT_FSIZE``, ``ulimit -f``, or the filesystem's largest file), the filesystem is
read-only (``EROFS``) or failing (``EIO``). Libraries say so in different ways: an
:class:`OSError` with its ``errno`` (Python, h5py, Pillow), SQLite's "database or disk is full"
and "disk I/O error" (:class:`sqlite3.OperationalError`), or only the system's text inside
another exception (OpenEXR's ``RuntimeError``). :func:`storage_errno` recognises all of them,
and :func:`storage_error` turns one into a :class:`gonio.errors.StorageError` whose one-line
message names the file, the reason and the filesystem (mount point, type, free space).
:func:`append_whole` appends a log line whole or not at all.
"""

from __future__ import annotations

import contextlib
import errno
import os
import resource
from pathlib import Path

from gonio.errors import GonioError, StorageError

#: errno -> what the one-line message says
REASONS: dict[int, str] = {
    errno.ENOSPC: "no space left on device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file too large",
    errno.EROFS: "read-only file system",
    errno.EIO: "input/output error (the storage is failing)",
}

_SQLITE = {
    "SQLITE_FULL": errno.ENOSPC,
    "SQLITE_IOERR": errno.EIO,
    "SQLITE_READONLY": errno.EROFS,
}
_SQLITE_TEXT = {"database or disk is full": errno.ENOSPC, "disk I/O error": errno.EIO}


def storage_errno(exc: BaseException) -> int | None:
    """The storage errno (a key of :data:`REASONS`) behind ``exc``, or None.

    Looks at ``exc`` and the exceptions it was raised from or during (``__cause__``,
    ``__context__`` unless ``from None`` hid it): an ``errno`` attribute, SQLite's error name
    or text, or the system's message for one of these errors (but EIO) inside the exception's
    text. A :class:`~gonio.errors.GonioError` other than StorageError on the way is no storage
    error: it already says what failed (a serial port's I/O error is a DeviceError).
    """
    seen: set[int] = set()
    e: BaseException | None = exc
    while e is not None and id(e) not in seen and len(seen) < 16:
        seen.add(id(e))
        if isinstance(e, GonioError) and not isinstance(e, StorageError):
            return None  # already said what it is (a serial port's EIO is a DeviceError)
        code = getattr(e, "errno", None)
        if code in REASONS:
            return code
        name = getattr(e, "sqlite_errorname", None)
        if isinstance(name, str):
            for prefix, c in _SQLITE.items():
                if name.startswith(prefix):
                    return c
        text = str(e)
        for needle, c in _SQLITE_TEXT.items():
            if needle in text and type(e).__module__ == "sqlite3":
                return c
        for c in REASONS:  # EIO's text is too common (a serial port's) to be read as storage
            if c != errno.EIO and os.strerror(c) in text:
                return c
        e = e.__cause__ or (None if e.__suppress_context__ else e.__context__)
    return None


def mount_of(path: str | os.PathLike) -> tuple[str, str]:
    """``(mount point, filesystem type)`` of the filesystem holding ``path`` (or, when it does
    not exist, its nearest existing ancestor); the type is ``""`` where ``/proc/self/mounts``
    cannot be read."""
    p = Path(os.path.abspath(path))
    while not p.exists() and p != p.parent:
        p = p.parent
    real = os.path.realpath(p)
    best, kind = "", ""
    try:
        with open("/proc/self/mounts", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                parts = line.split()
                if len(parts) < 3:
                    continue
                mnt = _unescape(parts[1])
                inside = real == mnt or real.startswith(mnt.rstrip("/") + "/")
                if inside and len(mnt) >= len(best):
                    best, kind = mnt, parts[2]
    except OSError:
        pass
    if best:
        return best, kind
    q = Path(real)
    while not os.path.ismount(q) and q != q.parent:
        q = q.parent
    return str(q), ""


def _unescape(field: str) -> str:
    """A path of /proc/self/mounts, whose space, tab, newline and backslash are octal escapes."""
    for code in ("\\040", "\\011", "\\012", "\\134"):
        field = field.replace(code, chr(int(code[1:], 8)))
    return field


def describe_filesystem(path: str | os.PathLike) -> str:
    """``"the filesystem at /mnt (tmpfs, 12 KiB of 400 KiB free)"`` for the one holding
    ``path``."""
    mnt, kind = mount_of(path)
    try:
        st = os.statvfs(mnt)
        free = f"{_size(st.f_bavail * st.f_frsize)} of {_size(st.f_blocks * st.f_frsize)} free"
    except OSError:
        free = ""
    detail = ", ".join(x for x in (kind, free) if x)
    return f"the filesystem at {mnt}" + (f" ({detail})" if detail else "")


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} B"  # pragma: no cover


def reason(code: int) -> str:
    """What :data:`REASONS` says for ``code``; for ``EFBIG`` under a file-size limit of the
    process (``ulimit -f``), that limit."""
    text = REASONS.get(code, os.strerror(code))
    if code == errno.EFBIG:
        soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
        if soft != resource.RLIM_INFINITY:
            text += f" (this process may write files of at most {_size(soft)}: ulimit -f)"
    return text


def storage_error(
    exc: BaseException, path: str | os.PathLike, what: str | None = None
) -> StorageError | None:
    """A :class:`StorageError` for ``exc`` writing ``path`` (``what`` names it in the message,
    default the path), or None when ``exc`` is not a storage error (:func:`storage_errno`).
    An existing StorageError is returned as it is."""
    if isinstance(exc, StorageError):
        return exc
    code = storage_errno(exc)
    if code is None:
        return None
    if code == errno.EIO:
        code = _cause_of_io_error(path)
    err = StorageError(f"{what or os.fspath(path)}: {reason(code)} on {describe_filesystem(path)}")
    err.errno = code
    return err


def _cause_of_io_error(path: str | os.PathLike) -> int:
    """What an I/O error writing ``path`` most likely was, for the libraries that report
    every failed write as one (SQLite's "disk I/O error"): the process's file-size limit
    reached by the file or its SQLite companions (``-wal``, ``-journal``), a full filesystem,
    else EIO itself."""
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft != resource.RLIM_INFINITY:
        for suffix in ("", "-wal", "-journal"):
            try:
                if os.stat(os.fspath(path) + suffix).st_size + 65536 >= soft:
                    return errno.EFBIG
            except OSError:
                continue
    return errno.ENOSPC if full_after_failure(path) else errno.EIO


def append_whole(fd: int, data: bytes) -> None:
    """Append ``data`` to the file open as ``fd`` whole or not at all: a write the storage cuts
    short (a full disk) is cut back off the file, and its OSError raised. For logs of one
    line per record, which then never end in a torn line."""
    start = os.lseek(fd, 0, os.SEEK_END)
    view = memoryview(data)
    try:
        while view:
            view = view[os.write(fd, view) :]
    except OSError:
        with contextlib.suppress(OSError):
            os.ftruncate(fd, start)
        raise


def full_after_failure(path: str | os.PathLike) -> bool:
    """Whether the filesystem holding ``path`` has no space left for this process: the last
    resort of a writer whose library reported a failed write without saying why."""
    try:
        st = os.statvfs(mount_of(path)[0])
    except OSError:
        return False
    return st.f_bavail == 0 or (st.f_favail == 0 and st.f_files > 0)


__all__ = [
    "REASONS",
    "append_whole",
    "describe_filesystem",
    "full_after_failure",
    "mount_of",
    "reason",
    "storage_errno",
    "storage_error",
]
