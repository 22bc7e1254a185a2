"""Which configurations to measure: greedy optimal design on the prior's coefficient posterior.

The criterion is the mean posterior variance of the mapped table over the valid cells and
channels, ``(tr Σ + Σ residual_var) / (V·C)`` (the basis is orthonormal, so
``diag(B Σ Bᵀ)`` sums to ``tr Σ``): an I-optimal (integrated-variance) design, which here is the
A-optimal one on the coefficients. Measuring a candidate with rows ``a`` (``(C, K)``) and noise
``s²`` (the prior's residual variance there; its own measurement noise is not known yet)
lowers ``tr Σ`` by

    tr((a Σ aᵀ + diag(s²))⁻¹ a Σ Σ aᵀ),

and the posterior after it is ``Σ - Σ aᵀ (a Σ aᵀ + diag s²)⁻¹ a Σ``. :func:`choose` adds the
candidate of largest reduction, updates Σ and repeats: deterministic (ties go to the lower
index), never the same candidate twice.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gonio.errors import ParameterError
from gonio.prior.posterior import Measured, covariance_after


def _candidates(prior: Any, wi: Any, wo: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    obs = prior.observe(wi, wo)
    ok = obs.usable & (obs.cc > 0)
    return obs.design, obs.residual_var, ok


def _reductions(cov: np.ndarray, A: np.ndarray, s2: np.ndarray) -> np.ndarray:
    """``(n,)`` reduction of ``tr Σ`` by each candidate (module docstring)."""
    P = A @ cov  # (n, C, K)
    S = np.einsum("nck,ndk->ncd", P, A)
    S[:, np.arange(S.shape[1]), np.arange(S.shape[1])] += np.maximum(s2, 1e-300)
    Q = np.einsum("nck,ndk->ncd", P, P)
    return np.einsum("ncc->n", np.linalg.solve(S, Q))


def variance_reduction(
    prior: Any, candidates_wi: Any, candidates_wo: Any, measured: Measured = None
) -> np.ndarray:
    """``(n,)``: how much measuring each candidate alone lowers the mean posterior variance of
    the mapped table over the valid cells and channels (0 for unusable candidates: below the
    horizon or away from every valid cell)."""
    A, s2, ok = _candidates(prior, candidates_wi, candidates_wo)
    cov = covariance_after(prior, measured)
    out = np.zeros(A.shape[0])
    if ok.any():
        out[ok] = _reductions(cov, A[ok], s2[ok]) / (prior.n_valid * prior.n_channels)
    return out


def choose(
    prior: Any, candidates_wi: Any, candidates_wo: Any, count: int, measured: Measured = None
) -> np.ndarray:
    """Indices into the candidates of ``count`` configurations chosen greedily (module
    docstring), in the order chosen.

    Parameters
    ----------
    prior : the prior.
    candidates_wi, candidates_wo : ``(n, 3)`` unit vectors, the sample's local frame.
    count : how many to choose, 1 <= count <= the number of usable candidates.
    measured : what is already measured (:data:`gonio.prior.posterior.Measured`).

    Returns
    -------
    ``(count,)`` int64 indices, distinct.
    """
    count = int(count)
    A, s2, ok = _candidates(prior, candidates_wi, candidates_wo)
    if count < 1:
        raise ParameterError(f"count must be >= 1, got {count}")
    if count > int(ok.sum()):
        raise ParameterError(
            f"count {count} is more than the {int(ok.sum())} usable candidates (above the "
            "horizon, near a valid cell of the prior's grid)"
        )
    cov = covariance_after(prior, measured)
    idx = np.flatnonzero(ok)
    A, s2 = A[idx], s2[idx]
    free = np.ones(idx.size, bool)
    chosen: list[int] = []
    for _ in range(count):
        gain = np.where(free, _reductions(cov, A, s2), -np.inf)
        j = int(np.argmax(gain))
        chosen.append(int(idx[j]))
        free[j] = False
        a = A[j]
        S = a @ cov @ a.T + np.diag(np.maximum(s2[j], 1e-300))
        P = a @ cov
        cov = cov - P.T @ np.linalg.solve(S, P)
        cov = 0.5 * (cov + cov.T)
    return np.asarray(chosen, dtype=np.int64)
