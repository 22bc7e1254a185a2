"""A fit folder holds one run: staged beside it, then swapped in as a whole.

``gonio fit FILE --out OUT`` (and each material folder of a batch) writes every file of the run
into a hidden sibling folder ``.OUT.partial-*`` and, once all are written, replaces ``OUT`` by it
(:func:`gonio.io.atomic.replace_folder`): a rerun never leaves the previous run's plots or JSON
beside the new ones, and a rerun that fails or is interrupted before the swap leaves the previous
run as it was (its staging folder is removed). A folder is a run when it holds ``summary.json``;
``OUT`` may be missing, empty or a run, never a folder of other files (which a swap would
delete). What the libraries said while the run was written (plotting warnings) goes to the run's
``log.txt``, not to the terminal.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from gonio.errors import ParameterError, StorageError
from gonio.io.atomic import current_umask, replace_folder
from gonio.io.storage import storage_error

#: The file that marks a folder as one finished fit run.
MARKER = "summary.json"
#: The run's log of library messages.
LOG = "log.txt"


def check_target(out: Path) -> None:
    """Refuse an ``--out`` folder that holds files but no fit run (before any work).

    Raises
    ------
    ParameterError
        ``out`` is a file, or a non-empty folder without :data:`MARKER`.
    """
    if out.exists() and not out.is_dir():
        raise ParameterError(f"--out {out}: exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not (out / MARKER).is_file():
        raise ParameterError(
            f"--out {out}: holds files that are not a gonio fit run (no {MARKER}); a run "
            "replaces its folder as a whole, so give an empty or new folder"
        )


def previous_run(out: Path) -> list[str] | None:
    """The models of the run in ``out`` (None when there is none)."""
    try:
        prev = json.loads((out / MARKER).read_text())
    except (OSError, ValueError):
        return None if not out.is_dir() or not any(out.iterdir()) else []
    rows = prev.get("table") if isinstance(prev, dict) else None
    return [str(r.get("model")) for r in rows or [] if isinstance(r, dict)]


@contextlib.contextmanager
def staging(out: Path) -> Iterator[Path]:
    """A hidden, empty sibling folder of ``out`` to write a run into; removed on the way out
    (after :func:`publish` it no longer exists)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        folder = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    except OSError as exc:  # named after the folder asked for, not the staging one
        raise storage_error(exc, out) or OSError(exc.errno, exc.strerror, str(out)) from None
    folder.chmod(0o777 & ~current_umask())  # the mode a plain mkdir gives (mkdtemp: 0o700)
    try:
        yield folder
    except StorageError as exc:  # named after the folder asked for, not the staging one
        err = StorageError(str(exc).replace(str(folder), str(out)))
        err.errno = exc.errno
        raise err from None
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def publish(folder: Path, out: Path, log: list[str]) -> str | None:
    """Write the ``log`` lines (when any) to the run's :data:`LOG` and swap ``folder`` in as
    ``out``. Returns the one line to tell the user when an earlier run was replaced, else
    None."""
    if log:
        (folder / LOG).write_text("\n".join(log) + "\n", encoding="utf-8")
    before = previous_run(out)
    n_old = sum(1 for _ in out.iterdir()) if out.is_dir() else 0
    if not replace_folder(folder, out) or before is None:
        return None
    models = ", ".join(before) or "unknown models"
    return f"{out}: replaced the previous run ({models}; {n_old} files)"
