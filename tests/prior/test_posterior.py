"""Reconstruction and the choice of configurations on a prior with a known basis."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.errors import ParameterError
from gonio.prior import space
from tests.prior.conftest import in_span, synthetic_prior


def _candidates(prior):
    return prior.cell_directions()


def test_choose_makes_the_system_full_rank_and_is_deterministic(prior):
    wi, wo = _candidates(prior)
    idx = prior.choose(wi, wo, 3)  # 3 samples x 3 channels = 9 rows >= rank 6
    assert len(set(idx.tolist())) == 3
    A = prior.observe(wi[idx], wo[idx]).design.reshape(-1, prior.rank)
    assert np.linalg.matrix_rank(A) == prior.rank
    np.testing.assert_array_equal(idx, prior.choose(wi, wo, 3))
    # batch by batch: the second batch is chosen after the first, never repeating it
    more = prior.choose(wi, wo, 2, measured=(wi[idx], wo[idx]))
    assert not set(more.tolist()) & set(idx.tolist())


def test_in_span_table_is_reconstructed_exactly(prior):
    c, m = in_span(prior)
    wi, wo = _candidates(prior)
    idx = prior.choose(wi, wo, 4)
    f = space.from_mapped(m, space.cos_product(wi, wo))
    r = prior.reconstruct(wi[idx], wo[idx], f[idx])
    assert np.abs(r.mapped - m).max() <= 1e-6 * np.abs(m).max()
    np.testing.assert_allclose(r.coefficients, c, rtol=1e-6, atol=1e-9)
    assert r.predicted_error < 1e-3 and r.n_used == 4 and r.n_dropped == 0
    t = r.table
    assert t.meta["sigma_correlated"] and t.sigma is not None
    assert len(t.meta["reconstruction"]["coefficients"]) == prior.rank


def test_posterior_narrows_with_samples_and_sigma_counts(prior):
    wi, wo = _candidates(prior)
    _, m = in_span(prior)
    f = space.from_mapped(m, space.cos_product(wi, wo))
    idx = prior.choose(wi, wo, 2)
    e0 = prior.predicted_error()
    e1 = prior.predicted_error((wi[idx[:1]], wo[idx[:1]]))
    e2 = prior.predicted_error((wi[idx], wo[idx]))
    assert e0 > e1 > e2
    noisy = prior.reconstruct(wi[idx], wo[idx], f[idx], 0.5 * f[idx])
    exact = prior.reconstruct(wi[idx], wo[idx], f[idx])
    assert np.trace(noisy.covariance) > np.trace(exact.covariance)
    # a reconstruction is an accepted "measured" and gives the same covariance as the samples
    np.testing.assert_allclose(prior.predicted_error(exact), e2, rtol=1e-6)
    red = prior.variance_reduction(wi[:50], wo[:50], measured=exact)
    assert red.shape == (50,) and (red >= -1e-12).all()


def test_bad_samples_are_dropped_or_refused(prior):
    wi, wo = _candidates(prior)
    below = wi[:3].copy()
    below[:, 2] *= -1
    with pytest.raises(ParameterError, match="no usable samples"):
        prior.reconstruct(below, wo[:3], np.ones((3, 3)))
    with pytest.raises(ParameterError, match=r"\(n, 3\)"):
        prior.reconstruct(wi[:3], wo[:3], np.ones((3, 2)))
    vals = np.ones((4, 3))
    vals[0, 1] = np.nan
    assert prior.reconstruct(wi[:4], wo[:4], vals).n_dropped == 1
    with pytest.raises(ParameterError, match="count"):
        prior.choose(wi, wo, wi.shape[0] + 1)


def test_residual_variance_is_the_noise_floor():
    p = synthetic_prior(residual=0.04)
    wi, wo = p.cell_directions()
    r = p.reconstruct(wi[:30], wo[:30], np.full((30, 3), 0.2))
    # with the basis fully determined the per-cell variance is at least the residual's
    assert (r.mapped_sigma >= 0.2 - 1e-9).all()
