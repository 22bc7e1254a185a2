"""The mapped space and the grid (gonio.prior.space)."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from gonio.brdf import frames
from gonio.prior import space
from tests.prior.conftest import SMALL_AXES


def test_mapping_round_trip_and_sigma():
    rng = np.random.default_rng(0)
    f = rng.uniform(0, 50, size=(100, 3))
    cc = rng.uniform(0.01, 1, size=100)
    m = space.to_mapped(f, cc)
    np.testing.assert_allclose(space.from_mapped(m, cc), f, rtol=1e-10)
    np.testing.assert_allclose(m, np.log(f * cc[:, None] + space.EPSILON))
    # delta method both ways is the identity
    s = space.sigma_to_mapped(f, 0.1 * f, cc)
    np.testing.assert_allclose(space.sigma_from_mapped(m, s, cc), 0.1 * f, rtol=1e-10)


def test_half_diff_matches_frames_folded():
    rng = np.random.default_rng(1)
    wi = rng.normal(size=(200, 3))
    wo = rng.normal(size=(200, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    th, td, pd = space.half_diff_angles(wi, wo)
    ref = frames.half_diff(jnp.asarray(wi), jnp.asarray(wo))
    np.testing.assert_allclose(th, np.asarray(ref[0]), atol=1e-5)
    np.testing.assert_allclose(td, np.asarray(ref[2]), atol=1e-5)
    p = np.mod(np.asarray(ref[3], np.float64), math.pi)
    np.testing.assert_allclose(pd, np.minimum(p, math.pi - p), atol=1e-4)


def test_nodes_weigh_only_themselves_and_horizon_is_masked():
    mask = space.valid_mask(SMALL_AXES)
    wi, wo = space.grid_directions(SMALL_AXES)
    flat = np.flatnonzero(mask.reshape(-1))
    cells, w = space.interpolation_weights(SMALL_AXES, mask, wi[flat], wo[flat])
    top = np.argmax(w, axis=1)
    np.testing.assert_array_equal(cells[np.arange(flat.size), top], flat)
    np.testing.assert_allclose(w.max(axis=1), 1.0, atol=1e-6)
    assert not mask.reshape(-1)[(wi[:, 2] <= 0) | (wo[:, 2] <= 0)].any()
    # the default grid coincides with MERL's centre nodes (every second theta_d and phi_d)
    from gonio.io.merl import merl_axes

    full = space.prior_axes()
    th, td, pd = merl_axes()
    np.testing.assert_allclose(full[0].nodes(), th.nodes())
    np.testing.assert_allclose(full[1].nodes(), td.nodes()[::2])
    np.testing.assert_allclose(full[2].nodes(), pd.nodes()[:90:2])
