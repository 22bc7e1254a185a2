"""MERL .binary: exact layout, scales, invalid cells, phi_d folding, atomic write, corruption."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from gonio.errors import FormatError
from gonio.io import load, merl, save
from tests.io.corrupt import assert_clean, variants

N = 90 * 90 * 180


def _handmade(cells: dict[tuple[int, int, int], tuple[float, float, float]]) -> bytes:
    """A MERL file built from the published layout, independently of gonio's writer."""
    raw = np.full((3, N), 1.0)
    for (ih, id_, ip), rgb in cells.items():
        idx = ip + 180 * (id_ + 90 * ih)
        for c in range(3):
            raw[c, idx] = rgb[c]
    return struct.pack("<3i", 90, 90, 180) + raw.astype("<f8").tobytes()


def test_layout_and_scales_follow_the_published_format(tmp_path):
    p = tmp_path / "m.binary"
    p.write_bytes(_handmade({(3, 40, 100): (1500.0, 1500.0, 1500.0), (0, 0, 0): (-1, 2, 2)}))
    a = merl.read_merl_arrays(p)
    assert a.values.shape == (90, 90, 180, 3)
    np.testing.assert_allclose(a.values[3, 40, 100], [1.0, 1.15, 1.66], rtol=1e-12)
    np.testing.assert_allclose(a.values[5, 5, 5], [1 / 1500, 1.15 / 1500, 1.66 / 1500])
    assert not a.mask[0, 0, 0] and a.mask.sum() == N - 1  # a negative channel -> invalid


def test_table_axes_are_merl_bins(tmp_path):
    p = tmp_path / "m.binary"
    p.write_bytes(_handmade({}))
    t = load(p)
    # README: theta_h bin edges (i/90)^2 pi/2; theta_d i/90 pi/2; phi_d i/180 pi; the default
    # nodes sit at the cells' centres (tests/io/test_merl_cells.py)
    th, td, pd = (a.nodes() for a in load(p, merl_cells="start").axes)
    np.testing.assert_allclose(th[:4], (np.arange(4) / 90) ** 2 * math.pi / 2)
    np.testing.assert_allclose(td[[0, 45]], [0, math.pi / 4])
    np.testing.assert_allclose(pd[[0, 90]], [0, math.pi / 2])
    assert t.parameterization == "half_diff_iso" and t.channels.kind == "rgb"


def test_bin_lookup_formula_recovers_each_cell(tmp_path):
    """Evaluate at directions inside a cell; the README's bin formula gives the same cell."""
    rng = np.random.default_rng(3)
    cells = {
        (int(rng.integers(5, 80)), int(rng.integers(5, 80)), int(rng.integers(5, 170))): (
            float(v),
            float(v),
            float(v),
        )
        for v in rng.uniform(100, 900, 6)
    }
    p = tmp_path / "m.binary"
    p.write_bytes(_handmade(cells))
    a = merl.read_merl_arrays(p)
    for (ih, id_, ip), v in cells.items():
        th = ((ih + 0.5) / 90) ** 2 * math.pi / 2
        td = (id_ + 0.5) / 90 * math.pi / 2
        pd = (ip + 0.5) / 180 * math.pi
        # README bins
        bh = min(max(int(math.sqrt(th / (math.pi / 2)) * 90), 0), 89)
        bd = int(td / (math.pi / 2) * 90)
        bp = int(pd / math.pi * 180)
        assert (bh, bd, bp) == (ih, id_, ip)
        assert a.values[bh, bd, bp, 0] == pytest.approx(v[0] / 1500)


def test_phi_d_folding_by_reciprocity(tmp_path):
    """phi_d and phi_d + pi are the same cell: the table gives equal values at both."""
    from gonio.brdf import frames

    vals = np.zeros((90, 90, 180, 3))
    vals[..., 0] = np.linspace(0.1, 1.0, 180)  # varies with phi_d only
    vals[..., 1:] = 0.5
    p = tmp_path / "m.binary"
    p.write_bytes(merl.merl_bytes(vals))
    t = load(p)
    th, td, pd = 0.3, 0.4, 0.7
    a = frames.half_diff_to_directions(th, 0.0, td, pd)
    b = frames.half_diff_to_directions(th, 0.0, td, pd + math.pi)
    fa = np.asarray(t.f(*a))
    fb = np.asarray(t.f(*b))
    np.testing.assert_allclose(fa, fb, rtol=1e-5)


def test_roundtrip_and_resampling_write(tmp_path):
    from gonio.brdf.models import Lambert

    rng = np.random.default_rng(0)
    vals = rng.uniform(0.01, 2.0, (90, 90, 180, 3))
    mask = rng.random((90, 90, 180)) > 0.2
    p = tmp_path / "a.binary"
    p.write_bytes(merl.merl_bytes(vals, mask))
    t = load(p)
    assert np.array_equal(t.mask, mask)
    np.testing.assert_allclose(t.values[mask], vals[mask], rtol=1e-6)
    # write the table back: identical bytes
    q = tmp_path / "b.binary"
    save(t, q)
    back = merl.read_merl_arrays(q)
    assert np.array_equal(back.mask, mask)
    np.testing.assert_allclose(back.values[mask], vals[mask], rtol=1e-6)
    # resampling an analytic model: Lambert gives albedo/pi at every valid cell
    r = tmp_path / "lambert.binary"
    merl.write_merl(Lambert(albedo=[0.2, 0.4, 0.6]), r)
    lam = merl.read_merl_arrays(r)
    np.testing.assert_allclose(
        lam.values[lam.mask], np.tile([0.2, 0.4, 0.6], (lam.mask.sum(), 1)) / math.pi, rtol=1e-12
    )
    assert 0.5 < lam.mask.mean() < 0.95


def test_a_merl_like_grid_of_another_resolution_is_written_at_merls(tmp_path):
    # MERL's reference reader refuses any dimensions but 90 x 90 x 180: a coarser table on the
    # same warped axes (gonio grid's default 16 x 15 x 12) is resampled, not written as is
    from gonio.brdf.tabulated import TabulatedBRDF

    rgb = np.array([0.05, 0.1, 0.2])
    axes = merl.merl_axes((16, 15, 12))
    t = TabulatedBRDF(np.broadcast_to(rgb, (16, 15, 12, 3)).copy(), axes, "half_diff_iso")
    p = tmp_path / "coarse.binary"
    save(t, p)
    assert struct.unpack("<3i", p.read_bytes()[:12]) == (90, 90, 180)
    a = merl.read_merl_arrays(p)
    assert 0.5 < a.mask.mean() < 0.95  # the cells with both directions above the horizon
    np.testing.assert_allclose(a.values[a.mask], np.tile(rgb, (a.mask.sum(), 1)), rtol=1e-6)


def test_bad_merl_files(tmp_path):
    good = _handmade({})
    cases = {
        "short": good[:7],
        "dims": struct.pack("<3i", 90, -90, 180) + good[12:],
        "huge": struct.pack("<3i", 1 << 20, 90, 180) + good[12:],
        "trailing": good + b"\0" * 8,
        "nan": good[:12] + np.full(3 * N, np.nan).tobytes(),
    }
    for name, data in cases.items():
        p = tmp_path / f"{name}.binary"
        p.write_bytes(data)
        with pytest.raises(FormatError) as exc:
            merl.read_merl(p)
        assert str(p) in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(FormatError, match="directory"):
        load(tmp_path)


def test_corrupted_merl_files_fail_cleanly(tmp_path):
    src = tmp_path / "src.binary"
    rng = np.random.default_rng(1)
    src.write_bytes(merl.merl_bytes(rng.uniform(0, 1, (90, 90, 180, 3))))
    outcomes = set()
    for what, p in variants(src, tmp_path, n_flips=8):

        def sane(t, what=what):
            v = np.asarray(t.values)[np.asarray(t.mask)]
            assert np.all(np.isfinite(v)) and np.all(v >= 0), what

        # truncations go through format detection; flips parse the arrays (no table build)
        if what.startswith("truncated"):
            outcomes.add(assert_clean(load, p, what, sane))
        else:
            outcomes.add(assert_clean(merl.read_merl_arrays, p, what, sane))
        p.unlink()
    assert "error" in outcomes  # truncations must be caught
