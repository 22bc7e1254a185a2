"""A damaged journal is refused before a resumed run opens the bus (nothing moves)."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from gonio.acquire.engine import acquire
from gonio.acquire.journal import Journal
from gonio.errors import FormatError

PLAN = 'kind = "isotropic"\ntheta_i_deg = [30]\ntheta_o_deg = [45, 60]\ndphi_deg = [180]\n'


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("journal")
    (d / "plan.toml").write_text(PLAN)
    s = acquire(d / "run", "sim_sample", d / "plan.toml", progress=False, write_table=False)
    assert s.complete and s.done == 2
    j = Journal(d / "run")  # the WAL checkpointed into the file: damage below reaches it
    j.db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    j.close()
    return d / "run"


class _Opened(Exception):
    pass


def _no_devices(rig, run_dir):
    raise _Opened  # the bus would open here: the journal passed its checks


def _sql(statement: str):
    def damage(run: Path) -> None:
        db = sqlite3.connect(run / "journal.sqlite")
        db.execute(statement)
        db.commit()
        db.close()

    return damage


def _overwrite(run: Path) -> None:
    path = run / "journal.sqlite"
    data = bytearray(path.read_bytes())
    # random bytes over the inside of every page after the schema's (a disk fault, not a
    # truncation): the b-trees no longer parse
    rng = np.random.default_rng(0)
    for start in range(4096 + 8, len(data), 4096):
        data[start : start + 2000] = rng.integers(0, 256, 2000, np.uint8).tobytes()
    path.write_bytes(bytes(data))


def _truncate(run: Path) -> None:
    path = run / "journal.sqlite"
    path.write_bytes(path.read_bytes()[:-700])


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (_sql("UPDATE samples SET value = 'garbage' WHERE idx = 0"), "a row does not decode"),
        (_sql("UPDATE configs SET joints = '{bad' WHERE idx = 1"), "a row does not decode"),
        (_sql("DROP TABLE samples"), "damaged journal"),
        (_sql("UPDATE configs SET status = 'refused' WHERE idx = 1"), "without an accepted"),
        (_sql("UPDATE meta SET value = '{x' WHERE key = 'plan_spec'"), "plan does not decode"),
        (_overwrite, "not a usable journal"),
        (_truncate, "damaged journal"),
    ],
)
def test_damaged_journal_is_refused_before_the_bus_opens(finished_run, tmp_path, damage, message):
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    with pytest.raises(_Opened):  # undamaged, the resume goes as far as the devices
        acquire(run, resume=True, progress=False, open_devices=_no_devices)
    damage(run)
    with pytest.raises(FormatError) as exc:
        acquire(run, resume=True, progress=False, open_devices=_no_devices)
    text = str(exc.value)
    assert message in text and "journal.sqlite" in text and "\n" not in text, text
