"""Hierarchical sample warping of a 2-D piecewise-constant density (environment lights).

The density is the one of :class:`gonio.brdf.sampling.distributions.Distribution2D` (a grid of
``ny x nx`` cells, each of constant density proportional to its weight), but a sample is drawn
down a quadtree instead of by marginal-then-conditional CDF inversion (McCool and Harwood 1997,
"Probability trees"; Clarberg et al. 2005, "Wavelet importance sampling"): at each level the
node's four children are chosen by two binary splits, top/bottom by ``u[..., 0]`` and then
left/right by ``u[..., 1]``, and each number is rescaled to [0, 1) by the split it went
through. The map from the unit square to the grid is then local in both axes: a small square
of ``u`` lands in a compact patch of cells, where row-then-column inversion smears it along a
row, each row with its own conditional CDF. Stratified points (the renderer's lattice points) keep
their stratification through it. Same-run measurement, 64² sphere under the studio environment
at 16 spp, relative MSE (mean of 4 seeds): Lambert light sampling alone 0.0058 by inversion,
0.0026 by this warp; with MIS 0.0045 and 0.0026; GGX (alpha 0.2) with MIS 0.0085 and 0.0067.

It also costs fewer dependent gathers: one level (two gathers: the node's top/bottom split,
then the left/right split of the half chosen) per factor of 2 in the larger grid dimension,
against one binary-search step per factor of 2 in each dimension, and its density at a point is
one gather (the cell's).

The split probabilities are float32; the cell probabilities reported (:meth:`pdf`, and the
density returned by :meth:`sample`) are the products of those float32 splits computed in
float64, i.e. the probabilities this sampler realizes for exactly uniform ``u``. As with CDF
inversion, the float32 uniforms (24 bits) make every cell's realized probability exact to a few
``2^-24``; :mod:`tests.render.test_warp2d` checks sample frequencies by a chi-square test.
Cells of zero weight are never drawn. Grids of any size are padded to powers of 2 with
zero-weight cells.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf._xla import materialize
from gonio.brdf.sampling.distributions import bin_of, bin_position
from gonio.errors import ParameterError

Array = jnp.ndarray

#: A level's split: ``"xy"`` (four children: top/bottom, then left/right), ``"x"`` or ``"y"``
#: (two children along that axis, where the grid is longer in one dimension).
_ARITY = {"xy": 4, "x": 2, "y": 2}


def _ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a / (a + b)``; 0.5 where both are 0 (such a node is never reached)."""
    s = a + b
    return np.where(s > 0, a / np.where(s > 0, s, 1.0), 0.5)


@jax.tree_util.register_pytree_node_class
class HierarchicalWarp2D:
    """Piecewise-constant density on ``[0, 1)^2`` over an ``ny x nx`` grid, sampled down a
    quadtree. Row ``iy`` covers ``y in [iy / ny, (iy + 1) / ny)``, column ``ix`` covers ``x``
    likewise (the convention of :class:`gonio.brdf.sampling.distributions.Distribution2D`).

    Parameters
    ----------
    weights : ``(ny, nx)`` finite, non-negative cell weights with a positive sum.

    Attributes
    ----------
    probs : ``(ny, nx)`` float64 cell probabilities as the sampler realizes them (NumPy).
    """

    def __init__(self, weights: Any) -> None:
        try:
            w = np.asarray(weights, dtype=np.float64)
        except (TypeError, ValueError):
            raise ParameterError("HierarchicalWarp2D: weights must be numbers") from None
        if w.ndim != 2 or w.size == 0:
            raise ParameterError(f"HierarchicalWarp2D: weights must be (ny, nx), got {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0) or not np.sum(w) > 0:
            raise ParameterError("HierarchicalWarp2D: weights must be finite, >= 0, not all 0")
        self.ny, self.nx = w.shape
        grid = np.zeros((1 << (self.ny - 1).bit_length(), 1 << (self.nx - 1).bit_length()))
        grid[: self.ny, : self.nx] = w
        # sums over the nodes of every level, finest first
        grids, kinds = [grid], []
        while grids[-1].shape != (1, 1):
            g = grids[-1]
            if g.shape[0] > 1 and g.shape[1] > 1:
                kinds.append("xy")
                grids.append(g[0::2, 0::2] + g[0::2, 1::2] + g[1::2, 0::2] + g[1::2, 1::2])
            elif g.shape[1] > 1:
                kinds.append("x")
                grids.append(g[:, 0::2] + g[:, 1::2])
            else:
                kinds.append("y")
                grids.append(g[0::2] + g[1::2])
        # coarse to fine: node numbers (child = parent * arity + child index, child index
        # 2 * bottom + right), the float32 splits per node, and what they realize
        code = np.zeros((1, 1), np.int64)
        prob = np.ones((1, 1))
        pt_l, p0_l, p1_l, offsets = [], [], [], []
        for kind, g in zip(kinds[::-1], grids[-2::-1], strict=True):
            if kind == "xy":
                w00, w01, w10, w11 = g[0::2, 0::2], g[0::2, 1::2], g[1::2, 0::2], g[1::2, 1::2]
                pt = _ratio(w00 + w01, w10 + w11)
                p0, p1 = _ratio(w00, w01), _ratio(w10, w11)
            elif kind == "x":
                p0 = _ratio(g[:, 0::2], g[:, 1::2])
                pt, p1 = np.ones_like(p0), p0
            else:
                pt = _ratio(g[0::2], g[1::2])
                p0 = p1 = np.ones_like(pt)
            pt, p0, p1 = (a.astype(np.float32) for a in (pt, p0, p1))
            order = np.argsort(code.reshape(-1))
            offsets.append(sum(a.size for a in pt_l))
            for lst, a in ((pt_l, pt), (p0_l, p0), (p1_l, p1)):
                lst.append(a.reshape(-1)[order])
            t, a0, a1 = (a.astype(np.float64) for a in (pt, p0, p1))
            child_code = np.empty(g.shape, np.int64)
            child_prob = np.empty(g.shape)
            k = _ARITY[kind]
            for b in (0, 1) if kind != "x" else (0,):
                for r in (0, 1) if kind != "y" else (0,):
                    sy = slice(b, None, 2) if kind != "x" else slice(None)
                    sx = slice(r, None, 2) if kind != "y" else slice(None)
                    py = t if b == 0 else 1.0 - t
                    px = (a0 if b == 0 else a1) if r == 0 else 1.0 - (a0 if b == 0 else a1)
                    child_code[sy, sx] = code * k + (2 * b + r if kind == "xy" else b + r)
                    child_prob[sy, sx] = prob * py * px
            code, prob = child_code, child_prob
        self.kinds = tuple(kinds[::-1])
        self.offsets = tuple(offsets)
        self.probs = prob[: self.ny, : self.nx]
        iy, ix = np.divmod(np.argsort(code.reshape(-1)), grid.shape[1])
        # padding cells (zero probability, never drawn) point at a real cell
        leaf = np.minimum(iy, self.ny - 1) * self.nx + np.minimum(ix, self.nx - 1)
        self._pt = jax.device_put(np.concatenate(pt_l) if pt_l else np.ones(1, np.float32))
        # a node's two left/right splits side by side (node k's split for the top half at 2 k,
        # for the bottom half at 2 k + 1): one gather, at an index that the top/bottom choice
        # completes, fetches the one a sample needs (two gathers per level instead of three)
        p0 = np.concatenate(p0_l) if p0_l else np.ones(1, np.float32)
        p1 = np.concatenate(p1_l) if p1_l else np.ones(1, np.float32)
        self._p01 = jax.device_put(np.stack([p0, p1], -1).reshape(-1))
        self._leaf = jax.device_put(leaf.astype(np.int32))
        self._density = jax.device_put((self.probs * (self.ny * self.nx)).astype(np.float32))

    def tree_flatten(self) -> tuple[tuple[Array, ...], tuple[Any, ...]]:
        leaves = (self._pt, self._p01, self._leaf, self._density)
        return leaves, (self.ny, self.nx, self.kinds, self.offsets)

    @classmethod
    def tree_unflatten(cls, aux: tuple[Any, ...], leaves: Any) -> HierarchicalWarp2D:
        obj = object.__new__(cls)
        obj.ny, obj.nx, obj.kinds, obj.offsets = aux
        obj._pt, obj._p01, obj._leaf, obj._density = leaves
        obj.probs = None  # host copy not carried through a trace
        return obj

    def sample(self, u: Array) -> tuple[Array, Array, Array]:
        """``u (..., 2)`` float in ``[0, 1)`` (``u[..., 0]`` for rows, ``u[..., 1]`` for columns)
        -> ``(xy (..., 2) in [0, 1)^2, density on the unit square, flat cell iy * nx + ix)``."""
        u = jnp.asarray(u)
        if not jnp.issubdtype(u.dtype, jnp.floating):
            u = u.astype(jnp.float64)
        dt = u.dtype
        one = float(np.nextafter(np.array(1.0, dt), np.array(0.0, dt)))
        # u = 1 would pass a split of probability 1 into its empty side
        u = jnp.clip(u, 0.0, one)
        uy, ux = u[..., 0], u[..., 1]
        node = jnp.zeros(uy.shape, jnp.int32)
        for kind, off in zip(self.kinds, self.offsets, strict=True):
            # stored once per level: otherwise XLA recomputes every earlier level inside each
            # gather's index computation, a cost that grows with the depth
            node, uy, ux = self._stored(node, uy, ux)
            child = jnp.zeros_like(node)
            if kind != "x":
                pt = jnp.take(self._pt, node + off, mode="clip").astype(dt)
                bottom = uy >= pt
                uy = jnp.where(bottom, (uy - pt) / jnp.where(bottom, 1.0 - pt, 1.0),
                               uy / jnp.where(bottom, 1.0, pt))  # fmt: skip
                child = 2 * bottom.astype(jnp.int32)
            if kind != "y":
                # child // 2 is the bottom flag ("xy"), 0 otherwise
                p0 = jnp.take(self._p01, 2 * (node + off) + child // 2, mode="clip").astype(dt)
                right = ux >= p0
                ux = jnp.where(right, (ux - p0) / jnp.where(right, 1.0 - p0, 1.0),
                               ux / jnp.where(right, 1.0, p0))  # fmt: skip
                child = child + right.astype(jnp.int32)
            node = node * _ARITY[kind] + (child if kind != "y" else child // 2)
        node = self._stored(node, uy, ux)[0] if self.kinds else node
        cell = jnp.take(self._leaf, node, mode="clip")
        iy = cell // self.nx
        ix = cell - iy * self.nx
        x = bin_position(ix, jnp.clip(ux, 0.0, one), self.nx)
        y = bin_position(iy, jnp.clip(uy, 0.0, one), self.ny)
        density = jnp.take(self._density, cell, mode="clip").astype(dt)
        return jnp.stack([x, y], -1), density, cell

    def _stored(self, node: Array, uy: Array, ux: Array) -> tuple[Array, Array, Array]:
        if self._leaf.shape[0] <= 1 << 24:  # node numbers exact through float32
            return tuple(materialize([node, uy, ux], uy))
        return jax.lax.optimization_barrier((node, uy, ux))

    def cell_of(self, xy: Array) -> Array:
        """Flat cell index ``iy * nx + ix`` of points ``xy (..., 2)`` (clamped to the grid)."""
        xy = jnp.asarray(xy)
        return bin_of(xy[..., 1], self.ny) * self.nx + bin_of(xy[..., 0], self.nx)

    def cell_density(self, cell: Array, dtype: Any = jnp.float32) -> Array:
        """Density on the unit square inside the flat cells ``cell`` (as :meth:`cell_of`)."""
        return jnp.take(self._density, cell, mode="clip").astype(dtype)

    def pdf(self, xy: Array) -> Array:
        """Density at ``xy (..., 2)`` on the unit square, as :meth:`sample` realizes it (0
        outside)."""
        xy = jnp.asarray(xy)
        if not jnp.issubdtype(xy.dtype, jnp.floating):
            xy = xy.astype(jnp.float64)
        x, y = xy[..., 0], xy[..., 1]
        inside = (x >= 0) & (x < 1) & (y >= 0) & (y < 1)
        density = jnp.take(self._density, self.cell_of(xy), mode="clip").astype(xy.dtype)
        return jnp.where(inside, density, 0.0)


__all__ = ["HierarchicalWarp2D"]
