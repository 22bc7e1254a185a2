"""Issue 44, full disk for every output: whatever library writes it (HDF5, OpenEXR, PNG, JSON,
HTML, text), an output that does not fit — a full filesystem (a small tmpfs, skipped where
mounting is refused) or a file-size limit (RLIMIT_FSIZE, EFBIG) — is one StorageError naming
the file and its filesystem, and leaves no file behind; the commands print it as one line with
exit status 5."""

from __future__ import annotations

import errno
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf import models
from gonio.brdf.measured import MeasuredSamples
from gonio.brdf.tabulated import Channels
from gonio.cli import main
from gonio.errors import StorageError
from gonio.io.storage import storage_errno, storage_error
from tests.export.conftest import fit_record, write_record
from tests.small_fs import file_size_limit, fill, small_tmpfs


def test_storage_errors_are_recognised_however_reported(tmp_path):
    assert storage_errno(OSError(errno.ENOSPC, "No space left on device")) == errno.ENOSPC
    assert storage_errno(OSError(errno.EDQUOT, "Disk quota exceeded")) == errno.EDQUOT
    assert storage_errno(sqlite3.OperationalError("database or disk is full")) == errno.ENOSPC
    assert storage_errno(sqlite3.OperationalError("disk I/O error")) == errno.EIO
    # OpenEXR: only the system's text inside a RuntimeError
    exr = RuntimeError('Failed to write pixel data to image file "x.exr". File too large.')
    assert storage_errno(exr) == errno.EFBIG
    try:  # raised while handling one
        try:
            raise OSError(errno.EROFS, "Read-only file system")
        except OSError:
            raise ValueError("could not save") from None
    except ValueError as exc:
        assert storage_errno(exc) is None  # `from None` hides it on purpose
    chained = ValueError("could not save")
    chained.__cause__ = OSError(errno.EROFS, "Read-only file system")
    assert storage_errno(chained) == errno.EROFS
    assert storage_errno(ValueError("bad number")) is None
    assert storage_errno(OSError(errno.EACCES, "Permission denied")) is None
    err = storage_error(OSError(errno.ENOSPC, ""), tmp_path / "x.h5")
    assert isinstance(err, OSError) and err.errno == errno.ENOSPC
    assert str(err).startswith(f"{tmp_path / 'x.h5'}: no space left on device on the filesystem")


def _samples() -> MeasuredSamples:
    rng = np.random.default_rng(0)
    th, ph = np.arccos(rng.uniform(0.2, 1, (2, 300))), rng.uniform(0, 2 * np.pi, (2, 300))
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    vals = rng.uniform(0.1, 1.0, (300, 3))
    return MeasuredSamples(d[0], d[1], vals, 0.05 * vals, Channels.rgb(), meta={"name": "t"})


def _writers():
    """name -> write(folder): every kind of output gonio writes, each larger than 4 kB."""
    from gonio import io
    from gonio.demo import report
    from gonio.io.exr import write_exr
    from gonio.io.fit_result import write_json
    from gonio.render.output import write_png

    img = np.random.default_rng(1).random((64, 64, 3)).astype(np.float32)

    def html(folder):
        original = report.render_html
        report.render_html = lambda summary: "<!DOCTYPE html>\n" + "<p>x</p>\n" * 1000
        try:
            report.write_report(folder / "index.html", None)
        finally:
            report.render_html = original

    return {
        "hdf5": lambda folder: io.save(_samples(), folder / "t.brdf.h5"),
        "exr": lambda folder: write_exr(folder / "i.exr", img, ["R", "G", "B"]),
        "png": lambda folder: write_png(folder / "i.png", img),
        "json": lambda folder: write_json({"a": "x" * 9000}, folder / "f.json"),
        "html": html,
    }


WRITERS = ["hdf5", "exr", "png", "json", "html"]


@pytest.mark.parametrize("kind", WRITERS)
def test_an_output_over_the_file_size_limit_leaves_nothing(tmp_path, kind):
    write = _writers()[kind]
    with file_size_limit(4096), pytest.raises(StorageError) as info:
        write(tmp_path)
    assert info.value.errno == errno.EFBIG and "file too large" in str(info.value)
    assert "ulimit -f" in str(info.value) and str(tmp_path) in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_outputs_on_a_full_filesystem_leave_nothing(tmp_path):
    with small_tmpfs(tmp_path / "mnt", "256k") as mnt:
        filler = fill(mnt)
        for kind, write in _writers().items():
            with pytest.raises(StorageError) as info:
                write(mnt)
            msg = str(info.value)
            assert "no space left on device" in msg and f"the filesystem at {mnt} (tmpfs" in msg
            assert [p.name for p in mnt.iterdir()] == ["filler"], kind
        filler.unlink()


def _command(name: str, folder: Path, out: Path) -> list[str]:
    from gonio import io

    table = folder / "t.brdf.h5"
    io.save(_samples(), table)
    fit = write_record(folder / "fit.json", fit_record(models.Lambert(albedo=[0.5, 0.4, 0.3])))
    return {
        "convert": ["convert", str(table), str(out / "c.brdf.h5")],
        "export": ["export", str(fit), "--to", "mitsuba", "--out", str(out / "m.xml")],
        "grid": ["grid", str(table), str(out / "g.brdf.h5")],
        "plot": ["plot", str(table), "--out", str(out / "p.png")],
        "fit": ["fit", str(table), "-m", "lambert", "--uncertainty", "none",
                "--out", str(out / "f")],
        "render": ["render", "--fitted", str(fit), "--resolution", "16", "--spp", "1",
                   "--out", str(out / "r.png")],
    }[name]  # fmt: skip


# the others take seconds to compute what they write: the writers above cover them fast
SLOW = ("grid", "plot", "fit", "render")
COMMANDS = ["convert", "export", *(pytest.param(c, marks=pytest.mark.slow) for c in SLOW)]


@pytest.mark.parametrize("name", COMMANDS)
def test_a_command_whose_output_does_not_fit_prints_one_line(tmp_path, capsys, name):
    with small_tmpfs(tmp_path / "mnt", "256k") as mnt:
        argv = _command(name, tmp_path, mnt)
        filler = fill(mnt)
        capsys.readouterr()
        assert main(argv) == 5
        err = capsys.readouterr().err.lstrip("\n")  # fit's progress display ends in a newline
        assert err.startswith(f"gonio: {mnt}/") and err.count("\n") == 1, err
        assert "no space left on device" in err and "Traceback" not in err, err
        assert [p.name for p in Path(mnt).iterdir()] == ["filler"]
        filler.unlink()
