"""Run tables: binning scattered samples onto a half/diff grid, reciprocal pairs, /gridded group."""

import math

import numpy as np
import pytest

from gonio.acquire.table import default_grid, grid_samples, half_diff_iso, reciprocal_pairs
from gonio.brdf.measured import MeasuredSamples
from gonio.brdf.tabulated import Channels
from gonio.errors import FormatError
from gonio.io.native import read_native, write_native


def _dirs(rng, n):
    th = np.arccos(rng.uniform(0.2, 1.0, n))
    ph = rng.uniform(0, 2 * np.pi, n)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)


def _samples(n=400, seed=0):
    rng = np.random.default_rng(seed)
    wi, wo = _dirs(rng, n), _dirs(rng, n)
    values = rng.uniform(0.1, 1.0, (n, 3))
    sigma = rng.uniform(0.01, 0.05, (n, 3))
    return MeasuredSamples(wi, wo, values, sigma, Channels.rgb(), meta={"source": "test"})


def test_grid_is_the_inverse_variance_mean_of_each_cell():
    s = _samples()
    t = grid_samples(s)
    axes = default_grid()
    th, td, pd = half_diff_iso(s.wi, s.wo)
    idx = tuple(np.asarray(a.nearest_index(x)) for a, x in zip(axes, (th, td, pd), strict=True))
    assert int(np.asarray(t.counts).sum()) == len(s)
    # pick the fullest cell and recompute it by hand
    cell = np.unravel_index(int(np.argmax(t.counts)), t.mask.shape)
    sel = np.all([i == c for i, c in zip(idx, cell, strict=True)], axis=0)
    w = 1 / s.sigma[sel] ** 2
    np.testing.assert_allclose(t.values[cell], (w * s.values[sel]).sum(0) / w.sum(0), rtol=1e-6)
    np.testing.assert_allclose(t.sigma[cell], 1 / np.sqrt(w.sum(0)), rtol=1e-6)
    # empty cells are invalid, never zero-valued data
    assert t.mask.sum() == np.count_nonzero(t.counts)
    assert not t.mask.all()


def test_phi_d_is_folded_by_reciprocity():
    s = _samples(50)
    _, _, pd = half_diff_iso(s.wi, s.wo)
    _, _, pd_swapped = half_diff_iso(s.wo, s.wi)
    assert np.all((pd >= 0) & (pd < math.pi))
    np.testing.assert_allclose(pd, pd_swapped, atol=1e-9)


def test_reciprocal_pairs_are_found_and_compared():
    def d(theta, phi):
        t, p = math.radians(theta), math.radians(phi)
        return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])

    targets = {
        0: (d(20, 0), d(45, 180)),
        1: (d(45, 0), d(20, 180)),  # the swap of 0
        2: (d(30, 0), d(30, 90)),  # its own reciprocal
        3: (d(20, 0), d(60, 90)),  # no partner
    }
    measured = {
        0: (np.array([1.0, 2.0]), np.array([0.1, 0.1])),
        1: (np.array([1.1, 2.0]), np.array([0.1, 0.1])),
        2: (np.array([1.0, 1.0]), None),
        3: (np.array([1.0, 1.0]), None),
    }
    pairs = reciprocal_pairs(targets, measured)
    assert [(p.a, p.b) for p in pairs] == [(0, 1)]
    np.testing.assert_allclose(pairs[0].rel_diff, [0.1 / 1.05, 0.0])
    np.testing.assert_allclose(pairs[0].z, [-0.1 / math.sqrt(0.02), 0.0])


def test_native_file_holds_samples_and_the_gridded_table(tmp_path):
    s = _samples()
    t = grid_samples(s)
    p = tmp_path / "table.brdf.h5"
    write_native(s, p, groups={"gridded": t})
    back = read_native(p)
    assert isinstance(back, MeasuredSamples) and len(back) == len(s)
    g = read_native(p, group="gridded")
    np.testing.assert_array_equal(g.mask, t.mask)
    np.testing.assert_allclose(np.asarray(g.sigma), np.asarray(t.sigma))
    with pytest.raises(FormatError, match="no table group"):
        read_native(p, group="nope")
