"""Bayesian linear model on the prior's coefficients: posterior, reconstruction, predicted error.

With the rows ``A`` (``(n·C, K)``) of :meth:`gonio.prior.model.Prior.observe`, the mapped
samples ``y`` and their noise variance ``s² = residual_var + σ_m²`` (the prior's residual
variance at the sample plus the measured σ carried into the mapped space by the delta method;
channels and samples taken as independent), the posterior of the coefficients is Gaussian:

    Σ = (Λ⁻¹ + Aᵀ S⁻¹ A)⁻¹,   μ = Σ Aᵀ S⁻¹ (y - offset),   Λ = diag(variances).

It is computed by least squares on the whitened, stacked system ``[S^-½ A; Λ^-½]`` (QR), never
by forming the normal equations. The reconstructed mapped table is ``mean + B μ``; its variance
per cell is ``diag(B Σ Bᵀ) + residual_var`` (the coefficients' uncertainty plus what the basis
cannot represent); values and σ in sr⁻¹ follow by the inverse map and the delta method
(:mod:`gonio.prior.space`). The mapped values are the posterior median of ``f`` (the map is
monotonic), not its mean.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np

from gonio.errors import ParameterError
from gonio.prior import space

if TYPE_CHECKING:
    from gonio.brdf.tabulated import TabulatedBRDF

#: What is already measured, for :func:`covariance_after`: nothing (None), an earlier
#: :class:`Reconstruction`, or a tuple ``(wi, wo)`` / ``(wi, wo, values, sigma)`` (values and
#: sigma in sr⁻¹; sigma may be None).
Measured: TypeAlias = Any

#: E|x| / σ of a zero-mean Gaussian.
_MEAN_ABS = math.sqrt(2.0 / math.pi)


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """A full table reconstructed from samples.

    Attributes
    ----------
    table : the isotropic :class:`~gonio.brdf.tabulated.TabulatedBRDF` on the prior's grid,
        values and σ in sr⁻¹; ``meta["sigma_correlated"]`` says that σ is correlated across
        cells and ``meta["reconstruction"]`` holds the coefficients and their covariance.
    coefficients : ``(K,)`` posterior mean of the coefficients.
    covariance : ``(K, K)`` their posterior covariance.
    predicted_error : expected mean absolute error of ``mapped`` over the valid cells and
        channels, from the posterior (``sqrt(2/π) · mean σ_m``).
    mapped : ``(V, C)`` the reconstruction in the mapped space over the valid cells.
    mapped_sigma : ``(V, C)`` its σ in the mapped space.
    n_used, n_dropped : samples used, and dropped (below the horizon, non-finite, no valid
        cell nearby).
    """

    table: TabulatedBRDF
    coefficients: np.ndarray
    covariance: np.ndarray
    predicted_error: float
    mapped: np.ndarray
    mapped_sigma: np.ndarray
    n_used: int
    n_dropped: int


def _samples(
    prior: Any, wi: Any, wo: Any, values: Any, sigma: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """``(A, y, s2, keep, n_dropped)``: the stacked rows ``(n·C, K)``, mapped samples minus the
    mean ``(n·C,)``, their noise variance ``(n·C,)`` and the kept samples' mask."""
    obs = prior.observe(wi, wo)
    n, C = obs.offset.shape
    vals = None
    if values is not None:
        vals = np.asarray(values, dtype=np.float64)
        if vals.ndim == 1 and C == 1:
            vals = vals[:, None]
        if vals.shape != (n, C):
            raise ParameterError(f"values must be (n, {C}) for this prior, got {vals.shape}")
    sig = None
    if sigma is not None:
        sig = np.asarray(sigma, dtype=np.float64)
        if sig.ndim == 1 and C == 1:
            sig = sig[:, None]
        if sig.shape != (n, C):
            raise ParameterError(f"sigma must be (n, {C}) for this prior, got {sig.shape}")
    keep = obs.usable & (obs.cc > 0)
    if vals is not None:
        keep &= np.isfinite(vals).all(axis=1)
    if sig is not None:
        keep &= (np.isfinite(sig) & (sig >= 0)).all(axis=1)
    s2 = obs.residual_var.copy()
    y = np.zeros((n, C))
    if vals is not None:
        v = np.where(keep[:, None], vals, 0.0)
        y = space.to_mapped(v, obs.cc, prior.epsilon) - obs.offset
        if sig is not None:
            sm = space.sigma_to_mapped(v, np.where(keep[:, None], sig, 0.0), obs.cc, prior.epsilon)
            s2 = s2 + sm * sm
    K = prior.rank
    A = obs.design[keep].reshape(-1, K)
    return A, y[keep].reshape(-1), s2[keep].reshape(-1), keep, int(n - keep.sum())


def _solve(
    prior: Any,
    A: np.ndarray,
    y: np.ndarray,
    s2: np.ndarray,
    start: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(μ, Σ)`` of the coefficients given rows ``A``, data ``y`` and noise ``s2``, starting
    from the prior or from ``start = (μ0, Σ0)`` (an earlier posterior)."""
    K = prior.rank
    if start is None:
        mu0 = np.zeros(K)
        L0inv = np.diag(1.0 / np.sqrt(prior.variances))  # Λ^-½
    else:
        mu0, cov0 = start
        # Σ0^-½ as the inverse Cholesky factor: Σ0 = L Lᵀ -> L^-1 whitens the prior
        L = np.linalg.cholesky(0.5 * (cov0 + cov0.T) + 1e-300 * np.eye(K))
        L0inv = np.linalg.solve(L, np.eye(K))
    w = 1.0 / np.sqrt(np.maximum(s2, 1e-300))
    M = np.vstack([A * w[:, None], L0inv])
    rhs = np.concatenate([(y - A @ mu0) * w, np.zeros(K)])
    Q, R = np.linalg.qr(M)
    delta = np.linalg.solve(R, Q.T @ rhs)
    Rinv = np.linalg.solve(R, np.eye(K))
    cov = Rinv @ Rinv.T
    return mu0 + delta, 0.5 * (cov + cov.T)


def covariance_after(prior: Any, measured: Measured) -> np.ndarray:
    """``(K, K)`` posterior covariance of the coefficients after ``measured`` (see
    :data:`Measured`; it does not depend on the values except through σ's mapping)."""
    if measured is None:
        return np.diag(prior.variances)
    if isinstance(measured, Reconstruction):
        return np.asarray(measured.covariance, dtype=np.float64)
    if isinstance(measured, Sequence) and len(measured) in (2, 4):
        wi, wo, *rest = measured
        values, sigma = rest if rest else (None, None)
        if values is None and sigma is not None:
            raise ParameterError("measured sigma needs the measured values (to map it)")
        A, _, s2, _, _ = _samples(prior, wi, wo, values, sigma)
        return _solve(prior, A, np.zeros_like(s2), s2)[1]
    raise ParameterError(
        "measured must be None, a Reconstruction, (wi, wo) or (wi, wo, values, sigma)"
    )


def cell_variance(prior: Any, cov: np.ndarray, chunk: int = 1 << 16) -> np.ndarray:
    """``(V, C)`` variance of the mapped table: ``diag(B Σ Bᵀ) + residual_var``."""
    V, C, K = prior.basis.shape
    B = prior.basis.reshape(-1, K)
    out = np.empty(V * C)
    for s in range(0, V * C, chunk):
        b = B[s : s + chunk].astype(np.float64)
        out[s : s + chunk] = np.einsum("ik,ik->i", b @ cov, b)
    return np.maximum(out.reshape(V, C), 0.0) + prior.residual_var


def predicted_error(prior: Any, cov: np.ndarray) -> float:
    """Expected mean absolute error of the mapped reconstruction over the valid cells and
    channels when the coefficients' posterior covariance is ``cov``: ``sqrt(2/π)`` times the
    mean of the per-cell σ (each cell's error taken as Gaussian)."""
    return float(_MEAN_ABS * np.sqrt(cell_variance(prior, cov)).mean())


def reconstruct(
    prior: Any, wi: Any, wo: Any, values: Any, sigma: Any = None, *, meta: dict | None = None
) -> Reconstruction:
    """:meth:`gonio.prior.model.Prior.reconstruct` (module docstring for the model)."""
    if values is None:
        raise ParameterError("reconstruct needs the measured values")
    A, y, s2, keep, dropped = _samples(prior, wi, wo, values, sigma)
    if not keep.any():
        raise ParameterError(
            f"no usable samples: all {dropped} are below the horizon, non-finite or away from "
            "every valid cell of the prior's grid"
        )
    mu, cov = _solve(prior, A, y, s2)
    V, C, K = prior.basis.shape
    mapped = prior.mean + (prior.basis.reshape(-1, K).astype(np.float64) @ mu).reshape(V, C)
    var = cell_variance(prior, cov)
    msig = np.sqrt(var)
    err = float(_MEAN_ABS * msig.mean())
    table = to_table(
        prior,
        mapped,
        msig,
        {
            **(meta or {}),
            "sigma_correlated": {
                "kind": "low-rank prior reconstruction",
                "rank": K,
                "note": "sigma comes from a few coefficients: it is correlated across cells, not "
                "independent noise per cell",
            },
            "reconstruction": {
                "prior": {
                    k: prior.meta.get(k)
                    for k in ("path", "created_utc", "rank", "materials")
                    if k in prior.meta
                },
                "space": {"name": space.SPACE, "epsilon": prior.epsilon},
                "coefficients": mu.tolist(),
                "coefficient_covariance": cov.tolist(),
                "predicted_error": err,
                "n_samples": int(keep.sum()),
                "n_dropped": dropped,
                "sigma": "delta method from the coefficients' posterior covariance plus the "
                "prior's residual variance",
            },
        },
    )
    return Reconstruction(table, mu, cov, err, mapped, msig, int(keep.sum()), dropped)


def to_table(
    prior: Any, mapped: np.ndarray, mapped_sigma: np.ndarray | None, meta: dict
) -> TabulatedBRDF:
    """A mapped table over the valid cells as a :class:`TabulatedBRDF` in sr⁻¹ on the
    prior's grid (σ by the delta method when ``mapped_sigma`` is given)."""
    from gonio.brdf.tabulated import TabulatedBRDF

    wi, wo = prior.cell_directions()
    cc = space.cos_product(wi, wo)
    grid = prior.mask.shape
    C = prior.n_channels
    keep = prior.mask.reshape(-1)
    vals = np.zeros((keep.size, C), np.float32)
    vals[keep] = space.from_mapped(mapped, cc, prior.epsilon)
    sig = None
    if mapped_sigma is not None:
        sig = np.zeros((keep.size, C), np.float32)
        sig[keep] = space.sigma_from_mapped(mapped, mapped_sigma, cc)
        sig = sig.reshape(*grid, C)
    return TabulatedBRDF(
        values=vals.reshape(*grid, C),
        axes=prior.axes,
        parameterization="half_diff_iso",
        mask=prior.mask,
        sigma=sig,
        channels=prior.channels,
        meta=meta,
    )
