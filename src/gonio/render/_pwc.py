"""A 2-D piecewise-constant distribution on the unit square, sampled inside jitted kernels.

Written here rather than taken from :mod:`gonio.brdf.sampling` because the renderer needs it
*traceable*: fixed-iteration vectorized binary searches over float32 CDFs, so that environment
importance sampling runs inside the jitted render kernel without host round trips.

The density is defined from the float32 CDF differences themselves, so :meth:`pdf` is exactly the
density of :meth:`sample` even where float32 rounding merges tiny bins.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from gonio.errors import ParameterError

Array = jnp.ndarray


def _cdf_rows(weights: np.ndarray) -> np.ndarray:
    """Normalized CDFs along the last axis, shape ``(..., n + 1)``, float64, last entry 1."""
    w = np.maximum(np.asarray(weights, dtype=np.float64), 0.0)
    csum = np.concatenate([np.zeros((*w.shape[:-1], 1)), np.cumsum(w, axis=-1)], axis=-1)
    total = csum[..., -1:]
    n = w.shape[-1]
    # Rows with no mass become uniform (they are never chosen by the marginal anyway).
    uniform = np.broadcast_to(np.linspace(0.0, 1.0, n + 1), csum.shape)
    cdf = np.where(total > 0, csum / np.where(total > 0, total, 1.0), uniform)
    cdf[..., -1] = 1.0
    return cdf


def _search(cdf: Array, u: Array, n: int) -> Array:
    """Largest ``i`` in ``[0, n - 1]`` with ``cdf[..., i] <= u`` (cdf gathered per query).

    ``cdf`` is a callable ``i -> cdf value`` so that both 1-D and per-row lookups share it.
    """
    lo = jnp.zeros(u.shape, dtype=jnp.int32)
    hi = jnp.full(u.shape, n, dtype=jnp.int32)
    for _ in range(max(1, math.ceil(math.log2(n + 1)))):
        mid = (lo + hi) // 2
        go_right = cdf(mid) <= u
        lo = jnp.where(go_right, mid, lo)
        hi = jnp.where(go_right, hi, mid)
    return jnp.clip(lo, 0, n - 1)


@jax.tree_util.register_pytree_node_class
class PiecewiseConstant2D:
    """Distribution over ``[0, 1)^2`` proportional to a non-negative ``(rows, cols)`` grid.

    Row ``r`` covers ``y in [r/rows, (r+1)/rows)`` and column ``c`` covers ``x in [c/cols, ...)``.
    """

    def __init__(self, weights: np.ndarray) -> None:
        w = np.asarray(weights, dtype=np.float64)
        if w.ndim != 2 or w.size == 0:
            raise ParameterError(f"importance map must be a non-empty 2-D array, got {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ParameterError("importance map must be finite and non-negative")
        if not np.any(w > 0):
            raise ParameterError("importance map has no mass (all zero)")
        self.marginal = jnp.asarray(_cdf_rows(w.sum(axis=1)), dtype=jnp.float32)
        self.conditional = jnp.asarray(_cdf_rows(w), dtype=jnp.float32)

    def tree_flatten(self):
        return (self.marginal, self.conditional), None

    @classmethod
    def tree_unflatten(cls, aux, leaves):
        obj = object.__new__(cls)
        obj.marginal, obj.conditional = leaves
        return obj

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.conditional.shape[0]), int(self.conditional.shape[1]) - 1

    def sample(self, u: Array) -> tuple[Array, Array]:
        """Map ``u`` (..., 2) to ``(xy (..., 2), pdf (...))``; pdf per unit area of the square."""
        rows, cols = self.shape
        u = jnp.clip(u.astype(jnp.float32), 0.0, 1.0 - 2.0**-24)
        m, c = self.marginal, self.conditional
        r = _search(lambda i: m[i], u[..., 1], rows)
        m0, m1 = m[r], m[r + 1]
        fy = (u[..., 1] - m0) / jnp.maximum(m1 - m0, 1e-30)
        col = _search(lambda i: c[r, i], u[..., 0], cols)
        c0, c1 = c[r, col], c[r, col + 1]
        fx = (u[..., 0] - c0) / jnp.maximum(c1 - c0, 1e-30)
        x = (col.astype(jnp.float32) + jnp.clip(fx, 0.0, 1.0 - 2.0**-24)) / cols
        y = (r.astype(jnp.float32) + jnp.clip(fy, 0.0, 1.0 - 2.0**-24)) / rows
        pdf = (m1 - m0) * (c1 - c0) * (rows * cols)
        return jnp.stack([x, y], -1), pdf

    def pdf(self, xy: Array) -> Array:
        """Density per unit area at ``xy`` (..., 2) in ``[0, 1)^2``."""
        rows, cols = self.shape
        col = jnp.clip(jnp.floor(xy[..., 0] * cols).astype(jnp.int32), 0, cols - 1)
        r = jnp.clip(jnp.floor(xy[..., 1] * rows).astype(jnp.int32), 0, rows - 1)
        pm = self.marginal[r + 1] - self.marginal[r]
        pc = self.conditional[r, col + 1] - self.conditional[r, col]
        return pm * pc * (rows * cols)
