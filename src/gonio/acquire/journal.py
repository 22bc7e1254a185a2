"""The run journal: every planned configuration and every measured sample, in SQLite.

The journal lives in ``RUN/journal.sqlite`` (WAL mode, ``synchronous=FULL``: a committed sample
survives SIGKILL and power loss). A sample is recorded by one ``INSERT`` into ``samples``,
whose primary key is the configuration index, so a configuration is either fully recorded or not
at all and can never be recorded twice. Resuming means: execute, in planned order, the
configurations of the current stage that have no sample and were not refused.

Tables
------
``meta(key, value)``            run metadata (rig file text, plan spec JSON, versions).
``stages(stage, n, planned_at)`` a row per planned stage (planning is one transaction).
``configs(idx, stage, seq, wi_*, wo_*, isotropic, joints, status, reason)``
                                targets (sample frame) and planned joint angles (deg, JSON).
``samples(idx, joints, wi_*, wo_*, value, sigma, t_*, recoveries, captured_at)``
                                what was measured: read-back angles and directions.
``events(n, t, kind, detail)``  what happened to the rig: servo faults and what was done
                                (JSON detail; created by the first :meth:`Journal.event`).
``decisions(stage, detail)``    what a plan that chooses from the measurements decided before
                                stage ``stage``: the batch's reason, the reconstruction's
                                summary, its predicted error, or why the run stops (JSON);
                                written in the transaction that plans the stage, so a decision
                                and its configurations are journaled together or not at all
                                (created by the first decision: fixed plans have none).

A write that the storage refuses (a full filesystem, a quota, a file-size limit, a read-only or
failing disk; SQLite's "database or disk is full" and "disk I/O error") raises
:class:`gonio.errors.StorageError` naming the journal and its filesystem; SQLite rolls the
failed statement back, so every sample committed before it is kept.
"""

from __future__ import annotations

import functools
import json
import sqlite3
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gonio.errors import FormatError
from gonio.io.storage import storage_error
from gonio.io.strict_json import dumps_json

SCHEMA_VERSION = 1

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS stages(stage INTEGER PRIMARY KEY, n INTEGER NOT NULL,
                                  planned_at REAL NOT NULL);
CREATE TABLE IF NOT EXISTS configs(
    idx INTEGER PRIMARY KEY, stage INTEGER NOT NULL, seq INTEGER NOT NULL,
    wi_x REAL, wi_y REAL, wi_z REAL, wo_x REAL, wo_y REAL, wo_z REAL,
    isotropic INTEGER NOT NULL, joints TEXT, status TEXT NOT NULL, reason TEXT);
CREATE INDEX IF NOT EXISTS configs_stage_seq ON configs(stage, seq);
CREATE TABLE IF NOT EXISTS samples(
    idx INTEGER PRIMARY KEY REFERENCES configs(idx),
    joints TEXT NOT NULL,
    wi_x REAL, wi_y REAL, wi_z REAL, wo_x REAL, wo_y REAL, wo_z REAL,
    value TEXT NOT NULL, sigma TEXT NOT NULL,
    t_motion REAL, t_settle REAL, t_capture REAL, t_book REAL,
    recoveries INTEGER NOT NULL DEFAULT 0, captured_at REAL NOT NULL);
"""


def _writes(method):
    """A journal method whose storage failures raise StorageError (see the module)."""

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except sqlite3.Error as exc:
            err = storage_error(exc, self.path)
            if err is None:
                raise
            raise err from None

    return wrapper


@dataclass(frozen=True)
class PlannedConfig:
    idx: int
    stage: int
    seq: int
    wi: tuple[float, float, float]
    wo: tuple[float, float, float]
    isotropic: bool
    joints_deg: dict[str, float] | None
    status: str
    reason: str | None


@dataclass(frozen=True)
class SampleRow:
    idx: int
    joints_deg: dict[str, float]
    wi: np.ndarray
    wo: np.ndarray
    value: np.ndarray
    sigma: np.ndarray
    timings: dict[str, float]
    recoveries: int


class Journal:
    """SQLite journal of one run directory.

    ``Journal(run_dir, create=True, meta={...})`` creates the tables and writes ``meta`` in one
    transaction, so that no reader ever sees a journal without its metadata.
    """

    FILENAME = "journal.sqlite"
    SCHEMA_VERSION = SCHEMA_VERSION

    def __init__(
        self, run_dir: str | Path, create: bool = False, meta: dict[str, str] | None = None
    ) -> None:
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / self.FILENAME
        if not create and not self.path.is_file():
            raise FormatError(f"{self.run_dir} is not a gonio run (no {self.FILENAME})")
        self.db = sqlite3.connect(self.path, isolation_level=None, timeout=30.0)
        try:
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=FULL")
            self.db.execute("PRAGMA foreign_keys=ON")
            if create:
                items = {"schema_version": str(SCHEMA_VERSION), **(meta or {})}
                with self._tx():
                    for stmt in filter(str.strip, _SCHEMA.split(";")):
                        self.db.execute(stmt)
                    self.db.executemany(
                        "INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)",
                        list(items.items()),
                    )
            else:  # read directly: get_meta's None for an unreadable table would hide why
                row = self.db.execute(
                    "SELECT value FROM meta WHERE key = 'schema_version'"
                ).fetchone()
                ver = row[0] if row else None
                if ver != str(SCHEMA_VERSION):
                    raise FormatError(f"{self.path}: unknown journal schema version {ver!r}")
        except sqlite3.DatabaseError as exc:
            self.db.close()
            raise storage_error(exc, self.path) or FormatError(
                f"{self.path}: not a usable journal ({exc})"
            ) from None

    def close(self) -> None:
        self.db.close()

    def check(self) -> None:
        """Refuse a damaged journal (FormatError) before a resumed run moves anything: SQLite's
        ``quick_check`` of every page and index, then every configuration and sample row
        decoded. A damaged file would otherwise stop the run on its first unreadable row
        after the servos moved, or hide a recorded sample from :meth:`pending` (its index
        page lost) so that the configuration is measured again."""
        try:
            found = [r[0] for r in self.db.execute("PRAGMA quick_check")]
            if found != ["ok"]:
                # one problem per line, the first may be a "*** in database main ***" heading;
                # raised as SQLite raises its own errors, reported by the handler below
                lines = [ln for f in found for ln in f.splitlines() if not ln.startswith("***")]
                raise sqlite3.DatabaseError(
                    f"{lines[0] if lines else found[0]}; {len(lines)} problem(s) found by"
                    " SQLite's quick_check"
                )
            configs, samples = self.configs(), self.samples()
            self.decisions()
        except sqlite3.DatabaseError as exc:
            raise storage_error(exc, self.path) or FormatError(
                f"{self.path}: damaged journal ({exc})"
            ) from None
        except (ValueError, TypeError) as exc:  # a row that is not what the journal writes
            raise FormatError(f"{self.path}: a row does not decode ({exc})") from None
        status = {c.idx: c.status for c in configs}
        stray = [s.idx for s in samples if status.get(s.idx) != "planned"]
        if stray:
            raise FormatError(
                f"{self.path}: {len(stray)} sample(s) without an accepted configuration "
                f"(first: index {stray[0]})"
            )

    # --- meta ---------------------------------------------------------------------------------
    @_writes
    def set_meta(self, items: dict[str, str]) -> None:
        with self._tx():
            self.db.executemany(
                "INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)", list(items.items())
            )

    def get_meta(self, key: str) -> str | None:
        try:
            row = self.db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        except sqlite3.DatabaseError:
            return None
        return row[0] if row else None

    def _tx(self):
        db = self.db

        class _T:
            def __enter__(self):
                db.execute("BEGIN IMMEDIATE")

            def __exit__(self, et, ev, tb):
                db.execute("COMMIT" if et is None else "ROLLBACK")

        return _T()

    # --- planning -----------------------------------------------------------------------------
    def stage_planned(self, stage: int) -> bool:
        return (
            self.db.execute("SELECT 1 FROM stages WHERE stage = ?", (stage,)).fetchone() is not None
        )

    def next_index(self) -> int:
        row = self.db.execute("SELECT COALESCE(MAX(idx), -1) + 1 FROM configs").fetchone()
        return int(row[0])

    @_writes
    def plan_stage(
        self, stage: int, configs: Sequence[PlannedConfig], decision: dict | None = None
    ) -> None:
        """Record a whole stage atomically (configs already carry idx and seq), with the plan's
        ``decision`` (JSON object) when it chose the stage from the measurements."""
        with self._tx():
            if decision is not None:
                self.db.execute(
                    "CREATE TABLE IF NOT EXISTS decisions(stage INTEGER PRIMARY KEY,"
                    " detail TEXT NOT NULL)"
                )
                self.db.execute(
                    "INSERT INTO decisions(stage, detail) VALUES (?, ?)",
                    (stage, dumps_json(decision)),
                )
            self.db.executemany(
                "INSERT INTO configs(idx, stage, seq, wi_x, wi_y, wi_z, wo_x, wo_y, wo_z,"
                " isotropic, joints, status, reason) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
                [
                    (
                        c.idx,
                        c.stage,
                        c.seq,
                        *c.wi,
                        *c.wo,
                        int(c.isotropic),
                        dumps_json(c.joints_deg) if c.joints_deg is not None else None,
                        c.status,
                        c.reason,
                    )
                    for c in configs
                ],
            )
            self.db.execute(
                "INSERT INTO stages(stage, n, planned_at) VALUES (?, ?, ?)",
                (stage, len(configs), time.time()),
            )

    def decisions(self) -> dict[int, dict]:
        """Stage -> the decision journaled with it ({} for a plan that decides nothing)."""
        try:
            rows = self.db.execute("SELECT stage, detail FROM decisions ORDER BY stage").fetchall()
        except sqlite3.OperationalError:  # a journal written before decisions existed
            return {}
        return {int(k): json.loads(d) for k, d in rows}

    def configs(self, stage: int | None = None) -> list[PlannedConfig]:
        q = (
            "SELECT idx, stage, seq, wi_x, wi_y, wi_z, wo_x, wo_y, wo_z, isotropic, joints,"
            " status, reason FROM configs"
        )
        args: tuple = ()
        if stage is not None:
            q += " WHERE stage = ?"
            args = (stage,)
        q += " ORDER BY stage, seq"
        return [_planned(r) for r in self.db.execute(q, args)]

    def pending(self, stage: int) -> list[PlannedConfig]:
        """Planned, not refused, not yet measured configurations of ``stage``, in order."""
        rows = self.db.execute(
            "SELECT c.idx, c.stage, c.seq, c.wi_x, c.wi_y, c.wi_z, c.wo_x, c.wo_y, c.wo_z,"
            " c.isotropic, c.joints, c.status, c.reason FROM configs c"
            " LEFT JOIN samples s ON s.idx = c.idx"
            " WHERE c.stage = ? AND c.status = 'planned' AND s.idx IS NULL ORDER BY c.seq",
            (stage,),
        )
        return [_planned(r) for r in rows]

    # --- samples ------------------------------------------------------------------------------
    @_writes
    def record(
        self,
        idx: int,
        joints_deg: dict[str, float],
        wi: Iterable[float],
        wo: Iterable[float],
        value: Iterable[float],
        sigma: Iterable[float],
        timings: dict[str, float],
        recoveries: int = 0,
    ) -> None:
        """Record one sample (single atomic INSERT; a second record of ``idx`` fails)."""
        self.db.execute(
            "INSERT INTO samples(idx, joints, wi_x, wi_y, wi_z, wo_x, wo_y, wo_z, value, sigma,"
            " t_motion, t_settle, t_capture, t_book, recoveries, captured_at)"
            " VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (
                idx,
                dumps_json(joints_deg),
                *map(float, wi),
                *map(float, wo),
                dumps_json([float(v) for v in value]),
                dumps_json([float(v) for v in sigma]),
                timings.get("motion", 0.0),
                timings.get("settle", 0.0),
                timings.get("capture", 0.0),
                timings.get("book", 0.0),
                recoveries,
                time.time(),
            ),
        )

    @_writes
    def reject(self, idx: int, reason: str) -> None:
        """Mark a planned configuration whose frame could not be measured as rejected (it is
        not retried on resume; :meth:`pending` skips it)."""
        self.db.execute(
            "UPDATE configs SET status = 'rejected', reason = ? WHERE idx = ? AND status ="
            " 'planned'",
            (reason, idx),
        )

    @_writes
    def set_book_time(self, idx: int, t_book: float) -> None:
        self.db.execute("UPDATE samples SET t_book = ? WHERE idx = ?", (t_book, idx))

    def samples(self, stage: int | None = None) -> list[SampleRow]:
        q = (
            "SELECT s.idx, s.joints, s.wi_x, s.wi_y, s.wi_z, s.wo_x, s.wo_y, s.wo_z, s.value,"
            " s.sigma, s.t_motion, s.t_settle, s.t_capture, s.t_book, s.recoveries"
            " FROM samples s JOIN configs c ON c.idx = s.idx"
        )
        args: tuple = ()
        if stage is not None:
            q += " WHERE c.stage = ?"
            args = (stage,)
        q += " ORDER BY s.idx"
        out = []
        for r in self.db.execute(q, args):
            out.append(
                SampleRow(
                    idx=r[0],
                    joints_deg=json.loads(r[1]),
                    wi=np.array(r[2:5]),
                    wo=np.array(r[5:8]),
                    value=np.array(json.loads(r[8]), dtype=float),  # null: NaN
                    sigma=np.array(json.loads(r[9]), dtype=float),
                    timings={"motion": r[10], "settle": r[11], "capture": r[12], "book": r[13]},
                    recoveries=r[14],
                )
            )
        return out

    # --- events -------------------------------------------------------------------------------
    def event(self, kind: str, detail: dict) -> None:
        """Record an event of the rig (a servo fault: its joints, bits, what was done, what to
        do next) with the time; the table is created by the first event, so journals written
        before it existed stay readable."""
        with self._tx():
            self.db.execute(
                "CREATE TABLE IF NOT EXISTS events(n INTEGER PRIMARY KEY, t REAL NOT NULL,"
                " kind TEXT NOT NULL, detail TEXT NOT NULL)"
            )
            self.db.execute(
                "INSERT INTO events(t, kind, detail) VALUES (?, ?, ?)",
                (time.time(), kind, dumps_json(detail, default=str)),
            )

    def events(self) -> list[tuple[float, str, dict]]:
        """``(time, kind, detail)`` of every event, in order ([] when there is none)."""
        try:
            rows = self.db.execute("SELECT t, kind, detail FROM events ORDER BY n").fetchall()
        except sqlite3.OperationalError:  # no event yet: no table
            return []
        return [(t, k, json.loads(d)) for t, k, d in rows]

    def counts(self) -> dict[str, int]:
        """``planned``: configurations the planner accepted (measured, pending or rejected);
        ``refused``: refused by the planner; ``rejected``: accepted but skipped because their
        frame could not be measured; ``done``: measured."""
        by = dict(self.db.execute("SELECT status, COUNT(*) FROM configs GROUP BY status"))
        done = self.db.execute("SELECT COUNT(*) FROM samples").fetchone()[0]
        rejected = int(by.get("rejected", 0))
        return {
            "planned": int(by.get("planned", 0)) + rejected,
            "refused": int(by.get("refused", 0)),
            "rejected": rejected,
            "done": done,
        }


def _planned(r) -> PlannedConfig:
    return PlannedConfig(
        idx=r[0],
        stage=r[1],
        seq=r[2],
        wi=(r[3], r[4], r[5]),
        wo=(r[6], r[7], r[8]),
        isotropic=bool(r[9]),
        joints_deg=json.loads(r[10]) if r[10] else None,
        status=r[11],
        reason=r[12],
    )
