"""Filled tables in *.brdf.h5: the extrapolation at invalid nodes is kept (``/mask`` attribute
``invalid_values = "extrapolated"``), other tables store zeros there, older files still load."""

from __future__ import annotations

import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from gonio.brdf import gridding
from gonio.brdf.measured import MeasuredSamples
from gonio.brdf.models import Lambert
from gonio.brdf.tabulated import Axis, TabulatedBRDF
from gonio.errors import FormatError
from gonio.io import load, native, save

EXAMPLES = Path(__file__).resolve().parents[2] / "data-schema" / "examples"


def _table(filled: bool, seed: int = 0) -> TabulatedBRDF:
    n = (12, 10, 8)
    axes = (
        Axis("theta_h", n[0], 0.0, math.pi / 2, "sqrt", False, 0.0),
        Axis("theta_d", n[1], 0.0, math.pi / 2, "linear", False, 0.0),
        Axis("phi_d", n[2], 0.0, math.pi, "linear", True, 0.0),
    )
    rng = np.random.default_rng(seed)
    values = np.exp(rng.normal(-1.0, 1.0, (*n, 3))).astype(np.float32)
    return TabulatedBRDF(values, axes, mask=rng.random(n) > 0.4, filled=filled)


def _mask_attr(path: Path) -> str | None:
    with h5py.File(path, "r") as f:
        v = f["mask"].attrs.get("invalid_values")
    return v.decode() if isinstance(v, bytes) else v


def test_a_filled_table_keeps_its_extrapolation(tmp_path):
    t = _table(filled=True)
    p = tmp_path / "f.brdf.h5"
    save(t, p)
    r = load(p)
    assert r.filled and _mask_attr(p) == "extrapolated"
    assert np.array_equal(r.mask, t.mask) and np.array_equal(r.values, t.values)
    assert native.read_header(p)["grid"]["invalid_values"] == "extrapolated"
    rng = np.random.default_rng(1)
    wi, wo = (rng.normal(size=(200, 3)) for _ in range(2))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    # lookups still ignore the invalid nodes
    assert np.array_equal(np.asarray(r.f(wi, wo)), np.asarray(t.f(wi, wo)))
    # a lossy write quantizes them like the valid ones (within its bound)
    q = tmp_path / "q.brdf.h5"
    save(t, q, lossy=0.01)
    lv = load(q).values[~t.mask].astype(np.float64)
    ref = t.values[~t.mask].astype(np.float64)
    assert load(q).filled and np.max(np.abs(lv - ref) / ref) <= 0.01 * (1 + 1e-5)


def test_other_tables_store_zeros_at_invalid_nodes(tmp_path):
    t = _table(filled=False)
    p = tmp_path / "z.brdf.h5"
    save(t, p)
    r = load(p)
    assert not r.filled and _mask_attr(p) == "zero"
    assert np.all(r.values[~t.mask] == 0) and np.array_equal(r.values[t.mask], t.values[t.mask])
    # a filled table without invalid nodes has nothing to declare
    full = _table(filled=True).replace(mask=None)
    save(full, tmp_path / "full.brdf.h5")
    assert _mask_attr(tmp_path / "full.brdf.h5") == "zero"


def test_files_without_the_attribute_load_as_before(tmp_path):
    old = EXAMPLES / "tiny-gridded.brdf.h5"  # committed before the attribute existed
    assert _mask_attr(old) is None
    assert not load(old).filled
    assert native.read_header(old)["grid"]["invalid_values"] == "zero"
    p = tmp_path / "f.brdf.h5"
    save(_table(filled=True), p)
    with h5py.File(p, "r+") as f:
        del f["mask"].attrs["invalid_values"]
    assert not load(p).filled


@pytest.mark.parametrize("edit", ["unknown", "nan"])
def test_bad_invalid_values_are_refused_in_one_line(tmp_path, edit):
    t = _table(filled=True)
    p = tmp_path / "b.brdf.h5"
    save(t, p)
    with h5py.File(p, "r+") as f:
        if edit == "unknown":
            f["mask"].attrs["invalid_values"] = "garbage"
        else:
            i, j, k = np.argwhere(~t.mask)[0]
            f["values"][i, j, k, 0] = np.nan
    with pytest.raises(FormatError) as exc:
        load(p)
    msg = str(exc.value)
    assert str(p) in msg and "\n" not in msg
    assert ("invalid_values" if edit == "unknown" else "/values") in msg, msg


def test_a_filled_table_needs_finite_values_everywhere():
    t = _table(filled=False)
    values = np.array(t.values)
    values[~t.mask] = np.nan
    assert not TabulatedBRDF(values, t.axes, mask=t.mask).filled  # fine unfilled
    with pytest.raises(FormatError, match="filled"):
        TabulatedBRDF(values, t.axes, mask=t.mask, filled=True)


def test_the_scattered_interpolant_is_filled():
    rng = np.random.default_rng(3)
    wi, wo = (rng.normal(size=(300, 3)) for _ in range(2))
    for w in (wi, wo):
        w[:, 2] = np.abs(w[:, 2]) + 0.3  # a limited part of the hemisphere: a coverage edge
        w /= np.linalg.norm(w, axis=-1, keepdims=True)
    vals = np.asarray(Lambert(albedo=[0.5, 0.4, 0.3]).f(wi, wo))
    t = gridding.interpolate_samples(MeasuredSamples(wi, wo, vals), gridding.default_grid(8, 8, 6))
    assert t.filled and not t.mask.all() and np.all(np.isfinite(t.values))
    assert t.replace(interpolation="nearest").filled
