"""Native *.brdf.h5: round trips, lossy bounds, partial reads, atomic writes, bad files, schema."""

from __future__ import annotations

import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from gonio.brdf.measured import MeasuredSamples
from gonio.brdf.tabulated import Axis, Channels, TabulatedBRDF
from gonio.errors import FormatError, ParameterError
from gonio.io import load, native, save
from tests.io.corrupt import assert_clean, variants

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "data-schema" / "examples"


def _table(n=(16, 12, 20), seed=0, channels=None, extras=True):
    axes = (
        Axis("theta_h", n[0], 0.0, math.pi / 2, "sqrt", False, 0.0),
        Axis("theta_d", n[1], 0.0, math.pi / 2, "linear", False, 0.0),
        Axis("phi_d", n[2], 0.0, math.pi, "linear", True, 0.0),
    )
    rng = np.random.default_rng(seed)
    c = 3 if channels is None else len(channels)
    values = np.exp(rng.normal(-1.0, 1.5, (*n, c))).astype(np.float32)
    mask = rng.random(n) > 0.25
    return TabulatedBRDF(
        values=values,
        axes=axes,
        parameterization="half_diff_iso",
        mask=mask,
        sigma=(0.05 * values) if extras else None,
        counts=rng.integers(0, 9, n) if extras else None,
        channels=channels,
        meta={"rig": {"name": "sim"}, "plan": "p1", "calibration": {"k": [1, 2]}, "x": 1.5},
        interpolation="nearest",
    )


def test_gridded_round_trip_is_exact(tmp_path):
    t = _table()
    p = tmp_path / "t.brdf.h5"
    save(t, p)
    r = load(p)
    assert isinstance(r, TabulatedBRDF)
    assert r.axes == t.axes and r.parameterization == t.parameterization
    assert r.interpolation == "nearest" and r.channels == t.channels
    assert np.array_equal(r.mask, t.mask)
    m = t.mask
    assert np.array_equal(r.values[m], t.values[m]) and np.all(r.values[~m] == 0)
    assert np.array_equal(r.sigma[m], t.sigma[m]) and np.array_equal(r.counts, t.counts)
    assert r.meta["rig"] == {"name": "sim"} and r.meta["calibration"] == {"k": [1, 2]}


def test_spectral_and_scattered_round_trip(tmp_path):
    wl = np.array([400.0, 500.0, 600.0, 700.0])
    t = _table(channels=Channels.spectral(wl), extras=False)
    save(t, tmp_path / "s.brdf.h5")
    r = load(tmp_path / "s.brdf.h5")
    assert r.channels == t.channels and r.sigma is None and r.counts is None
    rng = np.random.default_rng(2)
    wi = rng.normal(size=(50, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    s = MeasuredSamples(
        wi=wi,
        wo=wi[::-1],
        values=rng.random((50, 3)),
        sigma=None,
        channels=Channels.rgb(),
        weights=rng.random(50),
        meta={"a": "b"},
    )
    save(s, tmp_path / "m.brdf.h5")
    q = load(tmp_path / "m.brdf.h5")
    assert isinstance(q, MeasuredSamples)
    np.testing.assert_allclose(q.wi, s.wi, rtol=1e-15, atol=1e-15)
    np.testing.assert_array_equal(q.weights, s.weights)
    np.testing.assert_allclose(q.values, s.values, rtol=1e-7)  # stored float32
    assert q.meta == {"a": "b"}


@pytest.mark.parametrize("precision", [0.002, 0.01, 0.05])
def test_lossy_error_bound_holds_and_is_recorded(tmp_path, precision):
    t = _table(n=(20, 16, 30), seed=4)
    p = tmp_path / "l.brdf.h5"
    report = native.write_native(t, p, lossy=precision)
    r = load(p)
    h = native.read_header(p)
    enc = h["encoding"]
    assert enc["values"] == "log-quantized-delta"
    assert enc["bound_relative"] == pytest.approx(precision, rel=1e-9)
    v, d, m = t.values.astype(np.float64), r.values.astype(np.float64), t.mask
    sel = m[..., None] & (v >= enc["floor"])
    rel = np.abs(d[sel] - v[sel]) / v[sel]
    assert rel.max() <= precision * (1 + 1e-5)  # float32 decode rounding on top of the bound
    # achieved statistics recomputed independently match the recorded ones
    assert enc["achieved"]["median_relative"] == pytest.approx(np.median(rel), rel=1e-3)
    assert enc["achieved"]["max_relative"] == pytest.approx(rel.max(), rel=1e-3)
    assert report["achieved"] == enc["achieved"]
    assert np.all(d[~np.broadcast_to(m[..., None], d.shape)] == 0)


def test_lossy_decoding_formula_from_format_md(tmp_path):
    """Decode the raw integers with the documented formula, without gonio's decoder."""
    t = _table(n=(10, 8, 12), seed=5)
    p = tmp_path / "l.brdf.h5"
    save(t, p, lossy=0.01)
    with h5py.File(p, "r") as f:
        ds = f["values"]
        z = ds[()].astype(np.int64)
        a = {k: ds.attrs[k] for k in ("log_offset", "log_step", "delta_axis")}
    d = (z >> 1) ^ -(z & 1)
    q = np.cumsum(d, axis=int(a["delta_axis"]))
    v = np.where(q > 0, np.exp(a["log_offset"] + (q - 1) * a["log_step"]), 0.0)
    np.testing.assert_allclose(v, load(p).values, rtol=1e-6)


def test_partial_reads_take_rows_and_channels_from_their_own_chunks(tmp_path):
    t = _table(n=(40, 60, 90), seed=6)
    for lossy in (None, 0.01):
        p = tmp_path / f"p{lossy}.brdf.h5"
        save(t, p, lossy=lossy)
        full = load(p).values
        part = native.read_values(p, rows=slice(7, 19), channel=2)
        np.testing.assert_array_equal(part, full[7:19, ..., 2:3])
        with h5py.File(p, "r") as f:
            chunks = f["values"].chunks
            assert chunks[-1] == 1 and chunks[0] < 40 and chunks[1:-1] == (60, 90)
            assert f["values"].compression == "gzip" and f["values"].shuffle


def test_atomic_write_leaves_nothing_on_a_crash(tmp_path):
    t = _table()
    p = tmp_path / "a.brdf.h5"

    class Boom(RuntimeError):
        pass

    def hook(stage):
        if stage == "values":
            raise Boom(stage)

    with pytest.raises(Boom):
        native.write_native(t, p, _hook=hook)
    assert list(tmp_path.iterdir()) == []
    # an existing file survives a failed overwrite untouched
    save(t, p)
    before = p.read_bytes()
    with pytest.raises(Boom):
        native.write_native(t, p, _hook=hook)
    assert p.read_bytes() == before and sorted(x.name for x in tmp_path.iterdir()) == [p.name]


def _edit(path: Path, fn) -> None:
    with h5py.File(path, "r+") as f:
        fn(f)


def _nan_at_a_valid_cell(f) -> None:
    i, j, k = np.argwhere(f["mask"][()])[0]
    f["values"][i, j, k, 0] = np.nan


def test_bad_native_files(tmp_path):
    t = _table()
    good = tmp_path / "g.brdf.h5"
    save(t, good)
    edits = {
        "version": lambda f: f.attrs.__setitem__("format_version", 2),
        "format": lambda f: f.attrs.__setitem__("format", "other"),
        "kind": lambda f: f.attrs.__setitem__("kind", "cloud"),
        "units": lambda f: f.attrs.__setitem__("units", "W"),
        "meta": lambda f: f.attrs.__setitem__("metadata", "{not json"),
        "axis": lambda f: f["axes/theta_d"].attrs.__setitem__("size", 13),
        "warp": lambda f: f["axes/theta_d"].attrs.__setitem__("warp", "cubic"),
        "mask": lambda f: f.__delitem__("mask"),
        "nan": _nan_at_a_valid_cell,
    }
    for name, fn in edits.items():
        p = tmp_path / f"{name}.brdf.h5"
        p.write_bytes(good.read_bytes())
        _edit(p, fn)
        with pytest.raises(FormatError) as exc:
            load(p)
        msg = str(exc.value)
        assert str(p) in msg and "\n" not in msg, (name, msg)
    with pytest.raises(FormatError, match="format_version 2"):
        load(tmp_path / "version.brdf.h5")
    with pytest.raises(FormatError, match="directory"):
        load(tmp_path)
    with pytest.raises(FormatError, match="no such file"):
        load(tmp_path / "missing.brdf.h5")
    with pytest.raises(ParameterError):
        save(t, tmp_path / "x.unknown")


def test_corrupted_native_files_fail_cleanly(tmp_path):
    src = EXAMPLES / "tiny-gridded.brdf.h5"
    outcomes = []
    for what, p in variants(src, tmp_path, n_flips=20):

        def sane(t, what=what):
            v = np.asarray(t.values)[np.asarray(t.mask)]
            assert np.all(np.isfinite(v)), what

        outcomes.append(assert_clean(load, p, what, sane))
        p.unlink()
    assert outcomes.count("error") >= len(outcomes) // 2


def test_examples_load_and_match_the_schema():
    import jsonschema

    schema = json.loads((ROOT / "data-schema" / "table-metadata.schema.json").read_text())
    for name, cls in (("tiny-gridded", TabulatedBRDF), ("tiny-scattered", MeasuredSamples)):
        p = EXAMPLES / f"{name}.brdf.h5"
        assert isinstance(load(p), cls)
        jsonschema.validate(native.read_header(p), schema)
    bad = native.read_header(EXAMPLES / "tiny-gridded.brdf.h5")
    bad["grid"]["axes"][0]["warp"] = "cubic"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)


def test_hdf5_c_tools_read_the_documented_layout(tmp_path):
    """The HDF5 C library's own tools (no h5py) see the layout FORMAT.md describes."""
    import shutil
    import subprocess

    if shutil.which("h5ls") is None:
        pytest.skip("HDF5 command-line tools (h5ls) not installed")
    p = tmp_path / "t.brdf.h5"
    save(_table(n=(40, 60, 90), seed=9), p, lossy=0.01)
    out = subprocess.run(
        ["h5ls", "-v", f"{p}/values"], capture_output=True, text=True, check=True
    ).stdout
    assert "Chunks:    {" in out and ", 60, 90, 1}" in out
    assert "shuffle" in out and "deflate" in out and "unsigned short" in out
    out = subprocess.run(
        ["h5ls", "-r", str(EXAMPLES / "tiny-gridded.brdf.h5")],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    for name in ("/axes/theta_h/nodes", "/channels", "/mask", "/values", "/sigma", "/counts"):
        assert name in out
