"""MERL nearest lookup returns the reference reader's cell (BRDFRead.cpp), bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf import frames
from gonio.io import load, merl

NH, ND, NP = 90, 90, 180


# ---- the reference reader, transcribed to Python from its published description ------------
def _rotate(v, axis, angle):
    c, s = math.cos(angle), math.sin(angle)
    out = [v[k] * c for k in range(3)]
    t = (axis[0] * v[0] + axis[1] * v[1] + axis[2] * v[2]) * (1.0 - c)
    out = [out[k] + axis[k] * t for k in range(3)]
    cross = (
        axis[1] * v[2] - axis[2] * v[1],
        axis[2] * v[0] - axis[0] * v[2],
        axis[0] * v[1] - axis[1] * v[0],
    )
    return [out[k] + cross[k] * s for k in range(3)]


def _normalize(v):
    n = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
    return [x / n for x in v]


def _vec(theta, phi):
    return _normalize([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                       math.cos(theta)])  # fmt: skip


def reference_cell(theta_in, fi_in, theta_out, fi_out) -> int:
    """Flat cell index of ``lookup_brdf_val``: half/diff by rotations, then the bins."""
    a, b = _vec(theta_in, fi_in), _vec(theta_out, fi_out)
    half = _normalize([(a[k] + b[k]) / 2.0 for k in range(3)])
    theta_half = math.acos(half[2])
    fi_half = math.atan2(half[1], half[0])
    tmp = _rotate(a, (0.0, 0.0, 1.0), -fi_half)
    diff = _rotate(tmp, (0.0, 1.0, 0.0), -theta_half)
    theta_diff = math.acos(diff[2])
    fi_diff = math.atan2(diff[1], diff[0])
    # theta_half_index
    if theta_half <= 0.0:
        ih = 0
    else:
        ih = int(math.sqrt(theta_half / (math.pi / 2.0) * NH * NH))
        ih = min(max(ih, 0), NH - 1)
    # theta_diff_index
    idd = int(theta_diff / (math.pi * 0.5) * ND)
    idd = min(max(idd, 0), ND - 1)
    # phi_diff_index
    if fi_diff < 0.0:
        fi_diff += math.pi
    ip = int(fi_diff / math.pi * 360 / 2)
    ip = min(max(ip, 0), NP - 1)
    return ip + idd * NP + ih * NP * ND


def _angles(w):
    return math.acos(min(max(w[2], -1.0), 1.0)), math.atan2(w[1], w[0])


# ---- probes -----------------------------------------------------------------------------------
def _random_probes(rng, n):
    """Random pairs over the hemisphere, including grazing ones (theta up to 89.99 deg)."""

    def theta():
        grazing = rng.uniform(math.radians(85), math.radians(89.99), n // 4)
        return np.concatenate([np.arccos(rng.random(n)), grazing])

    th = theta()
    m = th.size
    ph = rng.uniform(-math.pi, math.pi, m)
    th2 = theta()
    ph2 = rng.uniform(-math.pi, math.pi, m)
    return np.stack([th, ph, th2[:m], ph2], -1)


def _edge_probes(rng, n, delta):
    """Pairs whose half/diff angles sit ``delta`` (in cell units of the warped index) on either
    side of a cell edge on one axis (cycling through the axes), random on the others."""
    x = np.stack(
        [rng.uniform(0.02, 0.98, n) * NH, rng.uniform(0.02, 0.98, n) * ND, rng.uniform(0, NP, n)],
        -1,
    )
    axis = np.arange(n) % 3
    edge = rng.integers(1, np.array([NH, ND, NP])[axis])
    side = np.where(np.arange(n) % 2 == 1, delta, -delta)
    x[np.arange(n), axis] = edge + side
    th = (x[:, 0] / NH) ** 2 * math.pi / 2
    td = x[:, 1] / ND * math.pi / 2
    pd = x[:, 2] / NP * math.pi + np.where(rng.random(n) < 0.5, math.pi, 0.0)  # both halves
    ph = rng.uniform(-math.pi, math.pi, n)
    wi, wo = (np.asarray(w) for w in frames.half_diff_to_directions(th, ph, td, pd))
    keep = (wi[:, 2] > 1e-6) & (wo[:, 2] > 1e-6)
    wi, wo = wi[keep], wo[keep]
    ang = [np.arccos(np.clip(w[:, 2], -1, 1)) for w in (wi, wo)]
    return np.stack(
        [ang[0], np.arctan2(wi[:, 1], wi[:, 0]), ang[1], np.arctan2(wo[:, 1], wo[:, 0])], -1
    )


def _directions(p):
    def v(t, f):
        return np.stack([np.sin(t) * np.cos(f), np.sin(t) * np.sin(f), np.cos(t)], -1)

    return v(p[:, 0], p[:, 1]), v(p[:, 2], p[:, 3])


@pytest.fixture(scope="module")
def random_table(tmp_path_factory):
    rng = np.random.default_rng(20)
    values = rng.uniform(0.01, 5.0, (NH, ND, NP, 3))
    mask = np.ones((NH, ND, NP), bool)
    mask[rng.integers(0, NH, 200), rng.integers(0, ND, 200), rng.integers(0, NP, 200)] = False
    p = tmp_path_factory.mktemp("merl") / "random.binary"
    p.write_bytes(merl.merl_bytes(values, mask))
    return p, merl.read_merl_arrays(p)


def _check(table, arrays, probes):
    wi, wo = _directions(probes)
    got = np.asarray(table.f(wi, wo))
    flat = np.array([reference_cell(*row) for row in probes])
    valid = arrays.mask.reshape(-1)[flat]
    # the reference returns the stored value times the scale; the table stores float32
    expect = arrays.values.reshape(-1, 3)[flat].astype(np.float32)
    agree = np.all(got[valid] == expect[valid], axis=-1)
    return agree, valid


def test_nearest_lookup_is_the_reference_cell_on_random_directions(random_table):
    path, arrays = random_table
    table = load(path)
    assert table.interpolation == "nearest"
    rng = np.random.default_rng(1)
    probes = _random_probes(rng, 20000)
    wi, wo = _directions(probes)
    # the probes cover phi_d < 0 and grazing directions
    phi_d = np.mod(np.asarray(frames.half_diff(wi, wo)[3]), 2 * math.pi)
    assert np.mean(phi_d > math.pi) > 0.3  # the reference's phi_d < 0, folded by + pi
    assert np.mean(probes[:, 0] > math.radians(85)) > 0.1
    agree, valid = _check(table, arrays, probes)
    assert valid.mean() > 0.95
    assert agree.all(), f"{(~agree).sum()} of {agree.size} disagree"


@pytest.mark.parametrize("delta", [1e-6, 1e-8])
def test_nearest_lookup_is_the_reference_cell_next_to_cell_edges(random_table, delta):
    """Within 1e-8 of a cell width of an edge on every axis. (Closer than about 2e-9, at the
    first theta_h edge, the reference's own ``acos(h_z)`` rounding decides the side: it is
    accurate to ~1e-12 rad there, where a cell is 2e-4 rad wide.)"""
    path, arrays = random_table
    table = load(path)
    probes = _edge_probes(np.random.default_rng(2), 6000, delta)
    agree, _ = _check(table, arrays, probes)
    assert agree.all(), f"{(~agree).sum()} of {agree.size} disagree"


def test_the_old_cell_start_rounding_was_half_a_cell_off(random_table):
    """``cells="start"`` (fastmerl / NBRDF nodes) rounds to the closest lower edge: it finds the
    reference cell for only a fraction of directions (about 1/8: one half per axis)."""
    path, arrays = random_table
    table = load(path, merl_cells="start")
    probes = _random_probes(np.random.default_rng(3), 4000)
    agree, valid = _check(table, arrays, probes)
    assert 0.05 < agree[valid].mean() < 0.3


def test_cell_positions_are_centres_in_the_warped_index(random_table):
    path, _ = random_table
    t = load(path)
    th, td, pd = (a.nodes() for a in t.axes)
    np.testing.assert_allclose(th[:3], ((np.arange(3) + 0.5) / NH) ** 2 * math.pi / 2)
    np.testing.assert_allclose(td[[0, 45]], (np.array([0, 45]) + 0.5) / ND * math.pi / 2)
    np.testing.assert_allclose(pd[[0, 90]], (np.array([0, 90]) + 0.5) / NP * math.pi)
    s = load(path, merl_cells="start")
    np.testing.assert_allclose(s.axes[0].nodes()[:3], (np.arange(3) / NH) ** 2 * math.pi / 2)
    # the node of each cell is inside the reference's cell
    wi, wo = (w.reshape(-1, 3) for w in t.node_directions())
    idx = np.random.default_rng(4).choice(wi.shape[0], 3000, replace=False)
    ok = (wi[idx, 2] > 1e-3) & (wo[idx, 2] > 1e-3)
    for j in idx[ok][:1500]:
        cell = reference_cell(*_angles(wi[j]), *_angles(wo[j]))
        assert cell == j


def test_linear_interpolation_is_between_cell_centres(tmp_path):
    """A table linear in the warped theta_d index: at cell centres the linear lookup equals
    the cell value; halfway between two centres it is their mean."""
    vals = np.zeros((NH, ND, NP, 3))
    vals[...] = (np.arange(ND, dtype=np.float64)[None, :, None, None] + 1.0) * 0.01
    p = tmp_path / "lin.binary"
    p.write_bytes(merl.merl_bytes(vals))
    t = load(p).replace(interpolation="linear")
    th, pd = 0.3, 0.7
    for x, expect in ((10.5, 11.0), (11.0, 11.5)):
        wi, wo = frames.half_diff_to_directions(th, 0.0, x / ND * math.pi / 2, pd)
        np.testing.assert_allclose(np.asarray(t.f(wi, wo))[0], expect * 0.01, rtol=1e-5)


def test_bad_cell_convention_is_refused(random_table):
    from gonio.errors import ParameterError

    with pytest.raises(ParameterError):
        load(random_table[0], merl_cells="middle")
