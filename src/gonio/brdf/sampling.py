"""Generic sampling building blocks: piecewise-constant 1-D/2-D distributions, alias tables and
rejection sampling.

Every structure may hold a *batch* of distributions (weights of shape ``(..., n)``); a query then
names the distribution it draws from with ``which`` (an integer array, flat index into the batch
dimensions). Construction runs once on the host (NumPy, float64); sampling and density
evaluation are pure JAX, vectorized over the queries, and keep the dtype of ``u`` (the float32
arrays are derived from the float64 ones, and every reported probability is computed from the
same arrays the sampler uses, so pdfs stay consistent with samples in either precision).

Used by :class:`gonio.brdf.tabulated.TabulatedBRDF` (sampling f cos over incident directions)
and by the renderer (environment-map importance sampling).

References: Pharr, Jakob & Humphreys, *Physically Based Rendering* 4th ed., sections A.1 (alias
method), A.5 (sampling piecewise-constant functions); Vose, "A linear algorithm for generating
random numbers with a given distribution", IEEE TSE 1991.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from functools import partial
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


def _float_u(u: Any) -> Array:
    u = jnp.asarray(u)
    if not jnp.issubdtype(u.dtype, jnp.floating):
        u = u.astype(jnp.float64)
    return jnp.clip(u, 0.0, _one_minus_eps(u.dtype))


def _bin_position(k: Array, r: Array, n: int) -> Array:
    """``(k + r) / n`` kept inside bin ``k`` as :func:`_bin_of` sees it, despite rounding."""
    dt = r.dtype
    kf = k.astype(dt)
    x = (kf + r) / n
    hi = jnp.nextafter((kf + 1) / n, jnp.zeros((), dt))
    return jnp.clip(x, kf / n, hi)


def _bin_of(x: Array, n: int) -> Array:
    """Bin ``k`` of ``x`` with the edges ``k / n`` computed in ``x``'s dtype (int32, clamped)."""
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


def _normalized_cdf(w: np.ndarray) -> np.ndarray:
    """``(..., n) -> (..., n + 1)`` CDF from 0 to exactly 1; an all-zero row becomes uniform."""
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
    # values alive to the end (together ~3x slower)
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


class Distribution1D:
    """Piecewise-constant density on ``[0, 1)`` with ``n`` equal bins (or a batch of them).

    Parameters
    ----------
    weights : ``(..., n)`` non-negative; each row is normalized (an all-zero row is uniform).

    Attributes
    ----------
    probs : ``(..., n)`` float64 bin probabilities.
    cdf : ``(..., n + 1)`` float64.
    """

    def __init__(self, weights: Any) -> None:
        w = _check_weights(weights, "Distribution1D")
        self.batch_shape = w.shape[:-1]
        self.n = w.shape[-1]
        self.cdf = _normalized_cdf(w)
        self.probs = np.diff(self.cdf, axis=-1)
        flat = self.cdf.reshape(-1)
        self._cdf = {jnp.float64: jnp.asarray(flat), jnp.float32: jnp.asarray(flat, jnp.float32)}

    def _arrays(self, dtype: Any) -> Array:
        return self._cdf[jnp.float64 if jnp.dtype(dtype) == jnp.float64 else jnp.float32]

    def _base(self, which: Any, shape: tuple[int, ...]) -> Array:
        if which is None:
            if self.batch_shape:
                raise ParameterError("Distribution1D: a batched distribution needs 'which'")
            return jnp.zeros(shape, jnp.int32)
        return jnp.asarray(which, jnp.int32) * (self.n + 1)

    def sample_discrete(self, u: Any, which: Any = None) -> tuple[Array, Array, Array]:
        """Draw a bin: ``(index int32, u_remapped in [0, 1), probability of the bin)``."""
        u = _float_u(u)
        return _sample_discrete_cdf(self._arrays(u.dtype), self._base(which, u.shape), self.n, u)

    def sample(self, u: Any, which: Any = None) -> tuple[Array, Array, Array]:
        """Draw ``x in [0, 1)``: ``(x, density at x, bin index)``."""
        k, r, p = self.sample_discrete(u, which)
        return _bin_position(k, r, self.n), p * self.n, k

    def pdf(self, x: Any, which: Any = None) -> Array:
        """Density at ``x in [0, 1)`` (0 outside)."""
        x = jnp.asarray(x)
        if not jnp.issubdtype(x.dtype, jnp.floating):
            x = x.astype(jnp.float64)
        k = _bin_of(x, self.n)
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


def _sample_discrete_cdf(cdf: Array, base: Array, n: int, u: Array) -> tuple[Array, Array, Array]:
    k = find_interval(cdf, base, n, u)
    lo = jnp.take(cdf, base + k, mode="clip")
    hi = jnp.take(cdf, base + k + 1, mode="clip")
    p = hi - lo
    r = jnp.where(p > 0, (u - lo) / jnp.where(p > 0, p, 1.0), 0.0)
    return k, jnp.clip(r, 0.0, _one_minus_eps(u.dtype)), p


class Distribution2D:
    """Piecewise-constant density on ``[0, 1)^2`` over an ``ny x nx`` grid (or a batch of them),
    sampled by marginal (rows, ``u[..., 0]``) then conditional (columns, ``u[..., 1]``) CDF
    inversion.

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
        self.probs = self.marginal.probs[..., :, None] * self.conditional.probs

    def sample(self, u: Any, which: Any = None) -> tuple[Array, Array, tuple[Array, Array]]:
        """``u (..., 2) -> (xy (..., 2) in [0, 1)^2, density on the unit square, (iy, ix))``."""
        cells, (ry, rx), p = self.sample_cell(u, which)
        iy, ix = cells
        x = _bin_position(ix, rx, self.nx)
        y = _bin_position(iy, ry, self.ny)
        return jnp.stack([x, y], -1), p * (self.nx * self.ny), (iy, ix)

    def sample_cell(
        self, u: Any, which: Any = None
    ) -> tuple[tuple[Array, Array], tuple[Array, Array], Array]:
        """Draw a cell: ``((iy, ix), (ry, rx) remapped uniforms in the cell, cell probability)``."""
        u = _float_u(u)
        iy, ry, py = self.marginal.sample_discrete(u[..., 0], which)
        row = iy if which is None else jnp.asarray(which, jnp.int32) * self.ny + iy
        ix, rx, px = self.conditional.sample_discrete(u[..., 1], row)
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
        ix = _bin_of(x, self.nx)
        iy = _bin_of(y, self.ny)
        p = self.cell_prob(iy, ix, which, xy.dtype) * (self.nx * self.ny)
        inside = (x >= 0) & (x < 1) & (y >= 0) & (y < 1)
        return jnp.where(inside, p, 0.0)


def _vose(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
            q[r], alias[r] = _vose(p[r])
        self.threshold = q.reshape(w.shape)
        self.alias = alias.reshape(w.shape)
        # the realized probabilities, recomputed from the table itself
        realized = q / self.n
        for r in range(p.shape[0]):
            np.add.at(realized[r], alias[r], (1.0 - q[r]) / self.n)
        self.probs = realized.reshape(w.shape)
        flat_alias = (alias + (np.arange(p.shape[0], dtype=np.int32) * self.n)[:, None]).reshape(-1)
        self._alias = jnp.asarray(flat_alias.astype(np.int32))
        self._q = {
            jnp.float64: jnp.asarray(q.reshape(-1)),
            jnp.float32: jnp.asarray(q.reshape(-1), jnp.float32),
        }
        self._p = {
            jnp.float64: jnp.asarray(realized.reshape(-1)),
            jnp.float32: jnp.asarray(realized.reshape(-1), jnp.float32),
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
    :func:`hash_uniform` counters ``3r, 3r + 1`` and ``3r + 2`` (see :func:`rejection_step`)."""
    r = jnp.asarray(rounds, jnp.uint32)
    up = jnp.stack([hash_uniform(seeds, 3 * r, dtype), hash_uniform(seeds, 3 * r + 1, dtype)], -1)
    return up, hash_uniform(seeds, 3 * r + 2, dtype)


class RejectionStep:
    """The jit-compiled proposal rounds that :func:`rejection_sample` runs (see
    :func:`rejection_step`): ``first`` for every query's first proposal, drawn from the
    caller's ``u``, and ``later`` for the hashed ones after it. Two functions rather than one
    with a select: XLA's CPU backend then never computes hashes it throws away, and the
    proposal fuses as it does alone (about 20 % faster)."""

    def __init__(self, round_fn: Callable[..., tuple[Array, Array]]) -> None:
        def first(inputs, u, seeds, consts):
            return round_fn(*inputs, u, hash_uniform(seeds, 2, u.dtype), *consts)

        def later(dtype, inputs, seeds, rounds, consts):
            return round_fn(*inputs, *_later_uniforms(seeds, rounds, dtype), *consts)

        self.first = jax.jit(first)
        # one function per dtype of u: a static keyword argument would take jit's slow
        # dispatch path on every call
        self._later = {
            jnp.dtype(dt): jax.jit(partial(later, jnp.dtype(dt)))
            for dt in (jnp.float32, jnp.float64)
        }

    def later(self, inputs, seeds, rounds, consts, dtype):
        """A proposal round after the first: ``rounds`` is its number (1, 2, ...)."""
        return self._later[jnp.dtype(dtype)](inputs, seeds, rounds, consts)


def rejection_step(round_fn: Callable[..., tuple[Array, Array]]) -> RejectionStep:
    """Wrap a one-proposal function into the jit-compiled steps :func:`rejection_sample` runs.

    ``round_fn(*inputs, u_prop (m, 2), u_acc (m,), *consts) -> (x, accepted (m,))`` draws one
    proposal per query from ``u_prop`` and accepts it when ``u_acc`` is below the acceptance
    ratio; ``x`` is an array ``(m, ...)`` or a tuple of them (a tuple rather than one
    concatenated array: XLA fuses a concatenation's producers into it, several times slower).
    Query ``i``'s ``r``-th proposal uses the caller's ``u`` when ``r = 0`` and
    :func:`hash_uniform` counters ``3r, 3r + 1`` after that; its acceptance test uses ``3r + 2``
    (counter 2 in the first round). Keep the returned step and reuse it: each new one compiles
    again.
    """
    return RejectionStep(round_fn)


_TAIL_LANES = 2048  # below this many pending queries, each gets several proposals per call
_IN_FLIGHT = 3  # calls dispatched ahead of the one whose results the host is reading


def _padded_size(m: int) -> int:
    """1024 times the smallest power of 4 that holds ``m`` rows (few shapes to compile)."""
    size = 1024
    while size < m:
        size *= 4
    return size


def _pieces(m: int, chunk: int) -> list[tuple[int, int]]:
    """``(start, stop)`` ranges covering ``m`` queries in calls of at most ``chunk``, each
    padded to :func:`_padded_size` with little waste: a remainder is cut into smaller pieces
    rather than padded by more than a quarter (every padded row is a wasted proposal)."""
    out = []
    start = 0
    while start < m:
        left = m - start
        size = min(chunk, _padded_size(left))
        if size > left and size > 1024 and size - left > left // 3:
            size //= 4  # e.g. 17000 left: 16384 now and 616 next, not one 65536 call
        stop = min(m, start + size)
        out.append((start, stop))
        start = stop
    return out


_HOST_ALIGN = 64  # bytes: XLA's CPU client adopts host arrays aligned to this without a copy


def _aligned_empty(shape: tuple[int, ...], dtype: Any) -> np.ndarray:
    """``np.empty(shape, dtype)`` starting on a ``_HOST_ALIGN``-byte boundary (unless empty).

    ``jax.device_put`` of such an array on the CPU backend wraps its memory instead of copying
    it (for :func:`rejection_sample`'s results, about 2.5 ms less CPU per 10^6 samples). NumPy
    has no aligned allocator (large blocks come from ``mmap`` 16 bytes past a page boundary),
    hence the over-allocation and offset.
    """
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    raw = np.empty(nbytes + _HOST_ALIGN, np.uint8)
    start = -raw.ctypes.data % _HOST_ALIGN
    return raw[start : start + nbytes].view(dtype).reshape(shape)


def _rows(a: np.ndarray) -> np.ndarray:
    """A view of a C-contiguous ``a (n, ...)`` as a 1-D array of opaque rows: NumPy scatters
    those about twice as fast as the rows of a 2-D array."""
    if a.ndim == 1:
        return a
    width = a.dtype.itemsize * int(np.prod(a.shape[1:]))
    return a.reshape(a.shape[0], -1).view(np.dtype((np.void, width)))[:, 0]


def _take_rows(a: np.ndarray, idx: Any) -> np.ndarray:
    """``a[idx]`` for a slice or an index array."""
    if isinstance(idx, slice):
        return a[idx]
    return np.take(a, idx, axis=0)  # for rows, about twice as fast as a[idx]


def rejection_sample(
    step: RejectionStep,
    inputs: tuple[Any, ...],
    u: Any,
    seeds: Any,
    max_rounds: int = 4096,
    consts: tuple[Any, ...] = (),
    chunk: int = 1 << 16,
) -> tuple[Any, Array, np.ndarray]:
    """Run a vectorized rejection sampler until every query has accepted a proposal.

    Parameters
    ----------
    step : from :func:`rejection_step`.
    inputs : per-query arrays with leading dimension N (e.g. the outgoing directions).
    u : ``(N, 2)`` the caller's uniforms, used for the first proposals.
    seeds : ``(N,)`` uint32 seeds of the further random numbers (:func:`seeds_from_u`,
        :func:`seeds_from_rng`).
    max_rounds : queries still rejected after this many proposals fail (``ok`` False).
    consts : extra arguments passed unchanged to every call.
    chunk : largest batch per call (1024 times a power of 4); smaller batches are padded to
        1024 times a power of 4, so only a few shapes are ever compiled. Batches of about 65536
        keep a proposal's intermediates in cache (1e6 at once runs about 1.5x slower on CPU).

    Returns
    -------
    x : ``(N, ...)`` accepted proposals, as the step returns them (array or tuple of arrays;
        the last proposal where failed).
    ok : ``(N,)`` bool.
    rounds : ``(N,)`` int32 NumPy array, the number of proposals each query used.

    Calls of up to ``chunk`` proposals are streamed (see ``_RejectionRun``): first proposals
    for the batch's rows in order, and further proposals for rejected queries as soon as a
    chunk of them is waiting; when the batch is done and fewer than ``_TAIL_LANES`` queries
    are left, each gets its next several proposals in one call and keeps the first accepted.
    The total work is about ``N / acceptance`` proposals, and the result is exactly that of
    query-by-query rounds, whatever the chunking.
    """
    inputs = tuple(np.asarray(a) for a in inputs)
    u = np.asarray(u)
    seeds = np.asarray(seeds)
    return _RejectionRun(step, inputs, u, seeds, max_rounds, consts, chunk).run()


def rejection_sample_traced(
    round_fn: Callable[..., tuple[Any, Array]],
    inputs: tuple[Array, ...],
    u: Array,
    seeds: Array,
    max_rounds: int = 4096,
) -> tuple[Any, Array, Array]:
    """:func:`rejection_sample` for traced inputs (inside ``jax.jit``): the same samples, the
    same ``(x, ok, rounds)``, from a ``lax.while_loop`` on the device.

    ``round_fn(*inputs, u_prop, u_acc)`` is the unwrapped proposal function of
    :func:`rejection_step`. Every query's first proposal is made in one pass; after that each
    iteration gathers the pending queries into a fixed number of lanes (an eighth of the
    batch, at least 1024) and, when fewer are pending than there are lanes, gives each of them
    several consecutive proposals, keeping the first accepted. Proposals depend only on the
    query's seed and counter, so the result is that of query-by-query rounds.
    """
    n = u.shape[0]
    dtype = u.dtype
    x, ok = round_fn(*inputs, u, hash_uniform(seeds, 2, dtype))
    rounds = jnp.ones(n, jnp.int32)
    if n == 0 or max_rounds <= 1:
        return x, ok, rounds
    # an eighth of the batch: about the pending queries left by an acceptance of 0.85 (a
    # quarter ran 20 % slower on the benchmark table, with lanes idle after the first pass)
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


class _RejectionRun:
    """The bookkeeping of :func:`rejection_sample`, streamed.

    Calls are kept ``_IN_FLIGHT`` deep: the first proposals of the next rows of the batch and,
    as soon as ``chunk`` of them are waiting, further proposals for rejected queries (each
    with its own proposal counter) go out while the host retires the oldest call's results,
    so that neither the device nor the host waits for the other between rounds. A query's
    proposals depend only on its seed and counter, so the samples are those of query-by-query
    rounds whatever the order of the calls.
    """

    def __init__(self, step, inputs, u, seeds, max_rounds, consts, chunk) -> None:
        self.step, self.inputs, self.u, self.seeds = step, inputs, u, seeds
        self.max_rounds, self.consts, self.chunk = max_rounds, consts, chunk
        n = u.shape[0]
        self.n = n
        self.rounds = np.ones(n, np.int32)
        self.ok = _aligned_empty((n,), bool)
        self.ok[:] = True
        self.out: list[np.ndarray] | None = None
        self.tree = None
        # rejected queries waiting for their next proposal, and that proposal's counter
        self.pool_q: list[np.ndarray] = []
        self.pool_r: list[np.ndarray] = []
        self.pool_n = 0

    def run(self) -> tuple[Any, Array, np.ndarray]:
        """Propose until every query has accepted or failed: ``(x, ok, rounds)``."""
        chunk = self.chunk
        in_flight: deque = deque()
        firsts = deque(_pieces(self.n, chunk))
        while True:
            while len(in_flight) < _IN_FLIGHT:
                if self.pool_n >= chunk or (self.pool_n and not firsts and not in_flight):
                    in_flight.append(self._dispatch_later(tail=not firsts and not in_flight))
                elif firsts:
                    in_flight.append(self._dispatch_first(*firsts.popleft()))
                else:
                    break
            if not in_flight:
                break
            self._retire(*in_flight.popleft())
        return self._result()

    # -- calls ---------------------------------------------------------------------------------
    def _dispatch_first(self, start: int, stop: int):
        m = stop - start
        size = _padded_size(m)
        idx = (
            slice(start, stop)
            if size == m
            else np.concatenate([np.arange(start, stop), np.full(size - m, start)])
        )
        args = tuple(_take_rows(a, idx) for a in self.inputs)
        res = self.step.first(args, self.u[idx], self.seeds[idx], self.consts)
        return np.arange(start, stop), None, 1, res

    def _dispatch_later(self, tail: bool):
        q = np.concatenate(self.pool_q)
        r = np.concatenate(self.pool_r)
        take = min(q.size, self.chunk)
        if take < q.size:
            self.pool_q, self.pool_r = [q[take:]], [r[take:]]
            q, r = q[:take], r[:take]
        else:
            self.pool_q, self.pool_r = [], []
        self.pool_n -= take
        k = 1
        if tail:  # few queries left: each gets its next k counters in this call
            k = max(1, min(_TAIL_LANES // q.size, int(self.max_rounds - r.max())))
        lanes = np.repeat(q, k) if k > 1 else q
        lane_r = (np.repeat(r, k) + np.tile(np.arange(k, dtype=np.int32), q.size)) if k > 1 else r
        m = lanes.size
        size = _padded_size(m)
        if size > m:
            lanes_p = np.concatenate([lanes, np.full(size - m, lanes[0])])
            lane_r = np.concatenate([lane_r, np.full(size - m, lane_r[0])])
        else:
            lanes_p = lanes
        args = tuple(_take_rows(a, lanes_p) for a in self.inputs)
        res = self.step.later(args, self.seeds[lanes_p], lane_r, self.consts, dtype=self.u.dtype)
        return q, r, k, res

    # -- results -------------------------------------------------------------------------------
    def _retire(self, q: np.ndarray, r: np.ndarray | None, k: int, res) -> None:
        x, acc = res
        leaves, self.tree = jax.tree.flatten(x)
        leaves = [np.asarray(a) for a in leaves]  # on the CPU: no copy
        if self.out is None:
            self.out = [_aligned_empty((self.n, *a.shape[1:]), a.dtype) for a in leaves]
        acc = np.asarray(acc)[: q.size * k]
        if r is None:  # first proposals: contiguous rows, the rejected ones fixed up later
            start = int(q[0])
            for o, a in zip(self.out, leaves, strict=True):
                o[start : start + q.size] = a[: q.size]
            rejected = np.flatnonzero(~acc) + start  # about 4x faster than q[~acc]
            if self.max_rounds <= 1:  # the first proposals were the last
                self.ok[rejected] = False
            else:
                self._requeue(rejected, np.ones(rejected.size, np.int32))
            return
        used = r + k  # proposals made by each query after this call
        if k == 1:  # one proposal per query: no search for the first accepted lane
            done, first = acc, 0
        else:
            acc_q = acc.reshape(-1, k)
            done, first = acc_q.any(axis=1), acc_q.argmax(axis=1)
        out_of_rounds = ~done & (used >= self.max_rounds)
        if out_of_rounds.any():  # keep their last proposal (lane k - 1), and fail them
            self.ok[q[out_of_rounds]] = False
            if k > 1:
                first = np.where(out_of_rounds, k - 1, first)
            done = done | out_of_rounds
        sel = np.flatnonzero(done)
        if k > 1:
            first = first[sel]
        lane = sel * k + first
        finished = q[sel]
        self.rounds[finished] = r[sel] + first + 1
        for o, a in zip(self.out, leaves, strict=True):
            _rows(o)[finished] = _rows(a)[lane]
        self._requeue(q[~done], used[~done])

    def _requeue(self, q: np.ndarray, r: np.ndarray) -> None:
        if q.size:
            self.pool_q.append(q)
            self.pool_r.append(r)
            self.pool_n += q.size

    def _result(self) -> tuple[Any, Array, np.ndarray]:
        if self.out is None:  # no queries: trace the step for the shapes of a proposal
            inputs, u, seeds = self.inputs, self.u, self.seeds
            shape = jax.eval_shape(
                self.step.first,
                tuple(np.zeros((1024, *a.shape[1:]), a.dtype) for a in inputs),
                np.zeros((1024, *u.shape[1:]), u.dtype),
                np.zeros(1024, seeds.dtype),
                self.consts,
            )[0]
            leaves, self.tree = jax.tree.flatten(shape)
            self.out = [np.zeros((0, *a.shape[1:]), a.dtype) for a in leaves]
        # aligned host arrays: device_put wraps them without a copy (jnp.asarray would copy)
        x = jax.tree.unflatten(self.tree, [jax.device_put(o) for o in self.out])
        return x, jax.device_put(self.ok), self.rounds


__all__ = [
    "AliasTable",
    "Distribution1D",
    "Distribution2D",
    "RejectionStep",
    "alias_sample",
    "alias_sample_2d",
    "find_interval",
    "hash_uniform",
    "rejection_sample",
    "rejection_sample_traced",
    "rejection_step",
    "seeds_from_rng",
    "seeds_from_u",
]
