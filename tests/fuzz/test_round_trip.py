"""What gonio writes, gonio reads (issue #45): every writer applies its reader's checks before
writing, and the fuzz suite's round-trip oracle (:func:`tests.fuzz.worker.round_trip`) proves
it on every loaded case. Here: constructed inputs that gonio reads but whose conversion its
reader refused (through the console script), the oracle catching a writer that skips the
checks, and the resampling writers (MERL from another grid, RGL tensor files) on the corpus."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from gonio import io
from tests import console_script
from tests.fuzz.corpus import _half_diff_table, _samples
from tests.fuzz.worker import Lie, round_trip


def _table(n: tuple[int, int, int], seed: int, edit=None):
    """A corpus table with ``edit(values, sigma)`` applied (a table's arrays are read-only)."""
    from gonio.brdf.tabulated import TabulatedBRDF

    t = _half_diff_table(n, seed)
    values, sigma = np.array(t.values), np.array(t.sigma)
    if edit is not None:
        edit(values, sigma)
    return TabulatedBRDF(values=values, axes=t.axes, parameterization=t.parameterization,
                         mask=t.mask, sigma=sigma, channels=t.channels, meta=t.meta)  # fmt: skip


def _refused_on_write(proc, out: Path, match: str) -> None:
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr[-800:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gonio: ") and out.name in lines[0], lines
    assert re.search(match, lines[0]), lines[0]
    assert not out.exists() and not list(out.parent.glob(f".{out.name}*"))


def test_lossy_convert_never_writes_a_value_its_reader_refuses(tmp_path):
    """A table with a value just under the 1e10 1/sr bound: ``gonio convert --lossy 1%`` wrote
    a file whose decoded value lay beyond it, and ``gonio info`` refused the file."""
    t = _table((6, 6, 12), 1, lambda v, s: v.__setitem__((2, 3, 4), 9.99e9))
    src = tmp_path / "peak.brdf.h5"
    io.save(t, src)
    console_script.assert_clean(console_script.run("info", src))  # the input is readable
    out = tmp_path / "lossy.brdf.h5"
    proc = console_script.run("convert", src, out, "--lossy", "1%")
    _refused_on_write(proc, out, r"/values: value 1(\.\d+)?e\+10 is beyond any reflectance")
    # lossless, the same table converts and reads back
    ok = tmp_path / "plain.brdf.h5"
    console_script.assert_clean(console_script.run("convert", src, ok))
    console_script.assert_clean(console_script.run("info", ok))


def test_merl_convert_never_writes_a_channel_its_reader_refuses(tmp_path):
    """A table whose red channel is slightly negative (within the readers' 1 % noise
    tolerance) everywhere: as MERL, every red value is MERL's "unmeasured" marker, which the
    MERL reader refuses as a negated channel; the writer now refuses it first."""
    t = _table((90, 90, 180), 2, lambda v, s: v.__setitem__((..., 0), -1e-3))  # cell for cell
    src = tmp_path / "redneg.brdf.h5"
    io.save(t, src)
    console_script.assert_clean(console_script.run("info", src))
    out = tmp_path / "redneg.binary"
    proc = console_script.run("convert", src, out)
    _refused_on_write(proc, out, r"MERL channel R is negative")


@pytest.mark.parametrize(
    "suffix, hostile, match",
    [
        (".brdf.h5", "beyond", r"/values: value 2e\+10 is beyond"),
        (".brdf.h5", "sigma", r"/sigma: value 2e\+10 is beyond"),
        (".exr", "beyond", r"slice values: value 2e\+10 is beyond"),
        (".brdf.h5", "horizon", r"/wi: 1 direction\(s\) below the horizon"),
    ],
)
def test_writers_refuse_what_their_readers_refuse(tmp_path, suffix, hostile, match):
    """In memory, objects no reader returns: each writer refuses them in one line, nothing
    written (the native writer checked finiteness only, the EXR writer nothing)."""
    from gonio.errors import FormatError

    if hostile == "horizon":
        from gonio.brdf.measured import MeasuredSamples

        s = _samples(20, 1)
        wi = np.array(s.wi)
        wi[3, 2] = -abs(wi[3, 2])
        obj = MeasuredSamples(wi=wi, wo=s.wo, values=s.values, channels=s.channels)
    elif hostile == "beyond":
        obj = _table((6, 6, 4), 3, lambda v, s: v.__setitem__((1, 1, 1, 0), 2e10))
    else:
        obj = _table((6, 6, 4), 3, lambda v, s: s.__setitem__((1, 1, 1, 0), 2e10))
    out = tmp_path / f"x{suffix}"
    with pytest.raises(FormatError, match=match) as info:
        io.save(obj, out)
    assert str(out) in str(info.value) and "\n" not in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_round_trip_oracle_fails_a_writer_that_skips_its_readers_checks(tmp_path, monkeypatch):
    """The fuzz suite's oracle is not vacuous: with the native writer's check removed, a table
    the writer then writes and the reader refuses is a failure of the case (a Lie)."""
    import gonio.io.native as native

    case = tmp_path / "case.brdf.h5"
    assert round_trip(_table((6, 6, 4), 4), str(case)).startswith("round trip: 3 written")
    t = _table((6, 6, 4), 4, lambda v, s: v.__setitem__((0, 0, 0, 0), 3e10))
    assert "3 refused" in round_trip(t, str(case))
    check = native.check_table_arrays  # shared by reader and writer: skip it in the writer only

    def reader_only(*args, **kwargs):
        if sys._getframe(1).f_code.co_name not in ("_write_gridded", "_write_scattered"):
            check(*args, **kwargs)

    monkeypatch.setattr(native, "check_table_arrays", reader_only)
    with pytest.raises(Lie, match=r"case-trip.brdf.h5, as gonio wrote it, is refused"):
        round_trip(t, str(case))
    assert not list(tmp_path.glob("case-trip*"))


@pytest.mark.slow
def test_round_trip_resampling_writers_on_the_corpus(tmp_path):
    """The writers too slow for every fuzz case (seconds each): MERL from another grid and the
    RGL tensor-file writer, on a gridded corpus table; a scattered one is refused by both
    (about 30 s: slow run only)."""
    from gonio.io.rgl_measured import RGLMeasured

    t = _half_diff_table((6, 6, 12), 5)
    case = tmp_path / "grid.brdf.h5"
    writers = [(".binary", {}), (".bsdf", {})]
    assert round_trip(t, str(case), writers).startswith("round trip: 2 written")
    assert "2 refused" in round_trip(_samples(50, 6), str(case), writers)
    io.save(t, tmp_path / "t.bsdf")
    assert isinstance(io.load(tmp_path / "t.bsdf"), RGLMeasured)
