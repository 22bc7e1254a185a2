"""Run directories that are valid from their first byte.

A new run is built under a hidden temporary name next to ``RUN`` (``.RUN.start-XXXX``): its
journal is created with the schema and all of the run's metadata (rig file, plan, versions) in
one SQLite transaction, closed, and only then is the directory renamed to ``RUN``. A kill at any
moment therefore leaves either no ``RUN`` (start again with ``--out RUN``) or a ``RUN`` whose
journal names its rig and plan (continue with ``--resume RUN``). A start that fails before the
rig is ready (no serial port, a wrong servo, a bad camera) removes ``RUN`` again with
:func:`discard`; leftovers of a killed start are removed by the next start into the same ``RUN``.

A run folder is held by the one acquisition writing it (:class:`RunHold`): an ``flock`` on
``RUN/.lock`` with the holder's PID in ``RUN/.lock.pid`` (:mod:`gonio.locks`), taken on the
temporary folder before its rename, so that no other process can ever write the run; a second
``gonio acquire --resume RUN`` is refused in one line naming the PID. Readers (``gonio info``,
``grid``, ``fit``, ``render`` of ``RUN/table.brdf.h5``) take no lock. Between configurations
the engine checks that ``RUN`` is still the folder it holds (:meth:`RunHold.check`): a run folder
removed or moved under a running acquisition stops it. A storage failure anywhere in the run (a
full filesystem, a quota, a file-size limit: :mod:`gonio.io.storage`) becomes one
:class:`~gonio.errors.StorageError` that says how many samples are kept and how to resume
(:func:`storage_failure`).
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import sqlite3
import tempfile
import time
from pathlib import Path
from typing import Self

from gonio.acquire.journal import Journal
from gonio.acquire.plans import Plan, plan_from_spec
from gonio.errors import FormatError, PlanError, StorageError
from gonio.io.storage import REASONS, storage_error
from gonio.io.strict_json import dumps_json
from gonio.locks import Lock
from gonio.rigs.config import RigConfig, parse_rig

#: the run folder's lock file (its holder's PID in ``LOCK_NAME + ".pid"``)
LOCK_NAME = ".lock"


def _stale_prefix(run_dir: Path) -> str:
    return f".{run_dir.name}.start-"


def start_new(
    run_dir: Path,
    rig: RigConfig,
    plan_spec: dict,
    meta: dict[str, str],
    hold: RunHold | None = None,
) -> bool:
    """Create run directory ``run_dir`` with its journal; return whether it existed (empty).

    ``meta`` adds to the recorded metadata; ``hold`` is taken on the new folder before it
    appears as ``run_dir``. PlanError if ``run_dir`` exists and is not an empty directory.
    """
    from gonio import __version__

    existed = run_dir.exists()
    if existed and (not run_dir.is_dir() or any(run_dir.iterdir())):
        raise PlanError(f"{run_dir} exists and is not empty (use --resume to continue a run)")
    parent = run_dir.parent
    parent.mkdir(parents=True, exist_ok=True)
    for stale in parent.glob(_stale_prefix(run_dir) + "*"):
        shutil.rmtree(stale, ignore_errors=True)  # a start killed before its rename
    tmp = Path(tempfile.mkdtemp(prefix=_stale_prefix(run_dir), dir=parent))
    try:
        record = {
            "schema_version": str(Journal.SCHEMA_VERSION),
            "gonio_version": __version__,
            "rig_text": rig.text,
            "rig_source": rig.source,
            "plan_spec": dumps_json(plan_spec),
            "created": str(time.time()),
            **meta,
        }
        Journal(tmp, create=True, meta=record).close()
        tmp.chmod(0o777 & ~_umask())
        if hold is not None:
            hold.take(tmp)
        # rename(2) replaces an empty directory atomically, and fails on a non-empty one
        tmp.replace(run_dir)
        if hold is not None and hold.lock is not None:
            hold.lock.moved(run_dir)
    except StorageError as exc:  # named after the run asked for, not the temporary folder
        shutil.rmtree(tmp, ignore_errors=True)
        err = StorageError(str(exc).replace(str(tmp), str(run_dir)))
        err.errno = exc.errno
        raise err from None
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise PlanError(f"cannot create run directory {run_dir}: {exc}") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return existed


def discard(run_dir: Path, existed: bool) -> None:
    """Remove a run directory whose start failed (recreating it empty if it was given so)."""
    shutil.rmtree(run_dir, ignore_errors=True)
    if existed:
        run_dir.mkdir(exist_ok=True)


def open_run(run_dir: Path) -> tuple[Journal, RigConfig, Plan]:
    """Open an existing run: its journal (checked, :meth:`Journal.check`), and the rig and plan
    recorded in it."""
    j = Journal(run_dir)
    try:
        j.check()
        text = j.get_meta("rig_text")
        spec = j.get_meta("plan_spec")
        if text is None or spec is None:
            raise FormatError(f"{run_dir}: journal lacks the rig or the plan")
        rig = parse_rig(text, j.get_meta("rig_source") or "rig")
        try:
            plan = plan_from_spec(json.loads(spec))
        except json.JSONDecodeError as exc:
            raise FormatError(f"{j.path}: the recorded plan does not decode ({exc})") from None
    except BaseException:
        j.close()
        raise
    return j, rig, plan


class RunHold:
    """``RUN`` held by this process: its lock (see the module) and the identity of the folder
    and the journal it holds. A context manager that releases the lock on the way out."""

    def __init__(self, run_dir: Path) -> None:
        self.run_dir = Path(run_dir)
        self.lock: Lock | None = None
        self._ident: tuple[os.stat_result, os.stat_result] | None = None

    def take(self, folder: Path | None = None) -> None:
        """Lock ``folder`` (default ``RUN``; a new run's temporary folder before its rename):
        InUseError naming the holder's PID if another process holds it."""
        folder = Path(folder or self.run_dir)
        if not (folder / Journal.FILENAME).is_file():  # no lock file left in a stranger's folder
            raise FormatError(f"{self.run_dir} is not a gonio run (no {Journal.FILENAME})")
        lock = Lock(
            folder / LOCK_NAME,
            f"run folder {self.run_dir}",
            "one acquisition writes a run at a time (gonio info, grid, fit and render may read"
            " it meanwhile)",
        )
        try:
            lock.acquire()
        except OSError as exc:
            raise storage_error(exc, folder) or exc from None
        self.lock = lock
        try:
            self._ident = (os.stat(folder), os.stat(folder / Journal.FILENAME))
        except OSError:
            self._ident = None  # gone already: open_run says so

    def check(self) -> None:
        """StorageError if ``RUN`` or its journal is no longer the one this process holds
        (removed, moved or replaced under the run)."""
        if self._ident is None:
            return
        try:
            now = (os.stat(self.run_dir), os.stat(self.run_dir / Journal.FILENAME))
            same = all(os.path.samestat(a, b) for a, b in zip(now, self._ident, strict=True))
        except OSError:
            same = False
        if not same:
            err = StorageError(
                f"{self.run_dir}: the run folder was removed or replaced while this acquisition"
                " was writing it; stopped (a moved folder keeps every sample journaled so far:"
                " gonio acquire --resume NEW_PLACE)"
            )
            err.errno = errno.ENOENT
            raise err

    def release(self) -> None:
        if self.lock is not None:
            self.lock.release()
            self.lock = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def storage_failure(exc: BaseException, run_dir: Path) -> StorageError | None:
    """``exc`` as the StorageError that stops a run, saying how many samples the journal kept
    and how to resume once space is freed (its notes, e.g. whether the rig was parked,
    carried over); None when ``exc`` is no storage failure."""
    if not isinstance(exc, Exception):
        return None
    err = storage_error(exc, run_dir)
    if err is None:
        return None
    if err is not exc:
        for note in getattr(exc, "__notes__", ()):
            err.add_note(note)  # e.g. whether the rig was parked
    if err.errno in REASONS and not Path(run_dir, Journal.FILENAME).is_file():
        err.add_note("no run was created: make room, then start it again")
    elif err.errno in REASONS:
        kept = _samples_kept(run_dir)
        what = "every committed sample is kept" if kept is None else f"{kept} samples kept"
        err.add_note(f"{what}: make room, then gonio acquire --resume {run_dir}")
    return err


def _samples_kept(run_dir: Path) -> int | None:
    """Samples in the journal, read without writing anything (None if it cannot be read)."""
    try:
        con = sqlite3.connect(f"file:{Path(run_dir, Journal.FILENAME)}?mode=ro", uri=True)
        try:
            return int(con.execute("SELECT COUNT(*) FROM samples").fetchone()[0])
        finally:
            con.close()
    except sqlite3.Error:
        return None


def _umask() -> int:
    import os

    mask = os.umask(0)
    os.umask(mask)
    return mask
