"""The environment's hierarchical sampler: its density integrates to 1, is the one its samples
follow (chi-square at a stated significance level, fixed seeds), and is what it reports."""

from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy.stats import chi2

from gonio.brdf.sampling.quadtree import HierarchicalWarp2D
from gonio.errors import ParameterError
from gonio.render.lights import Environment, studio_environment

#: Significance level of each chi-square test (the chance that a correct sampler fails it).
ALPHA = 1e-3


def _weights(shape, seed):
    rng = np.random.default_rng(seed)
    w = rng.random(shape) ** 4  # a wide range of cell weights
    w[rng.random(shape) < 0.2] = 0.0  # and empty cells
    w.flat[0] = 1.0
    return w


def _studio_weights():
    img = studio_environment().astype(np.float64)
    h = img.shape[0]
    return img.mean(-1) * np.sin(np.pi * (np.arange(h) + 0.5) / h)[:, None]


SHAPES = [(1, 1), (1, 5), (3, 1), (6, 3), (16, 32), (33, 17)]


@pytest.mark.parametrize("shape", SHAPES)
def test_probabilities_sum_to_one_and_follow_the_weights(shape):
    w = _weights(shape, 1)
    warp = HierarchicalWarp2D(w)
    assert warp.probs.shape == shape
    assert abs(warp.probs.sum() - 1.0) < 1e-12
    # float32 splits: each level's probability is within ~6e-8 of the weights' ratio
    np.testing.assert_allclose(warp.probs, w / w.sum(), rtol=1e-5, atol=5e-7)
    assert np.all(warp.probs[w == 0] == 0)
    # the density integrates to 1 over the unit square (each cell has area 1 / (ny nx))
    ny, nx = shape
    y, x = np.meshgrid((np.arange(ny) + 0.5) / ny, (np.arange(nx) + 0.5) / nx, indexing="ij")
    dens = np.asarray(warp.pdf(np.stack([x, y], -1).astype(np.float32)), np.float64)
    assert abs(dens.sum() / (ny * nx) - 1.0) < 1e-6
    outside = np.array([[-0.1, 0.5], [0.5, 1.0], [1.0, 0.2]], np.float32)
    assert np.all(np.asarray(warp.pdf(outside)) == 0)


def _chi2_pvalue(counts, probs, n, min_expected=5.0):
    """Pearson's test of ``counts`` against ``n * probs``, cells with a small expectation
    pooled (in order of probability) until each pool expects at least ``min_expected``."""
    order = np.argsort(probs)
    e, c = probs[order] * n, counts[order]
    pools_e, pools_c, acc_e, acc_c = [], [], 0.0, 0.0
    for ei, ci in zip(e, c, strict=True):
        acc_e, acc_c = acc_e + ei, acc_c + ci
        if acc_e >= min_expected:
            pools_e.append(acc_e)
            pools_c.append(acc_c)
            acc_e = acc_c = 0.0
    if acc_e > 0 and pools_e:
        pools_e[-1] += acc_e
        pools_c[-1] += acc_c
    pe, pc = np.asarray(pools_e), np.asarray(pools_c)
    if pe.size < 2:
        return 1.0
    stat = float(np.sum((pc - pe) ** 2 / pe))
    return float(chi2.sf(stat, pe.size - 1))


@pytest.mark.parametrize("shape", [*SHAPES, "studio"])
def test_sample_frequencies_match_the_density(shape):
    w = _studio_weights() if shape == "studio" else _weights(shape, 2)
    warp = HierarchicalWarp2D(w)
    n = 400_000
    u = np.random.default_rng(3).random((n, 2)).astype(np.float32)
    xy, dens, cell = (np.asarray(a) for a in jax.jit(warp.sample)(u))
    assert np.all((xy >= 0) & (xy < 1))
    # every sample lies in the cell it reports, with that cell's density, as pdf() sees it
    np.testing.assert_array_equal(np.asarray(warp.cell_of(xy)), cell)
    np.testing.assert_array_equal(np.asarray(warp.pdf(xy)), dens)
    probs = warp.probs.reshape(-1)
    np.testing.assert_allclose(dens, probs[cell] * probs.size, rtol=1e-6)
    counts = np.bincount(cell, minlength=probs.size)
    assert counts[probs == 0].sum() == 0
    assert _chi2_pvalue(counts[probs > 0], probs[probs > 0], n) > ALPHA


def test_chi_square_detects_a_wrong_density():
    """The test above can fail: samples of one map against another's probabilities."""
    w = _weights((16, 32), 2)
    other = w.copy()
    other[:8] *= 1.05  # 5 % more weight in the top half
    u = np.random.default_rng(3).random((400_000, 2)).astype(np.float32)
    cell = np.asarray(jax.jit(HierarchicalWarp2D(w).sample)(u)[2])
    probs = HierarchicalWarp2D(other).probs.reshape(-1)
    counts = np.bincount(cell, minlength=probs.size)
    assert _chi2_pvalue(counts[probs > 0], probs[probs > 0], u.shape[0]) < ALPHA


def test_u_at_one_never_reaches_an_empty_cell():
    w = np.array([[1.0, 0.0], [0.0, 0.0]])  # every split has probability 1 on one side
    u = np.array([[1.0, 1.0], [0.0, 1.0], [1.0, 0.0], [0.0, 0.0]], np.float32)
    xy, dens, cell = HierarchicalWarp2D(w).sample(u)
    assert np.all(np.asarray(cell) == 0) and np.all(np.asarray(dens) == 4.0)
    assert np.all(np.asarray(xy) < 0.5)


def test_small_squares_of_u_land_in_compact_patches():
    """The point of the tree: a 1/8 x 1/8 square of u maps into a patch of a few cells in
    both axes (row-then-column inversion smears such a square along rows)."""
    warp = HierarchicalWarp2D(np.ones((64, 64)))
    g = (np.arange(64) + 0.5) / 64 / 8  # points inside the square [0, 1/8)^2 of u
    u = np.stack(np.meshgrid(g + 3 / 8, g + 5 / 8), -1).reshape(-1, 2).astype(np.float32)
    xy = np.asarray(warp.sample(u)[0])
    assert np.ptp(xy[:, 0]) <= 1 / 8 and np.ptp(xy[:, 1]) <= 1 / 8


def test_environment_samples_follow_its_pdf():
    env = Environment("studio").importance()
    u = np.random.default_rng(4).random((4096, 2)).astype(np.float32)
    p = np.zeros((4096, 3), np.float32)
    s = env.sample(p, u)
    pdf_again = np.asarray(env.pdf(p, s.wi))
    ok = np.asarray(s.pdf) > 0
    assert ok.mean() > 0.999
    assert np.mean(~np.isclose(pdf_again[ok], np.asarray(s.pdf)[ok], rtol=2e-3)) < 1e-3


@pytest.mark.parametrize(
    "w", [np.zeros((4, 4)), np.ones(5), -np.ones((2, 2)), np.full((2, 2), np.nan), "x"]
)
def test_bad_weights_raise_parameter_error(w):
    with pytest.raises(ParameterError):
        HierarchicalWarp2D(w)
