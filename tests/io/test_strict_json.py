"""Strict JSON everywhere gonio prints or writes JSON (issue #45): one writer,
:mod:`gonio.io.strict_json`; NaN/Inf written as null with a reason, or refused."""

from __future__ import annotations

import ast
import json
import math
from pathlib import Path

import numpy as np
import pytest

import gonio
from gonio.errors import FormatError
from gonio.io.strict_json import NONFINITE_KEY, dumps_json, write_json

SRC = Path(gonio.__file__).parent


def _strict(text: str):
    def refuse(token: str):
        raise ValueError(f"non-strict JSON token {token}")

    return json.loads(text, parse_constant=refuse)


def test_no_json_writer_outside_strict_json():
    """Every ``json.dump``/``json.dumps`` call of gonio is the one in gonio.io.strict_json (a
    new writer that calls json directly fails here)."""
    found = []
    for path in sorted(SRC.rglob("*.py")):
        if path == SRC / "io" / "strict_json.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr in ("dump", "dumps")
                and isinstance(node.func.value, ast.Name)
                and node.func.value.id == "json"
            ):
                found.append(f"{path.relative_to(SRC)}:{node.lineno}")
    assert not found, f"JSON written without gonio.io.strict_json: {found}"


def test_null_with_reason_or_refused(tmp_path):
    out = _strict(dumps_json({"a": [1.0, np.float32("nan")], "b": np.array([np.inf])}))
    assert out == {
        "a": [1.0, None],
        "b": [None],
        NONFINITE_KEY: {"a[1]": "NaN", "b[0]": "Infinity"},
    }
    with pytest.raises(FormatError, match=r"^x.json: a\[1\] is NaN; JSON has no NaN"):
        dumps_json({"a": [1.0, math.nan]}, nonfinite="refuse", source="x.json")
    with pytest.raises(FormatError, match=r"out.json: loss is -Infinity"):
        write_json({"loss": -math.inf}, tmp_path / "out.json")
    assert list(tmp_path.iterdir()) == []  # nothing written, no temporary left


def test_mitsuba_scene_dict_refuses_a_nan():
    """Mitsuba's load_dict file holds numbers a renderer reads: a NaN is refused, not
    written as NaN (Python's json) or null."""
    from gonio.export import mitsuba
    from gonio.export._lobes import Lobes

    ok = mitsuba.build("m", Lobes(channels=3, diffuse=np.array([0.5, 0.4, 0.3]), specular=None))
    assert _strict(ok.files[".json"])
    with pytest.raises(FormatError, match=r"m.json: .* is NaN"):
        mitsuba.build("m", Lobes(channels=3, diffuse=np.array([0.5, math.nan, 0.3]), specular=None))


def test_native_metadata_nan_written_as_null_and_read_back(tmp_path):
    """A table's provenance with a NaN: the file's metadata attribute is strict JSON (null,
    listed under nonfinite_as_null; it was the string "nan"), and gonio reads it back."""
    import h5py

    from gonio import io
    from gonio.brdf import models
    from gonio.brdf.tabulated import TabulatedBRDF, default_axes

    t = TabulatedBRDF.from_model(models.Lambert(0.5), axes=default_axes("half_diff_iso", 4, 4, 8))
    t.meta = {"source": {"gain": math.nan, "peak": [1.0, math.inf]}}
    p = tmp_path / "t.brdf.h5"
    io.save(t, p)
    with h5py.File(p, "r") as h5:
        meta = _strict(h5.attrs["metadata"])
    assert meta["source"]["gain"] is None
    assert meta[NONFINITE_KEY] == {"source.gain": "NaN", "source.peak[1]": "Infinity"}
    assert io.load(p).meta["source"]["gain"] is None


def test_journal_stores_nan_as_null_and_reads_it_back_as_nan(tmp_path):
    from gonio.acquire.journal import Journal, PlannedConfig

    (tmp_path / "run").mkdir()
    j = Journal(tmp_path / "run", create=True)
    try:
        j.plan_stage(0, [PlannedConfig(0, 0, 0, (0, 0, 1), (0, 0, 1), True, None, "planned", None)])
        j.record(0, {"a": 1.0}, (0, 0, 1), (0, 0, 1), [1.0, math.nan, 2.0], [0.1, 0.1, math.inf],
                 {})  # fmt: skip
        raw = j.db.execute("SELECT value, sigma FROM samples").fetchone()
        assert [_strict(x) for x in raw] == [[1.0, None, 2.0], [0.1, 0.1, None]]
        (row,) = j.samples()
        assert np.isnan(row.value[1]) and row.value.dtype == np.float64
        assert np.isnan(row.sigma[2])
    finally:
        j.close()
