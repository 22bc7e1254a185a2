"""Atomic file output: the one helper every gonio writer uses (DESIGN.md: files are written to a
temporary file, then renamed).

>>> with atomic_output("out/figure.png", suffix=".png", make_parents=True) as tmp:
...     fig.savefig(tmp)
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path

from gonio.errors import FormatError, StorageError
from gonio.io.storage import full_after_failure, storage_error

PathLike = str | os.PathLike[str]


def current_umask() -> int:
    """The process's file-mode creation mask (read without changing it for good)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_output(
    path: PathLike, suffix: str = ".tmp", *, make_parents: bool = False
) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; when the body succeeds, rename it onto ``path``.

    The temporary file lives in the destination folder so that :func:`os.replace` is an atomic
    rename on the same file system, and it gets the mode a plain ``open()`` would give the file
    (``0o666`` less the umask; :func:`tempfile.mkstemp` creates it ``0o600``). If the body raises
    (``KeyboardInterrupt`` included), the temporary file is removed and ``path`` is left as it
    was: a crash never leaves a half-written file under the final name, nor a stale temporary.
    A failure of the storage itself (a full filesystem, a quota, a file-size limit, a read-only
    or failing filesystem: :mod:`gonio.io.storage`), whatever library reported it, is raised
    as one :class:`~gonio.errors.StorageError` naming ``path`` and its filesystem.

    Parameters
    ----------
    path : the destination file.
    suffix : suffix of the temporary file (some writers choose the format from it, e.g. ``.exr``).
    make_parents : create missing parent folders first; otherwise a missing folder is an error.

    Raises
    ------
    FormatError
        ``path`` is a folder, or its folder does not exist (and ``make_parents`` is False).
    StorageError
        The storage refused the file (see above).
    """
    dest = Path(path)
    folder = dest.parent if str(dest.parent) else Path(".")
    if dest.is_dir():
        raise FormatError(f"{os.fspath(dest)}: is a directory, cannot write a file there")
    if make_parents:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise storage_error(exc, folder) or exc from None
    elif not folder.is_dir():
        raise FormatError(f"{os.fspath(dest)}: output folder {folder} does not exist")
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=suffix, dir=folder)
    except OSError as exc:  # named after the file asked for, not the temporary one
        raise storage_error(exc, dest) or OSError(
            exc.errno, exc.strerror, os.fspath(dest)
        ) from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~current_umask())
        os.replace(tmp, dest)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        if isinstance(exc, Exception) and not isinstance(exc, StorageError):
            err = storage_error(exc, dest)
            if err is None and isinstance(exc, OSError | RuntimeError) and full_after_failure(dest):
                # a library that reports a failed write without its reason, on a full disk
                err = storage_error(OSError(errno.ENOSPC, ""), dest)
            if err is not None:
                raise err from None
        raise


def same_file(a: PathLike, b: PathLike) -> bool:
    """Whether ``a`` and ``b`` name one file: through symlinks and hard links when both
    exist, by their resolved names otherwise (an output that does not exist yet)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


__all__ = ["atomic_output", "current_umask", "same_file"]


def replace_folder(staging: PathLike, target: PathLike) -> bool:
    """Move the finished folder ``staging`` onto ``target`` as a whole; True when ``target``
    existed and was replaced.

    ``staging`` must be a sibling of ``target`` (same file system). An existing ``target`` is
    first renamed aside (``.NAME.old-*``), ``staging`` renamed onto its name, then the old folder
    removed: nothing of the old folder survives beside the new one, and until the second rename
    the old folder is whole under its own name (if that rename fails, the old one is put back).
    """
    staging, target = Path(staging), Path(target)
    if not target.exists():
        os.rename(staging, target)
        return False
    aside = target.parent / f".{target.name}.old-{uuid.uuid4().hex[:8]}"
    os.rename(target, aside)
    try:
        os.rename(staging, target)
    except BaseException:
        os.rename(aside, target)
        raise
    shutil.rmtree(aside, ignore_errors=True)
    return True
