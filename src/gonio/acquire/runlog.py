"""``RUN/log.jsonl``: the run's structured log, one strict JSON object per line.

A line is written whole or not at all. A write the storage refuses (a full filesystem, a quota,
a file-size limit) never raises where it happens: the log cuts the file back to its last whole
line, keeps the failure in :attr:`RunLog.error` (a :class:`gonio.errors.StorageError` naming the
filesystem) and drops later lines, so that logging on the way out of a run (parking after a
fault) cannot itself stop the park. The run engine calls :meth:`RunLog.check` where stopping is
safe, between configurations. A line cut by a killed process is ended when the log is opened
again, so the next one is whole.
"""

from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path

from gonio.io.storage import append_whole, storage_error
from gonio.io.strict_json import dumps_json


class RunLog:
    """Append-only JSON-lines log (one line per event, strict JSON:
    :func:`gonio.io.strict_json.dumps_json`)."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        #: the first failed write (its later lines are dropped), None while every line landed
        self.error: OSError | None = None
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o666)
        with contextlib.suppress(OSError), open(self.path, "rb") as fh:
            end = fh.seek(0, os.SEEK_END)
            if end:
                fh.seek(end - 1)
                if fh.read(1) != b"\n":  # a line cut by a killed process
                    os.write(self._fd, b"\n")

    def __call__(self, event: str, **fields) -> None:
        if self.error is not None or self._fd < 0:
            return
        rec = {"t": round(time.time(), 6), "event": event, **fields}
        try:
            append_whole(self._fd, (dumps_json(rec, default=str) + "\n").encode("utf-8"))
        except OSError as exc:
            self.error = storage_error(exc, self.path) or exc

    def check(self) -> None:
        """Raise the failure that stopped the log (StorageError or OSError), if any."""
        if self.error is not None:
            raise self.error

    def close(self) -> None:
        if self._fd >= 0:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = -1
