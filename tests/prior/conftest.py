"""Small priors for the tests: a synthetic one (a known basis) and tables to build one from."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.grid import Channels
from gonio.prior import Prior, prior_axes, space

#: A coarse grid: 30 theta_h x 15 theta_d x 15 phi_d nodes (5,087 valid cells).
SMALL_AXES = prior_axes(30, 15, 15)


def synthetic_prior(rank: int = 6, seed: int = 1, residual: float = 1e-12) -> Prior:
    """A prior with a random orthonormal basis on :data:`SMALL_AXES` (RGB)."""
    rng = np.random.default_rng(seed)
    mask = space.valid_mask(SMALL_AXES)
    V, C = int(mask.sum()), 3
    B, _ = np.linalg.qr(rng.normal(size=(V * C, rank)))
    mean = rng.normal(-2.0, 0.5, size=(V, C))
    return Prior(
        SMALL_AXES,
        mask,
        mean,
        B.reshape(V, C, rank).astype(np.float32),
        np.linspace(4.0, 0.5, rank),
        np.full((V, C), residual),
        Channels.rgb(),
        meta={"materials": ["a", "b"]},
    )


@pytest.fixture(scope="session")
def prior() -> Prior:
    return synthetic_prior()


def in_span(prior: Prior, seed: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """``(coefficients, mapped table (V, C))`` of a material drawn from the prior."""
    rng = np.random.default_rng(seed)
    c = rng.normal(size=prior.rank) * np.sqrt(prior.variances)
    K = prior.rank
    m = prior.mean + (prior.basis.reshape(-1, K).astype(np.float64) @ c).reshape(prior.mean.shape)
    return c, m


@pytest.fixture(scope="session")
def tables() -> list:
    """Six small model tables (16 x 16 x 16 nodes), shared by the tests."""
    return model_tables(6)


def model_tables(n: int, seed: int = 0, res: int = 16) -> list:
    """``n`` small RGB tables of Lambert + GGX Torrance-Sparrow materials."""
    from gonio.brdf import models
    from gonio.brdf.tabulated import TabulatedBRDF

    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        m = models.Lambert(albedo=list(rng.uniform(0.05, 0.8, 3))) + models.TorranceSparrow(
            alpha=float(rng.uniform(0.05, 0.5)),
            distribution="ggx",
            fresnel=models.Schlick(f0=float(rng.uniform(0.02, 0.9))),
        )
        axes = TabulatedBRDF.default_axes(n_theta_h=res, n_theta_d=res, n_phi_d=res)
        out.append(TabulatedBRDF.from_model(m, axes=axes))
    return out
