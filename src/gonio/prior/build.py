"""Building a prior from a library of materials: mapped tables, their mean and a low-rank basis.

Each material is evaluated at the valid cells' nodes of the grid (:mod:`gonio.prior.space`),
mapped, and stacked as one row of ``X`` (``M x V·C``: the channels of a material form one
vector, so the basis carries how they vary together). The basis is the leading right singular
vectors of the centred ``X`` (computed through the ``M x M`` Gram matrix: ``M`` is small); the
prior variance of coefficient ``k`` is ``s_k² / (M - 1)``.

Rank and residual, by leave-one-material-out
--------------------------------------------
Every held-out material is projected (all its cells known) onto the rank-K basis of the other
``M - 1``; this is done exactly and cheaply in the ``M - 1``-dimensional span of the centred data.
The LOO RMS error in the mapped space, as a function of K, is stored in the file
(``rank_selection``). Unless a rank is given, the rank is the smallest K whose LOO RMS error is
within :data:`RANK_TOLERANCE` (2 %) of the best over ``1 .. min(max_rank, M - 2)``. The residual
variance per cell and channel is the mean over held-out materials of their squared LOO residual
at that rank, floored at :data:`RESIDUAL_FLOOR`: it is what the basis cannot represent in a
material it has not seen, which is what a reconstruction meets.
"""

from __future__ import annotations

import resource
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np

from gonio.brdf.grid import Channels
from gonio.errors import ParameterError
from gonio.prior import space
from gonio.prior.model import Prior

#: Relative slack of the rank rule (module docstring).
RANK_TOLERANCE = 0.02
#: Default largest rank (file size: K · V · C float32; 56 x 137,652 cells x 3 channels = 92.5 MB).
MAX_RANK = 56
#: Smallest residual variance per cell, mapped units².
RESIDUAL_FLOOR = 1e-12


def evaluate(material: Any, wi: np.ndarray, wo: np.ndarray, chunk: int = 1 << 16) -> np.ndarray:
    """``material.f`` at ``(wi, wo)`` as float64 ``(n, C)``, in chunks."""
    out = [
        np.asarray(material.f(wi[s : s + chunk], wo[s : s + chunk]), dtype=np.float64)
        for s in range(0, wi.shape[0], chunk)
    ]
    f = np.concatenate(out, axis=0)
    return f[:, None] if f.ndim == 1 else f


def build_prior(
    tables: Iterable[Any],
    names: Sequence[str],
    rank: int | None = None,
    *,
    max_rank: int = MAX_RANK,
    axes: tuple | None = None,
    epsilon: float = space.EPSILON,
    sources: Sequence[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> Prior:
    """Build a :class:`~gonio.prior.model.Prior` from materials (module docstring).

    Parameters
    ----------
    tables : materials with ``f(wi, wo) -> (n, C)`` in sr⁻¹ (tables, models, RGL files), all
        with the same channel count; iterated once (a generator keeps one in memory at a time).
    names : their names, recorded in the file (as many as ``tables``, at least 3).
    rank : the number of basis vectors; None chooses it by leave-one-out (module docstring).
    max_rank : the largest rank considered.
    axes : the grid (default :func:`gonio.prior.space.prior_axes`).
    epsilon : ε of the mapped space, sr⁻¹.
    sources : what each material was read from, recorded in the file.
    progress : called with a short status line per material.

    Raises
    ------
    ParameterError
        Fewer than 3 materials, mismatched channel counts, a rank out of ``1 .. M - 1``,
        non-finite values.
    """
    t0 = time.perf_counter()
    names = [str(n) for n in names]
    M = len(names)
    if M < 3:
        raise ParameterError(f"a prior needs at least 3 materials, got {M}")
    axes = tuple(axes) if axes is not None else space.prior_axes()
    mask = space.valid_mask(axes)
    wi, wo = space.grid_directions(axes)
    keep = mask.reshape(-1)
    wi, wo = wi[keep], wo[keep]
    cc = space.cos_product(wi, wo)
    V = int(keep.sum())
    rows: list[np.ndarray] = []
    C = None
    channels = None
    for i, t in enumerate(tables):
        if i >= M:
            raise ParameterError(f"more tables than the {M} names")
        if progress is not None:
            progress(f"evaluating {names[i]} ({i + 1}/{M})")
        f = evaluate(t, wi, wo)
        if C is None:
            C = f.shape[1]
            ch = getattr(t, "channels", None)
            channels = Channels.describe(ch if isinstance(ch, Channels) else None, C)
        elif f.shape[1] != C:
            raise ParameterError(f"{names[i]} has {f.shape[1]} channels, the others {C}")
        if not np.isfinite(f).all():
            raise ParameterError(f"{names[i]}: non-finite values at valid cells of the grid")
        rows.append(space.to_mapped(f, cc, epsilon).reshape(-1).astype(np.float32))
    if len(rows) != M:
        raise ParameterError(f"{len(rows)} tables for {M} names")
    if progress is not None:
        progress("basis")
    X = np.stack(rows)
    del rows
    mean = X.mean(axis=0, dtype=np.float64)
    X -= mean.astype(np.float32)
    gram = _gram(X)
    lam, U = np.linalg.eigh(gram)
    order = np.argsort(lam)[::-1]
    lam, U = np.maximum(lam[order], 0.0), U[:, order]
    r = int((lam > lam[0] * 1e-12).sum()) if lam[0] > 0 else 0
    if r < 1:
        raise ParameterError("the materials are all the same in the mapped space")
    s = np.sqrt(lam[:r])
    coords = U[:, :r] * s  # row m: material m's centred vector in the basis below
    Vfull = _right_vectors(X, U[:, :r] / s)  # (V·C, r) float32, orthonormal columns
    del X
    loo_sq, resid = _leave_one_out(coords)
    k_max = max(1, min(int(max_rank), M - 2, r))
    loo_rms = np.sqrt(loo_sq[:k_max] / (V * C))
    rule = "given"
    if rank is None:
        best = float(loo_rms.min())
        rank = int(np.flatnonzero(loo_rms <= best * (1 + RANK_TOLERANCE))[0]) + 1
        rule = f"smallest K with LOO RMS within {RANK_TOLERANCE:.0%} of the best up to {k_max}"
    rank = int(rank)
    if not 1 <= rank <= min(r, M - 1):
        raise ParameterError(f"rank must be in 1..{min(r, M - 1)} for these {M} materials")
    E = resid[:, min(rank, resid.shape[1] - 1), :]  # (M, r) residual coordinates at the rank
    res_var = _residual_variance(Vfull, E.T @ E / M).reshape(V, C)
    res_var = np.maximum(res_var, RESIDUAL_FLOOR)
    basis = np.ascontiguousarray(Vfull[:, :rank]).reshape(V, C, rank)
    variances = lam[:rank] / (M - 1)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    meta = {
        "materials": names,
        "sources": list(sources) if sources is not None else names,
        "rank_selection": {
            "rule": rule,
            "loo_rms": [float(x) for x in loo_rms],
            "loo_rms_at_rank": float(np.sqrt(loo_sq[min(rank, k_max) - 1] / (V * C))),
        },
        "residual": {
            "kind": "per_cell",
            "floor": RESIDUAL_FLOOR,
            "estimate": "mean squared leave-one-material-out residual at the rank",
        },
        "build": {
            "seconds": round(time.perf_counter() - t0, 3),
            "peak_rss_mib": round(peak, 1),
            "n_materials": M,
        },
    }
    return Prior(axes, mask, mean.reshape(V, C), basis, variances, res_var, channels, epsilon, meta)


def _gram(X: np.ndarray, chunk: int = 1 << 16) -> np.ndarray:
    """``X Xᵀ`` in float64, by column blocks of the float32 ``X``."""
    G = np.zeros((X.shape[0], X.shape[0]))
    for s in range(0, X.shape[1], chunk):
        b = X[:, s : s + chunk].astype(np.float64)
        G += b @ b.T
    return G


def _right_vectors(X: np.ndarray, W: np.ndarray, chunk: int = 1 << 16) -> np.ndarray:
    """``Xᵀ W`` (``(V·C, r)`` float32) by row blocks of ``Xᵀ``."""
    out = np.empty((X.shape[1], W.shape[1]), np.float32)
    for s in range(0, X.shape[1], chunk):
        out[s : s + chunk] = X[:, s : s + chunk].T.astype(np.float64) @ W
    return out


def _leave_one_out(coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-material-out projection errors in the span of the centred data.

    Parameters
    ----------
    coords : ``(M, r)`` the centred materials' coordinates.

    Returns
    -------
    sq : ``(r + 1,)``: ``sq[K - 1]`` is the mean over held-out materials of the squared norm of
        their residual at rank K (``K = 1 .. r``; the last entry repeats the largest rank).
    resid : ``(M, r + 1, r)``: each held-out material's residual coordinates at rank
        ``K = 0 .. r`` (index K).
    """
    M, r = coords.shape
    resid = np.zeros((M, r + 1, r))
    for m in range(M):
        rest = np.delete(coords, m, axis=0) + coords[m] / (M - 1)  # centred without m
        b = coords[m] * M / (M - 1)  # m minus the others' mean
        _, _, Wt = np.linalg.svd(rest, full_matrices=False)
        proj = np.zeros(r)
        resid[m, 0] = b
        for k in range(r):
            if k < Wt.shape[0]:
                proj = proj + (Wt[k] @ b) * Wt[k]
            resid[m, k + 1] = b - proj
    sq = (resid[:, 1:, :] ** 2).sum(axis=2).mean(axis=0)
    return np.append(sq, sq[-1]), resid


def _residual_variance(Vfull: np.ndarray, cov: np.ndarray, chunk: int = 1 << 16) -> np.ndarray:
    """``diag(Vfull cov Vfullᵀ)`` (``(V·C,)``)."""
    out = np.empty(Vfull.shape[0])
    for s in range(0, Vfull.shape[0], chunk):
        b = Vfull[s : s + chunk].astype(np.float64)
        out[s : s + chunk] = np.einsum("ik,ik->i", b @ cov, b)
    return out
