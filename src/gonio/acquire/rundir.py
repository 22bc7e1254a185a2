"""Run directories that are valid from their first byte.

A new run is built under a hidden temporary name next to ``RUN`` (``.RUN.start-XXXX``): its
journal is created with the schema and all of the run's metadata (rig file, plan, versions) in
one SQLite transaction, closed, and only then is the directory renamed to ``RUN``. A kill at any
moment therefore leaves either no ``RUN`` (start again with ``--out RUN``) or a ``RUN`` whose
journal names its rig and plan (continue with ``--resume RUN``). A start that fails before the
rig is ready (no serial port, a wrong servo, a bad camera) removes ``RUN`` again with
:func:`discard`; leftovers of a killed start are removed by the next start into the same ``RUN``.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path

from gonio.acquire.journal import Journal
from gonio.acquire.plans import Plan, plan_from_spec
from gonio.errors import FormatError, PlanError
from gonio.io.strict_json import dumps_json
from gonio.rigs.config import RigConfig, parse_rig


def _stale_prefix(run_dir: Path) -> str:
    return f".{run_dir.name}.start-"


def start_new(run_dir: Path, rig: RigConfig, plan_spec: dict, meta: dict[str, str]) -> bool:
    """Create run directory ``run_dir`` with its journal; return whether it existed (empty).

    ``meta`` adds to the recorded metadata. PlanError if ``run_dir`` exists and is not an empty
    directory.
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
        # rename(2) replaces an empty directory atomically, and fails on a non-empty one
        tmp.replace(run_dir)
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


def _umask() -> int:
    import os

    mask = os.umask(0)
    os.umask(mask)
    return mask
