"""Helpers shared by the format modules: input checks, clean failures and atomic writes
(:func:`gonio.io.atomic.atomic_output`, re-exported here)."""

from __future__ import annotations

import os
from pathlib import Path

from gonio._bounded import MAX_DECODED_BYTES, MAX_TEXT_BYTES
from gonio.errors import FormatError
from gonio.io.atomic import atomic_output

PathLike = str | os.PathLike[str]


def fail(path: PathLike, problem: str) -> FormatError:
    """Build the one-line :class:`FormatError` for ``path`` (callers ``raise fail(...)``)."""
    problem = " ".join(str(problem).split())  # one line, whatever the cause said
    return FormatError(f"{os.fspath(path)}: {problem}")


def check_input_file(path: PathLike) -> Path:
    """Return ``path`` as a :class:`Path` after checking that it is a readable regular file.

    Raises
    ------
    FormatError
        When the path does not exist, is a directory or cannot be opened.
    """
    p = Path(path)
    if p.is_dir():
        raise fail(p, "is a directory, expected a file")
    if not p.exists():
        raise fail(p, "no such file")
    if not p.is_file():
        raise fail(p, "not a regular file")
    if not os.access(p, os.R_OK):
        raise fail(p, "permission denied")
    return p


def read_bytes(path: PathLike, max_bytes: int = MAX_DECODED_BYTES + (1 << 20)) -> bytes:
    """Read a whole input file, turning OS errors into :class:`FormatError`.

    A file larger than ``max_bytes`` (default: the memory budget of one table plus 1 MiB for
    headers, see :mod:`gonio._bounded`) is refused before anything is read.
    """
    p = check_input_file(path)
    try:
        size = p.stat().st_size
        if size > max_bytes:
            raise fail(p, f"{size} bytes, more than the {max_bytes} a file of this kind may have")
        return p.read_bytes()
    except OSError as exc:
        raise fail(p, f"cannot read: {exc.strerror or exc}") from None


def read_text(path: PathLike) -> str:
    """Read a text file as UTF-8 (undecodable bytes are an error, not silently replaced)."""
    data = read_bytes(path, MAX_TEXT_BYTES)
    if b"\x00" in data:
        raise fail(path, "binary content in a text file (NUL byte)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise fail(path, f"not a UTF-8 text file (byte offset {exc.start})") from None


__all__ = ["PathLike", "atomic_output", "check_input_file", "fail", "read_bytes", "read_text"]
