"""Generic sampling building blocks: piecewise-constant 1-D/2-D distributions, alias tables and
a rejection-sampling loop.

Every structure may hold a *batch* of distributions (weights of shape ``(..., n)``); a query then
names the distribution it draws from with ``which`` (an integer array, flat index into the batch
dimensions). Construction runs once on the host (NumPy, float64); sampling and density
evaluation are pure JAX, vectorized over the queries, and keep the dtype of ``u`` (the float32
arrays are derived from the float64 ones, and every reported probability is computed from the
same arrays the sampler uses, so pdfs stay consistent with samples in either precision).

Used by :class:`gonio.brdf.tabulated.TabulatedBRDF` (sampling f cos over incident directions)
and by the renderer (environment-map importance sampling). :class:`Distribution1D` and
:class:`Distribution2D` are registered pytrees (their leaves are the JAX
arrays the sampler reads), so they can be passed to ``jax.jit`` as arguments; the builders
:func:`normalized_cdf`, :func:`vose_alias` and :func:`alias_arrays` are public for callers that
stack many distributions themselves.

References: Pharr, Jakob & Humphreys, *Physically Based Rendering* 4th ed., sections A.1 (alias
method), A.5 (sampling piecewise-constant functions); Vose, "A linear algorithm for generating
random numbers with a given distribution", IEEE TSE 1991.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf._xla import materialize
from gonio.errors import ParameterError

Array = jnp.ndarray

_ONE_MINUS_EPS32 = float(np.nextafter(np.float32(1.0), np.float32(0.0)))
_ONE_MINUS_EPS64 = float(np.nextafter(1.0, 0.0))


def _one_minus_eps(dtype: Any) -> float:
    return _ONE_MINUS_EPS64 if jnp.dtype(dtype) == jnp.float64 else _ONE_MINUS_EPS32


def _put(a: np.ndarray, dtype: Any = None) -> Array:
    """A host array on the default device, cast on the host: ``jax.device_put`` copies without
    compiling anything, where ``jnp.asarray(a, float32)`` of a float64 array compiles a small
    conversion kernel per new shape."""
    return jax.device_put(np.ascontiguousarray(a, dtype))


def _float_u(u: Any) -> Array:
    u = jnp.asarray(u)
    if not jnp.issubdtype(u.dtype, jnp.floating):
        u = u.astype(jnp.float64)
    return jnp.clip(u, 0.0, _one_minus_eps(u.dtype))


def bin_position(k: Array, r: Array, n: int) -> Array:
    """``(k + r) / n`` kept inside bin ``k`` as :func:`bin_of` sees it, despite rounding."""
    dt = r.dtype
    kf = k.astype(dt)
    x = (kf + r) / n
    hi = jnp.nextafter((kf + 1) / n, jnp.zeros((), dt))
    return jnp.clip(x, kf / n, hi)


def bin_of(x: Array, n: int) -> Array:
    """Bin ``k`` of ``x`` with the edges ``k / n`` computed in ``x``'s dtype (int32, clamped).

    Public with :func:`bin_position` for samplers outside this module that must agree with these
    distributions on bin edges (:mod:`gonio.brdf.sampling.quadtree`)."""
    k = jnp.clip(jnp.floor(x * n).astype(jnp.int32), 0, n - 1)
    kf = k.astype(x.dtype)
    k = jnp.where((x < kf / n) & (k > 0), k - 1, k)
    kf = k.astype(x.dtype)
    return jnp.where((x >= (kf + 1) / n) & (k < n - 1), k + 1, k)


def _check_weights(weights: Any, what: str, min_dims: int = 1) -> np.ndarray:
    try:
        w = np.asarray(weights, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(f"{what}: weights must be numbers") from None
    if w.ndim < min_dims or w.shape[-1] < 1 or w.size == 0:
        raise ParameterError(f"{what}: weights need at least {min_dims} non-empty dimension(s)")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ParameterError(f"{what}: weights must be finite and >= 0")
    return w


def normalized_cdf(w: np.ndarray) -> np.ndarray:
    """``(..., n) -> (..., n + 1)`` CDF from 0 to exactly 1 (float64, host); an all-zero row
    becomes uniform. ``w`` must be finite and non-negative."""
    total = w.sum(axis=-1, keepdims=True)
    n = w.shape[-1]
    w = np.where(total > 0, w, 1.0)
    total = np.where(total > 0, total, float(n))
    c = np.cumsum(w, axis=-1) / total
    c = np.concatenate([np.zeros((*w.shape[:-1], 1)), c], axis=-1)
    c[..., -1] = 1.0
    return np.minimum(c, 1.0)


def find_interval(cdf_flat: Array, base: Array, n: int, u: Array) -> Array:
    """Largest ``k`` in ``[0, n)`` with ``cdf_flat[base + k] <= u`` for each query (int32).

    ``cdf_flat`` holds many CDFs of ``n + 1`` entries back to back; ``base`` is where each query's
    CDF starts. Written as a branchless binary search with a fixed number of gathers because
    ``jnp.searchsorted`` searches a single sorted array, while here every query may search a
    different row.
    """
    idx = jnp.zeros(u.shape, jnp.int32)
    step = 1 << max(0, (n - 1).bit_length() - 1) if n > 1 else 0
    # base and each step's index are stored (gonio.brdf._xla.materialize): otherwise XLA
    # recomputes them inside every later step's gather loop and keeps every step's gathered
    # values alive to the end, a large share of inversion sampling's cost
    # (benchmarks/bench_throughput.py)
    if step:
        (base,) = materialize([jnp.broadcast_to(base, u.shape)], u)
    while step:
        cand = idx + step
        ok = cand <= n - 1
        val = jnp.take(cdf_flat, base + jnp.minimum(cand, n - 1), mode="clip")
        idx = jnp.where(ok & (val <= u), cand, idx)
        step >>= 1
        if step:
            (idx,) = materialize([idx], u)
    return idx


@jax.tree_util.register_pytree_node_class
class Distribution1D:
    """Piecewise-constant density on ``[0, 1)`` with ``n`` equal bins (or a batch of them).

    Parameters
    ----------
    weights : ``(..., n)`` non-negative; each row is normalized (an all-zero row is uniform).

    Attributes
    ----------
    probs : ``(..., n)`` float64 bin probabilities (NumPy).
    cdf : ``(..., n + 1)`` float64 (NumPy).
    """

    def __init__(self, weights: Any) -> None:
        w = _check_weights(weights, "Distribution1D")
        self.batch_shape = w.shape[:-1]
        self.n = w.shape[-1]
        flat = normalized_cdf(w).reshape(-1)
        self._cdf = {jnp.float64: _put(flat), jnp.float32: _put(flat, np.float32)}

    def tree_flatten(self) -> tuple[tuple[Array, Array], tuple[Any, ...]]:
        return (self._cdf[jnp.float64], self._cdf[jnp.float32]), (self.batch_shape, self.n)

    @classmethod
    def tree_unflatten(cls, aux: tuple[Any, ...], leaves: Any) -> Distribution1D:
        obj = object.__new__(cls)
        obj.batch_shape, obj.n = aux
        obj._cdf = {jnp.float64: leaves[0], jnp.float32: leaves[1]}
        return obj

    @property
    def cdf(self) -> np.ndarray:
        return np.asarray(self._cdf[jnp.float64]).reshape(*self.batch_shape, self.n + 1)

    @property
    def probs(self) -> np.ndarray:
        return np.diff(self.cdf, axis=-1)

    def _arrays(self, dtype: Any) -> Array:
        return self._cdf[jnp.float64 if jnp.dtype(dtype) == jnp.float64 else jnp.float32]

    def _base(self, which: Any, shape: tuple[int, ...]) -> Array:
        if which is None:
            if self.batch_shape:
                raise ParameterError("Distribution1D: a batched distribution needs 'which'")
            return jnp.zeros(shape, jnp.int32)
        return jnp.asarray(which, jnp.int32) * (self.n + 1)

    def sample_discrete(
        self, u: Any, which: Any = None, *, clip: bool = True
    ) -> tuple[Array, Array, Array]:
        """Draw a bin: ``(index int32, u_remapped in [0, 1), probability of the bin)``.

        ``clip=False``: ``u`` is already a float array in [0, 1) (saves a pass over it).
        """
        u = _float_u(u) if clip else u
        return sample_discrete_cdf(self._arrays(u.dtype), self._base(which, u.shape), self.n, u)

    def sample(self, u: Any, which: Any = None) -> tuple[Array, Array, Array]:
        """Draw ``x in [0, 1)``: ``(x, density at x, bin index)``."""
        k, r, p = self.sample_discrete(u, which)
        return bin_position(k, r, self.n), p * self.n, k

    def pdf(self, x: Any, which: Any = None) -> Array:
        """Density at ``x in [0, 1)`` (0 outside)."""
        x = jnp.asarray(x)
        if not jnp.issubdtype(x.dtype, jnp.floating):
            x = x.astype(jnp.float64)
        k = bin_of(x, self.n)
        cdf = self._arrays(x.dtype)
        base = self._base(which, x.shape)
        p = jnp.take(cdf, base + k + 1, mode="clip") - jnp.take(cdf, base + k, mode="clip")
        return jnp.where((x >= 0) & (x < 1), p * self.n, 0.0)

    def prob(self, k: Any, which: Any = None, dtype: Any = jnp.float64) -> Array:
        """Probability of bin ``k`` (as the sampler in ``dtype`` realizes it)."""
        k = jnp.asarray(k, jnp.int32)
        cdf = self._arrays(dtype)
        base = self._base(which, k.shape)
        return jnp.take(cdf, base + k + 1, mode="clip") - jnp.take(cdf, base + k, mode="clip")


def sample_discrete_cdf(cdf: Array, base: Array, n: int, u: Array) -> tuple[Array, Array, Array]:
    k = find_interval(cdf, base, n, u)
    lo = jnp.take(cdf, base + k, mode="clip")
    hi = jnp.take(cdf, base + k + 1, mode="clip")
    p = hi - lo
    r = jnp.where(p > 0, (u - lo) / jnp.where(p > 0, p, 1.0), 0.0)
    return k, jnp.clip(r, 0.0, _one_minus_eps(u.dtype)), p


@jax.tree_util.register_pytree_node_class
class Distribution2D:
    """Piecewise-constant density on ``[0, 1)^2`` over an ``ny x nx`` grid (or a batch of them),
    sampled by marginal (rows, ``u[..., 0]``) then conditional (columns, ``u[..., 1]``) CDF
    inversion. Row ``iy`` covers ``y in [iy / ny, (iy + 1) / ny)``, column ``ix`` covers ``x``
    likewise.

    Parameters
    ----------
    weights : ``(..., ny, nx)`` non-negative cell weights.
    """

    def __init__(self, weights: Any) -> None:
        w = _check_weights(weights, "Distribution2D", min_dims=2)
        self.batch_shape = w.shape[:-2]
        self.ny, self.nx = w.shape[-2:]
        self.marginal = Distribution1D(w.sum(axis=-1))
        self.conditional = Distribution1D(w)

    def tree_flatten(self) -> tuple[tuple[Distribution1D, Distribution1D], tuple[Any, ...]]:
        return (self.marginal, self.conditional), (self.batch_shape, self.ny, self.nx)

    @classmethod
    def tree_unflatten(cls, aux: tuple[Any, ...], leaves: Any) -> Distribution2D:
        obj = object.__new__(cls)
        obj.batch_shape, obj.ny, obj.nx = aux
        obj.marginal, obj.conditional = leaves
        return obj

    @property
    def probs(self) -> np.ndarray:
        """``(..., ny, nx)`` float64 cell probabilities (NumPy)."""
        return self.marginal.probs[..., :, None] * self.conditional.probs

    def sample(self, u: Any, which: Any = None) -> tuple[Array, Array, tuple[Array, Array]]:
        """``u (..., 2) -> (xy (..., 2) in [0, 1)^2, density on the unit square, (iy, ix))``."""
        cells, (ry, rx), p = self.sample_cell(u, which)
        iy, ix = cells
        x = bin_position(ix, rx, self.nx)
        y = bin_position(iy, ry, self.ny)
        return jnp.stack([x, y], -1), p * (self.nx * self.ny), (iy, ix)

    def sample_cell(
        self, u: Any, which: Any = None, *, clip: bool = True
    ) -> tuple[tuple[Array, Array], tuple[Array, Array], Array]:
        """Draw a cell: ``((iy, ix), (ry, rx) remapped uniforms in the cell, cell probability)``.

        ``clip=False``: ``u`` is already a float array in [0, 1)^2. Callers inside a kernel pass
        it so: a second clip there is not free on XLA's CPU backend (it is fused into the
        inversion kernel's gather loops).
        """
        u = _float_u(u) if clip else u
        iy, ry, py = self.marginal.sample_discrete(u[..., 0], which, clip=False)
        row = iy if which is None else jnp.asarray(which, jnp.int32) * self.ny + iy
        ix, rx, px = self.conditional.sample_discrete(u[..., 1], row, clip=False)
        return (iy, ix), (ry, rx), py * px

    def cell_prob(self, iy: Any, ix: Any, which: Any = None, dtype: Any = jnp.float64) -> Array:
        """Probability of cell ``(iy, ix)`` exactly as :meth:`sample_cell` realizes it."""
        iy = jnp.asarray(iy, jnp.int32)
        ix = jnp.asarray(ix, jnp.int32)
        row = iy if which is None else jnp.asarray(which, jnp.int32) * self.ny + iy
        return self.marginal.prob(iy, which, dtype) * self.conditional.prob(ix, row, dtype)

    def pdf(self, xy: Any, which: Any = None) -> Array:
        """Density at ``xy (..., 2)`` on the unit square (0 outside)."""
        xy = jnp.asarray(xy)
        if not jnp.issubdtype(xy.dtype, jnp.floating):
            xy = xy.astype(jnp.float64)
        x, y = xy[..., 0], xy[..., 1]
        ix = bin_of(x, self.nx)
        iy = bin_of(y, self.ny)
        p = self.cell_prob(iy, ix, which, xy.dtype) * (self.nx * self.ny)
        inside = (x >= 0) & (x < 1) & (y >= 0) & (y < 1)
        return jnp.where(inside, p, 0.0)


def vose_alias(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vose's alias construction for one normalized distribution ``p (n,)``.

    A plain Python loop: the construction is inherently sequential (two work lists), runs once per
    table, and neither NumPy nor SciPy provides it.
    """
    n = p.size
    scaled = (p * n).tolist()
    q = [1.0] * n
    alias = list(range(n))
    small = [i for i, s in enumerate(scaled) if s < 1.0]
    large = [i for i, s in enumerate(scaled) if s >= 1.0]
    while small and large:
        s = small.pop()
        g = large.pop()
        q[s] = scaled[s]
        alias[s] = g
        scaled[g] = (scaled[g] + scaled[s]) - 1.0
        (small if scaled[g] < 1.0 else large).append(g)
    for i in large + small:  # leftovers are 1 up to rounding
        q[i] = 1.0
        alias[i] = i
    return np.asarray(q), np.asarray(alias, dtype=np.int32)


def alias_arrays(w: np.ndarray) -> dict[str, np.ndarray]:
    """Alias table of the weights ``w (n,)`` (positive sum, host): thresholds ``q (n,)``,
    ``alias (n,)`` int32 and the probabilities ``p (n,)`` the table *realizes* (an outcome's
    mass collected from its own column and from the columns aliasing to it)."""
    q, alias = vose_alias(w / w.sum())
    n = w.size
    realized = q / n
    np.add.at(realized, alias, (1.0 - q) / n)
    return {"q": q, "alias": alias, "p": realized}


class AliasTable:
    """Walker/Vose alias table: draws one of ``n`` outcomes in O(1) (or a batch of tables).

    Parameters
    ----------
    weights : ``(..., n)`` non-negative (an all-zero row is uniform).

    The probability reported for an outcome (``probs``) is the one the table realizes: an
    outcome's mass is collected from its own column and from the columns aliasing to it.
    """

    def __init__(self, weights: Any) -> None:
        w = _check_weights(weights, "AliasTable")
        self.batch_shape = w.shape[:-1]
        self.n = w.shape[-1]
        rows = w.reshape(-1, self.n)
        total = rows.sum(axis=1, keepdims=True)
        p = np.where(total > 0, rows / np.where(total > 0, total, 1.0), 1.0 / self.n)
        q = np.empty_like(p)
        alias = np.empty(p.shape, np.int32)
        for r in range(p.shape[0]):
            q[r], alias[r] = vose_alias(p[r])
        self.threshold = q.reshape(w.shape)
        self.alias = alias.reshape(w.shape)
        # the realized probabilities, recomputed from the table itself
        realized = q / self.n
        for r in range(p.shape[0]):
            np.add.at(realized[r], alias[r], (1.0 - q[r]) / self.n)
        self.probs = realized.reshape(w.shape)
        flat_alias = (alias + (np.arange(p.shape[0], dtype=np.int32) * self.n)[:, None]).reshape(-1)
        self._alias = _put(flat_alias, np.int32)
        self._q = {jnp.float64: _put(q.reshape(-1)), jnp.float32: _put(q.reshape(-1), np.float32)}
        self._p = {
            jnp.float64: _put(realized.reshape(-1)),
            jnp.float32: _put(realized.reshape(-1), np.float32),
        }

    def _key(self, dtype: Any) -> Any:
        return jnp.float64 if jnp.dtype(dtype) == jnp.float64 else jnp.float32

    def sample_discrete(self, u: Any, which: Any = None) -> tuple[Array, Array, Array]:
        """Draw an outcome: ``(index int32, u_remapped in [0, 1), probability of the outcome)``."""
        u = _float_u(u)
        if which is None:
            if self.batch_shape:
                raise ParameterError("AliasTable: a batched table needs 'which'")
            base = jnp.zeros(u.shape, jnp.int32)
        else:
            base = jnp.asarray(which, jnp.int32) * self.n
        key = self._key(u.dtype)
        return alias_sample(self._q[key], self._alias, self._p[key], base, self.n, u)

    def prob(self, k: Any, which: Any = None, dtype: Any = jnp.float64) -> Array:
        k = jnp.asarray(k, jnp.int32)
        base = 0 if which is None else jnp.asarray(which, jnp.int32) * self.n
        return jnp.take(self._p[self._key(dtype)], base + k, mode="clip")


def alias_sample(
    q: Array, alias_flat: Array, probs: Array, base: Array, n: int, u: Array
) -> tuple[Array, Array, Array]:
    """Core of :meth:`AliasTable.sample_discrete` on flat arrays (``alias_flat`` holds flat
    indices); returns ``(index within the row, u_remapped, probability)``.

    One number picks the column and, with what is left of its bits, keeps the column or takes
    its alias: fine in float64 or for small ``n``; for thousands of outcomes in float32 use
    :func:`alias_sample_2d`."""
    s = u * n
    col = jnp.minimum(jnp.floor(s).astype(jnp.int32), n - 1)
    r = s - col.astype(u.dtype)
    flat = base + col
    thr = jnp.take(q, flat, mode="clip")
    keep = r < thr
    chosen = jnp.where(keep, flat, jnp.take(alias_flat, flat, mode="clip"))
    rr = jnp.where(
        keep, r / jnp.where(thr > 0, thr, 1.0), (r - thr) / jnp.where(thr < 1, 1 - thr, 1.0)
    )
    rr = jnp.clip(rr, 0.0, _one_minus_eps(u.dtype))
    return chosen - base, rr, jnp.take(probs, chosen, mode="clip")


def alias_sample_2d(
    q: Array, alias_flat: Array, probs: Array, base: Array, n: int, u_col: Array, u_keep: Array
) -> tuple[Array, Array, Array, Array]:
    """:func:`alias_sample` with two uniform numbers: ``u_col`` picks the column, ``u_keep``
    decides between the column and its alias.

    With one number split over ``n`` columns only ``24 - log2(n)`` of a float32's bits are left
    for that decision (11 for 8192 cells), so a column whose threshold is below ``2**-11``
    would be kept with the wrong probability. Returns ``(index within the row, fractional part
    of u_col * n, u_keep remapped to [0, 1), probability)``: the two remapped numbers are
    independent and uniform given the outcome, ready to place a sample inside a 2-D cell.
    """
    s = u_col * n
    col = jnp.minimum(jnp.floor(s).astype(jnp.int32), n - 1)
    frac = jnp.clip(s - col.astype(u_col.dtype), 0.0, _one_minus_eps(u_col.dtype))
    flat = base + col
    thr = jnp.take(q, flat, mode="clip")
    keep = u_keep < thr
    chosen = jnp.where(keep, flat, jnp.take(alias_flat, flat, mode="clip"))
    rr = jnp.where(
        keep,
        u_keep / jnp.where(thr > 0, thr, 1.0),
        (u_keep - thr) / jnp.where(thr < 1, 1 - thr, 1.0),
    )
    rr = jnp.clip(rr, 0.0, _one_minus_eps(u_keep.dtype))
    return chosen - base, frac, rr, jnp.take(probs, chosen, mode="clip")


# ---------------------------------------------------------------------------------------------
# Rejection sampling
# ---------------------------------------------------------------------------------------------
def _hash32(x: Array) -> Array:
    """``lowbias32`` integer hash (Chris Wellons): a bijection on uint32 with good avalanche."""
    x = x ^ (x >> 16)
    x = x * jnp.uint32(0x7FEB352D)
    x = x ^ (x >> 15)
    x = x * jnp.uint32(0x846CA68B)
    return x ^ (x >> 16)


def seeds_from_u(u: Array) -> Array:
    """A uint32 seed per query derived from the bits of its uniforms ``u (..., k)``.

    This is the deterministic default source of the extra random numbers a rejection sampler
    needs: the same ``u`` always gives the same sample.
    """
    u = jnp.asarray(u)
    if u.dtype == jnp.float64:
        b = jax.lax.bitcast_convert_type(u, jnp.uint64)
        b32 = (b ^ (b >> 32)).astype(jnp.uint32)
    else:
        b32 = jax.lax.bitcast_convert_type(u.astype(jnp.float32), jnp.uint32)
    h = jnp.full(u.shape[:-1], 0x9E3779B9, jnp.uint32)
    for k in range(u.shape[-1]):
        h = _hash32(h ^ _hash32(b32[..., k] + jnp.uint32(k * 0x632BE5AB)))
    return h


def seeds_from_rng(rng: Any, shape: tuple[int, ...]) -> Array:
    """uint32 seeds from a NumPy Generator, an integer seed, or a JAX PRNG key."""
    if isinstance(rng, (int, np.integer)):
        rng = np.random.default_rng(int(rng))
    if isinstance(rng, np.random.Generator):
        return jnp.asarray(rng.integers(0, 2**32, size=shape, dtype=np.uint64).astype(np.uint32))
    try:
        return jax.random.bits(rng, shape, jnp.uint32)
    except (TypeError, ValueError):
        raise ParameterError(
            "rng must be a numpy Generator, an integer seed or a JAX PRNG key"
        ) from None


def hash_uniform(seed: Array, counter: int | Array, dtype: Any = jnp.float32) -> Array:
    """A uniform number in ``[0, 1)`` from ``(seed, counter)``: counter-based, stateless."""
    x = _hash32(seed ^ _hash32(jnp.asarray(counter, jnp.uint32) * jnp.uint32(0x9E3779B9) + 1))
    x = _hash32(x + jnp.uint32(0x85EBCA6B))
    if jnp.dtype(dtype) == jnp.float64:
        y = _hash32(x ^ jnp.uint32(0xC2B2AE35))
        v = (x.astype(jnp.float64) * 2.0**21 + (y >> 11).astype(jnp.float64)) * 2.0**-53
        return v.astype(jnp.float64)
    return ((x >> 8).astype(jnp.float32) * np.float32(2.0**-24)).astype(dtype)


def _later_uniforms(seeds: Array, rounds: Array, dtype: Any) -> tuple[Array, Array]:
    """``(u_prop (m, 2), u_acc (m,))`` of proposal number ``rounds`` (1, 2, ...) of each query:
    :func:`hash_uniform` counters ``3r, 3r + 1`` and ``3r + 2`` (see
    :func:`rejection_sample_traced`)."""
    r = jnp.asarray(rounds, jnp.uint32)
    up = jnp.stack([hash_uniform(seeds, 3 * r, dtype), hash_uniform(seeds, 3 * r + 1, dtype)], -1)
    return up, hash_uniform(seeds, 3 * r + 2, dtype)


def rejection_sample_traced(
    round_fn: Callable[..., tuple[Any, Array]],
    inputs: tuple[Array, ...],
    u: Array,
    seeds: Array,
    max_rounds: int = 4096,
) -> tuple[Any, Array, Array]:
    """Run a vectorized rejection sampler until every query has accepted a proposal (or used
    ``max_rounds``): one ``lax.while_loop``, traceable, called under ``jax.jit``.

    ``round_fn(*inputs, u_prop (m, 2), u_acc (m,)) -> (x, accepted (m,))`` draws one proposal
    per query from ``u_prop`` and accepts it when ``u_acc`` is below the acceptance ratio; ``x``
    is an array ``(m, ...)`` or a tuple of them. Query ``i``'s ``r``-th proposal uses the
    caller's ``u`` when ``r = 0`` and :func:`hash_uniform` counters ``3r, 3r + 1`` of its seed
    after that; its acceptance test uses ``3r + 2`` (counter 2 in the first round).

    Returns ``(x, ok (N,), rounds (N,) int32)``: the accepted proposals (the last one where a
    query failed), whether each query accepted, and how many proposals it used.

    Every query's first proposal is made in one pass; after that each iteration gathers the
    pending queries into a fixed number of lanes (an eighth of the batch, at least 1024) and,
    when fewer are pending than there are lanes, gives each of them several consecutive
    proposals, keeping the first accepted. Proposals depend only on the query's seed and
    counter, so the result is that of query-by-query rounds.
    """
    n = u.shape[0]
    dtype = u.dtype
    x, ok = round_fn(*inputs, u, hash_uniform(seeds, 2, dtype))
    rounds = jnp.ones(n, jnp.int32)
    if n == 0 or max_rounds <= 1:
        return x, ok, rounds
    # an eighth of the batch: about the pending queries left by an acceptance of 0.85 (a
    # larger retry batch leaves lanes idle after its first pass)
    lanes = n if n <= 1024 else max(1024, n // 8)
    leaves, tree = jax.tree.flatten(x)
    lane = jnp.arange(lanes, dtype=jnp.int32)
    none = jnp.int32(lanes)  # "no accepted proposal" in a segment minimum

    def pending(ok, rounds):
        return ~ok & (rounds < max_rounds)

    def cond(c):
        _, ok, rounds = c
        return jnp.any(pending(ok, rounds))

    def body(c):
        leaves, ok, rounds = c
        pend = pending(ok, rounds)
        served = jnp.minimum(jnp.sum(pend, dtype=jnp.int32), lanes)  # queries this iteration
        k = jnp.maximum(lanes // jnp.maximum(served, 1), 1)  # proposals per query
        (query,) = jnp.nonzero(pend, size=lanes, fill_value=0)  # query of each slot
        # lane -> (slot, consecutive proposal of that slot's query)
        slot = lane // k
        sub = lane - slot * k
        q = query[slot]
        r = rounds[q] + sub
        live = (slot < served) & (r < max_rounds)
        up, ua = _later_uniforms(seeds[q], r, dtype)
        w, acc = round_fn(*(jnp.take(a, q, axis=0) for a in inputs), up, ua)
        acc = acc & live
        first = jax.ops.segment_min(jnp.where(acc, sub, none), slot, num_segments=lanes)
        # per slot (index = slot number): its query's outcome
        is_served = lane < served
        before = rounds[query]
        done = is_served & (first < none)
        used = jnp.minimum(k, max_rounds - before)  # proposals it could make
        failed = is_served & ~done & (before + used >= max_rounds)  # keeps its last one
        pick = jnp.clip(lane * k + jnp.where(done, first, used - 1), 0, lanes - 1)
        target = jnp.where(done | failed, query, n)  # n: dropped
        leaves = [
            leaf.at[target].set(jnp.take(new, pick, axis=0), mode="drop")
            for leaf, new in zip(leaves, jax.tree.leaves(w), strict=True)
        ]
        ok = ok.at[jnp.where(done, query, n)].set(True, mode="drop")
        after = jnp.where(done, before + first + 1, before + used)
        rounds = rounds.at[jnp.where(is_served, query, n)].set(after, mode="drop")
        return leaves, ok, rounds

    leaves, ok, rounds = jax.lax.while_loop(cond, body, (leaves, ok, rounds))
    return jax.tree.unflatten(tree, leaves), ok, rounds


__all__ = [
    "AliasTable",
    "Distribution1D",
    "Distribution2D",
    "alias_arrays",
    "alias_sample",
    "alias_sample_2d",
    "bin_of",
    "bin_position",
    "find_interval",
    "hash_uniform",
    "normalized_cdf",
    "rejection_sample_traced",
    "sample_discrete_cdf",
    "seeds_from_rng",
    "seeds_from_u",
    "vose_alias",
]
