"""Continuous marginal/conditional 2-D warps over bilinear grids, in JAX (:class:`Marginal2D`).

The one implementation behind RGL tensor files: :mod:`gonio.io.rgl_measured` evaluates, inverts
and samples a file's ``ndf``, ``sigma``, ``vndf``, ``luminance`` and colour tables with it, and
:mod:`gonio.io.rgl_write` builds a file's colour table through the same ``vndf`` warp.

A warp holds ``S`` slices of an ``H x W`` grid of non-negative values (``(*param_res, H, W)`` in
the file, the last axis contiguous) and the parameter values ``(p_0, ..., p_{D-1})`` at which the
slices are tabulated. Between slices every lookup is multilinear in the parameters (a slice index
found by ``find_interval``, weights clamped to [0, 1]); within a slice the density is the
bilinear interpolant of the grid over ``[0, 1]^2`` (``x`` along ``W``).

This is the representation of Dupuy & Jakob 2018 as their reference reader (the ``Marginal2D``
warp of Mitsuba 3, ``Continuous = true``) defines it: per slice a conditional CDF along ``x``
(trapezoid rule on the grid values) and a marginal CDF along ``y`` (trapezoid rule on the rows'
totals), both normalized by the slice's total; sampling inverts the marginal, then the
conditional, solving the quadratic of the linear interpolant inside the patch; ``invert`` is the
exact inverse of ``sample``; ``eval`` is the normalized density (or, for warps built without
CDFs, the plain interpolant of the raw values). Written from that description, not copied.

Everything here is pure ``jax.numpy`` and vectorized over any batch shape; the computation runs
in the dtype of the positions (float32 for rendering, float64 for fits).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf._xla import materialize

Array = jnp.ndarray

#: Relative slope below which a patch is treated as constant when solving its quadratic (the
#: reference reader's threshold).
_CONST_TOL = 1e-4


class Marginal2D(NamedTuple):
    """Arrays of one continuous 2-D warp (a JAX pytree); build with :func:`build` or
    :func:`build_channels`.

    Attributes
    ----------
    data : (S, H * W) slice values; normalized (each slice integrates to 1 over ``[0, 1]^2`` after
        multiplying by ``(W - 1)(H - 1)``) when ``cond`` is present, raw otherwise.
    cond : (S, H * W) conditional CDF along x per row (unnormalized per row), or None.
    marg : (S, H) marginal CDF along y, or None.
    params : tuple of D arrays, the parameter values of each slice axis (increasing).
    shape : (H, W) as a small int array (its static shape is what is used).
    single : ``(data, cond, marg)`` rounded to float32, read by float32 queries: the same
        values they would round to after the lookup, at half the memory traffic.
    """

    data: Array
    cond: Array | None
    marg: Array | None
    params: tuple[Array, ...]
    shape: Array
    single: tuple[Array, Array | None, Array | None] | None = None


def _f32(*arrays):
    return tuple(None if a is None else jnp.asarray(np.asarray(a, np.float32)) for a in arrays)


def _in(warp: Marginal2D, dtype) -> Marginal2D:
    """``warp`` with its tables in the query dtype (float32 copies for float32 queries)."""
    if warp.single is None or jnp.dtype(dtype) != jnp.float32:
        return warp
    data, cond, marg = warp.single
    return warp._replace(data=data, cond=cond, marg=marg)


def build(values: np.ndarray, params: list[np.ndarray], cdf: bool) -> Marginal2D:
    """A :class:`Marginal2D` from ``values`` ``(*param_res, H, W)`` (host-side, float64 sums).

    With ``cdf`` the slices are normalized and their CDFs built (for ``sample``/``invert``);
    without, ``eval`` interpolates the raw values.
    """
    values = np.asarray(values, dtype=np.float64)
    h, w = values.shape[-2:]
    slices = values.reshape(-1, h, w)
    if cdf:
        cond = np.zeros_like(slices)
        cond[:, :, 1:] = np.cumsum(0.5 * (slices[:, :, :-1] + slices[:, :, 1:]), axis=2)
        rows = cond[:, :, -1]
        marg = np.zeros((slices.shape[0], h))
        marg[:, 1:] = np.cumsum(0.5 * (rows[:, :-1] + rows[:, 1:]), axis=1)
        norm = 1.0 / marg[:, -1]
        data = slices * norm[:, None, None]
        cond_j = jnp.asarray((cond * norm[:, None, None]).reshape(len(slices), -1))
        marg_j = jnp.asarray(marg * norm[:, None])
    else:
        data = slices
        cond_j = marg_j = None
    data_j = jnp.asarray(data.reshape(len(slices), -1))
    return Marginal2D(
        data_j,
        cond_j,
        marg_j,
        tuple(jnp.asarray(np.asarray(p, dtype=np.float64)) for p in params),
        jnp.zeros((h, w), jnp.int8),
        _f32(data_j, cond_j, marg_j),
    )


def _hw(warp: Marginal2D) -> tuple[int, int]:
    return int(warp.shape.shape[0]), int(warp.shape.shape[1])


def find_interval(size: int, pred, like: Array) -> Array:
    """Largest ``i`` in ``[0, size - 2]`` with ``pred(i)`` true (0 if none), for a predicate
    that is true on a prefix of the indices: a branch-free binary search over the batch shape
    of ``like``. A ``fori_loop``, so that XLA neither unrolls the steps nor recomputes earlier
    steps inside later ones."""
    hi = max(size - 2, 0)
    i0 = jnp.zeros(like.shape, jnp.int32)
    if hi == 0:
        return i0
    n_steps = hi.bit_length()

    def body(k, i):
        cand = i + jnp.left_shift(jnp.int32(1), n_steps - 1 - k)
        ok = (cand <= hi) & pred(jnp.minimum(cand, hi))
        return jnp.where(ok, cand, i)

    return jax.lax.fori_loop(0, n_steps, body, i0)


def _corners(warp: Marginal2D, params: tuple[Array, ...], dtype) -> list[tuple[Array, Array]]:
    """Parameter interpolation: ``(slice index, weight)`` of each of the 2^D' corners (axes of
    a single value contribute one corner of weight 1), computed once (materialized)."""
    corners: list[tuple[Array, Array]] = [(jnp.zeros((), jnp.int32), jnp.ones((), dtype))]
    stride = 1
    strides = []
    for vals in reversed(warp.params):
        strides.append(stride)
        stride *= int(vals.shape[0])
    strides.reverse()
    like = None
    for vals, p, s in zip(warp.params, params, strides, strict=True):
        n = int(vals.shape[0])
        if n == 1:
            continue
        v = vals.astype(dtype)
        p = jnp.asarray(p, dtype)
        like = p if like is None else like
        i0 = find_interval(n, lambda k, v=v, p=p: v[k] < p, p)
        p0, p1 = v[i0], v[i0 + 1]
        w1 = jnp.clip((p - p0) / (p1 - p0), 0.0, 1.0)
        corners = [(o + i0 * s, w * (1 - w1)) for o, w in corners] + [
            (o + (i0 + 1) * s, w * w1) for o, w in corners
        ]
    if like is None:
        return corners
    shape = jnp.broadcast_shapes(*(jnp.shape(o) for o, _ in corners), like.shape)
    like = jnp.broadcast_to(like, shape)
    flat = [jnp.broadcast_to(x, shape) for c in corners for x in c]
    flat = materialize(flat, like)
    return [(flat[2 * k], flat[2 * k + 1]) for k in range(len(corners))]


def _lookup(arr: Array, row: int, corners, idx: Array, dtype) -> Array:
    """Parameter-interpolated ``arr[slice, idx]`` (``row`` = length of a slice in ``arr``)."""
    flat = arr.reshape(-1)
    out = None
    for off, w in corners:
        v = jnp.take(flat, off * row + idx, mode="clip").astype(dtype) * w
        out = v if out is None else out + v
    return out


def _patch(warp: Marginal2D, pos: Array) -> tuple[Array, Array, Array, Array]:
    h, w = _hw(warp)
    x = jnp.clip(pos[..., 0], 0.0, 1.0) * (w - 1)
    y = jnp.clip(pos[..., 1], 0.0, 1.0) * (h - 1)
    px = jnp.minimum(x.astype(jnp.int32), w - 2)
    py = jnp.minimum(y.astype(jnp.int32), h - 2)
    return px, py, x - px.astype(x.dtype), y - py.astype(y.dtype)


def _patch_values(warp: Marginal2D, corners, px: Array, py: Array, dtype):
    h, w = _hw(warp)
    n = h * w
    i = py * w + px
    d = warp.data
    return (
        _lookup(d, n, corners, i, dtype),
        _lookup(d, n, corners, i + 1, dtype),
        _lookup(d, n, corners, i + w, dtype),
        _lookup(d, n, corners, i + w + 1, dtype),
    )


def eval_warp(warp: Marginal2D, pos: Array, params: tuple[Array, ...] = ()) -> Array:
    """Density (or interpolated raw value, for warps without CDFs) at ``pos`` ``(..., 2)``."""
    dtype = pos.dtype
    warp = _in(warp, dtype)
    h, w = _hw(warp)
    corners = _corners(warp, params, dtype)
    px, py, fx, fy = _patch(warp, pos)
    v00, v10, v01, v11 = _patch_values(warp, corners, px, py, dtype)
    val = (1 - fy) * ((1 - fx) * v00 + fx * v10) + fy * ((1 - fx) * v01 + fx * v11)
    return val * ((w - 1) * (h - 1)) if warp.cond is not None else val


def eval_channels(warp: Marginal2D, pos: Array, params: tuple[Array, ...]) -> Array:
    """Raw interpolant of a multi-channel table at ``pos`` ``(..., 2)`` -> ``(..., C)``.

    ``warp`` comes from :func:`build_channels`: each slice holds C grids (a channel axis before
    the grid), all sharing one parameter interpolation and one bilinear patch. This equals
    treating the channel as one more interpolated parameter evaluated at its nodes (the
    reference reader's colour lookup at a channel's own wavelength), at a third of the cost.
    """
    dtype = pos.dtype
    warp = _in(warp, dtype)
    h, w = _hw(warp)
    n = h * w
    c_count = int(warp.data.shape[1]) // n
    corners = _corners(warp, params, dtype)
    px, py, fx, fy = materialize(_patch(warp, pos), pos[..., 0])
    i = py * w + px
    row = c_count * n
    out = []
    for c in range(c_count):
        j = i + c * n
        v00 = _lookup(warp.data, row, corners, j, dtype)
        v10 = _lookup(warp.data, row, corners, j + 1, dtype)
        v01 = _lookup(warp.data, row, corners, j + w, dtype)
        v11 = _lookup(warp.data, row, corners, j + w + 1, dtype)
        out.append((1 - fy) * ((1 - fx) * v00 + fx * v10) + fy * ((1 - fx) * v01 + fx * v11))
    return jnp.stack(out, -1)


def build_channels(values: np.ndarray, params: list[np.ndarray]) -> Marginal2D:
    """A multi-channel table ``(*param_res, C, H, W)`` for :func:`eval_channels`."""
    values = np.asarray(values, dtype=np.float64)
    c, h, w = values.shape[-3:]
    data = values.reshape(-1, c * h * w)
    return Marginal2D(
        jnp.asarray(data),
        None,
        None,
        tuple(jnp.asarray(np.asarray(p, dtype=np.float64)) for p in params),
        jnp.zeros((h, w), jnp.int8),
        _f32(data, None, None),
    )


def invert(warp: Marginal2D, pos: Array, params: tuple[Array, ...]) -> tuple[Array, Array]:
    """Inverse of :func:`sample`: the uniform point ``(..., 2)`` that maps to ``pos``, and the
    density at ``pos``."""
    dtype = pos.dtype
    warp = _in(warp, dtype)
    h, w = _hw(warp)
    n = h * w
    corners = _corners(warp, params, dtype)
    px, py, x, y = materialize(_patch(warp, pos), pos[..., 0])
    v00, v10, v01, v11 = _patch_values(warp, corners, px, py, dtype)
    c0 = (1 - y) * v00 + y * v01
    c1 = (1 - y) * v10 + y * v11
    pdf = (1 - x) * c0 + x * c1
    i = py * w + px
    sx = x * (c0 + 0.5 * x * (c1 - c0))
    sx = sx + (1 - y) * _lookup(warp.cond, n, corners, i, dtype)
    sx = sx + y * _lookup(warp.cond, n, corners, i + w, dtype)
    last = py * w + (w - 1)
    r0 = _lookup(warp.cond, n, corners, last, dtype)
    r1 = _lookup(warp.cond, n, corners, last + w, dtype)
    sx = sx / ((1 - y) * r0 + y * r1)
    sy = y * (r0 + 0.5 * y * (r1 - r0)) + _lookup(warp.marg, h, corners, py, dtype)
    return jnp.stack([sx, sy], -1), pdf * ((w - 1) * (h - 1))


def _solve_linear_cdf(a: Array, b: Array, s: Array) -> Array:
    """``t`` in [0, 1] with ``a t + (b - a) t^2 / 2 = s`` (the integral of a linear density
    from ``a`` to ``b``), as the reference reader solves it."""
    const = jnp.abs(a - b) < _CONST_TOL * (a + b)
    disc = jnp.maximum(a * a - 2.0 * s * (a - b), 0.0)
    num = jnp.where(const, 2.0 * s, a - jnp.sqrt(disc))
    den = jnp.where(const, a + b, a - b)
    return jnp.where(den != 0, num / jnp.where(den != 0, den, 1.0), num)


def sample(warp: Marginal2D, u: Array, params: tuple[Array, ...]) -> tuple[Array, Array]:
    """Warp uniform ``u`` ``(..., 2)`` to a point of the density; returns ``(pos, pdf)``."""
    dtype = u.dtype
    warp = _in(warp, dtype)
    h, w = _hw(warp)
    n = h * w
    eps = float(np.finfo(np.float32).eps) / 2
    u = jnp.clip(u, eps, 1.0 - eps)
    corners = _corners(warp, params, dtype)
    uy = u[..., 1]
    row = find_interval(h, lambda k: _lookup(warp.marg, h, corners, k, dtype) < uy, uy)
    uy = uy - _lookup(warp.marg, h, corners, row, dtype)
    base = row * w
    r0 = _lookup(warp.cond, n, corners, base + (w - 1), dtype)
    r1 = _lookup(warp.cond, n, corners, base + (2 * w - 1), dtype)
    t = _solve_linear_cdf(r0, r1, uy)
    ux = u[..., 0] * ((1 - t) * r0 + t * r1)
    row, t, ux = materialize([row, t, ux], ux)
    base = row * w

    def cond_at(k):
        a = _lookup(warp.cond, n, corners, base + k, dtype)
        b = _lookup(warp.cond, n, corners, base + w + k, dtype)
        return (1 - t) * a + t * b

    col = find_interval(w, lambda k: cond_at(k) < ux, ux)
    ux = ux - cond_at(col)
    col, ux = materialize([col, ux], ux)
    v00, v10, v01, v11 = _patch_values(warp, corners, col, row, dtype)
    c0 = (1 - t) * v00 + t * v01
    c1 = (1 - t) * v10 + t * v11
    s = _solve_linear_cdf(c0, c1, ux)
    pos = jnp.stack([(col.astype(dtype) + s) / (w - 1), (row.astype(dtype) + t) / (h - 1)], axis=-1)
    return pos, ((1 - s) * c0 + s * c1) * ((w - 1) * (h - 1))
