"""Filesystems that fill: a small tmpfs mounted for one test (skipped with the reason where
mounting is refused), a file that takes all the space left, and a child process under a
file-size limit (``RLIMIT_FSIZE``, the ``EFBIG`` of ``ulimit -f``)."""

from __future__ import annotations

import errno
import os
import resource
import shutil
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest


@contextmanager
def small_tmpfs(path: Path, size: str) -> Iterator[Path]:
    """Mount a tmpfs of ``size`` (``mount -o size=...``: ``"2m"``, ``"400k"``) on ``path`` for
    the block; skips the test with the reason where mounting is refused (not root, no
    ``mount``, a container without the capability)."""
    path.mkdir(parents=True, exist_ok=True)
    if shutil.which("mount") is None:
        pytest.skip("no mount command: the RLIMIT_FSIZE tests cover the file-size limit")
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
        capture_output=True,
        text=True,
    )
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({r.stderr.strip() or r.returncode})")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True)


def fill(folder: Path) -> Path:
    """Write ``folder/filler`` until the filesystem is full; returns its path (remove it to
    free the space)."""
    filler = folder / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    block = b"\0" * 4096
    try:
        while True:
            try:
                os.write(fd, block)
            except OSError as exc:
                if exc.errno != errno.ENOSPC:
                    raise
                if len(block) == 1:
                    break
                block = block[: len(block) // 2]
    finally:
        os.close(fd)
    return filler


@contextmanager
def file_size_limit(limit: int) -> Iterator[None]:
    """Limit the files this process writes to ``limit`` bytes for the block (the soft
    ``RLIMIT_FSIZE``; writes past it fail with EFBIG, as Python ignores SIGXFSZ)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))


def under_file_size_limit(limit: int, cmd: list[str]) -> list[str]:
    """``cmd`` run by a Python that first limits its files to ``limit`` bytes (the limit is
    kept across ``exec``; no ``preexec_fn``, which forks a threaded process)."""
    code = (
        "import os, resource, sys; "
        f"resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit})); "
        "os.execv(sys.argv[1], sys.argv[1:])"
    )
    return [sys.executable, "-c", code, *map(str, cmd)]
