"""Defects of the second hostile-files round (issue #45) outside the RGL and fit-JSON readers,
one constructed input each, run through the ``gonio`` console script where the issue showed
them there: memory bounded by what the input means (checked before allocating), one line on
stderr and a non-zero exit for input that cannot be right, never a traceback."""

from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np
import pytest

from gonio import io
from gonio.errors import FormatError
from tests import console_script
from tests.fuzz.corpus import _half_diff_table


def _one_line_refusal(proc, path: Path, match: str) -> None:
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr[-800:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gonio: ") and str(path.name) in lines[0], lines
    assert re.search(match, lines[0]), lines[0]


def _refused(path: Path, match: str) -> None:
    with pytest.raises(FormatError, match=match) as info:
        io.load(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


# ------------------------------------------------------------------------------------- MERL
def _merl(path: Path, dims: tuple[int, int, int], fill: float = 0.5) -> Path:
    n = int(np.prod(dims))
    path.write_bytes(struct.pack("<3i", *dims) + np.full(3 * n, fill, "<f8").tobytes())
    return path


def test_merl_grid_beyond_a_measured_grid_is_refused_from_its_header(tmp_path):
    """1.5 MB declaring 1 x 1 x 65536 cells: ``gonio convert T.binary out.exr`` reached 3.0
    GiB writing 65,536 one-cell slices. Each axis is bounded at 4 times MERL's resolution."""
    p = _merl(tmp_path / "T.binary", (1, 1, 65536))
    assert p.stat().st_size < 2 << 20
    proc = console_script.run("convert", p, tmp_path / "out.exr")
    _one_line_refusal(proc, p, r"MERL dimensions \(1, 1, 65536\) beyond .* \(360, 360, 720\)")
    assert not (tmp_path / "out.exr").exists()
    # within each axis' bound, over the cells' one: refused from the header alone
    q = tmp_path / "cells.binary"
    q.write_bytes(struct.pack("<3i", 360, 360, 46))
    _refused(q, r"5832000 in all")
    _merl(q, (360, 360, 46))
    _refused(q, r"more than the 139968012 a file of this kind may have")  # before reading


def test_merl_grid_at_the_bounds_loads(tmp_path):
    from gonio.io.merl import MAX_DIMS

    t = io.load(_merl(tmp_path / "thin.binary", (1, 1, MAX_DIMS[2])))
    assert t.values.shape == (1, 1, 720, 3) and bool(np.all(t.mask))


def test_merl_file_with_a_negated_channel_is_refused(tmp_path):
    """Negative values mark unmeasured cells, in all three channels; a red channel negated
    everywhere left the cells where red was exactly 0 (or an invalid -1, now +1) and loaded
    without a word."""
    p = tmp_path / "neg.binary"
    io.save(_half_diff_table((5, 5, 10), 8), p)
    d = p.read_bytes()
    raw = np.frombuffer(d, "<f8", offset=12).copy().reshape(3, -1)
    assert np.array_equal(raw[0] < 0, raw[1] < 0)  # the writer marks all three channels
    raw[0] = -raw[0]
    p.write_bytes(d[:12] + raw.tobytes())
    _refused(p, r"MERL channel R is negative at \d+ of the \d+ cells the other channels measured")
    raw[0, :] = np.abs(raw[0])
    raw[0, ::1000] = -1.0  # a few cells marked in one channel only: kept as invalid cells
    p.write_bytes(d[:12] + raw.tobytes())
    t = io.load(p)
    assert 0 < np.count_nonzero(t.mask) < t.mask.size
