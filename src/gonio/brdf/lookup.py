"""Lookup kernels of gridded tables (pure JAX): direction pairs to half/diff angles, angles to
node indices, and multilinear or nearest interpolation over the valid nodes.

Interpolation is multilinear in the *warped index* coordinates of each :class:`Axis`; periodic
axes wrap around, the others clamp at their first and last node. Invalid nodes (``mask``) get no
weight and the weights of the remaining corners are renormalized; where no corner is valid the
result is 0.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf._xla import materialize
from gonio.brdf.grid import Axis

Array = jnp.ndarray


@dataclass(frozen=True)
class LookupSpec:
    """Static description of a table needed by the lookup kernel (hashable)."""

    axes: tuple[Axis, ...]
    parameterization: str
    interpolation: str
    has_mask: bool
    n_channels: int
    fold: int  # phi_d folding for iso tables: 0 none, 1 reciprocity, 2 reciprocity + mirror


# atan(a) ~= a P(a^2) on [0, 1]: odd polynomial fitted for minimal relative error (max 9e-8 in
# float64, 2.2e-7 evaluated in float32). XLA:CPU's float32 jnp.arctan2 is not vectorized and
# takes a large share of the table lookup and of inversion sampling (both timed by
# benchmarks/bench_throughput.py); float64 input keeps jnp.arctan2.
_ATAN_COEFFS = (
    0.9999999110764471,
    -0.33332092081615694,
    0.19971358427746339,
    -0.1402933562974844,
    0.09942544849997133,
    -0.05990181920915065,
    0.024555142746539572,
    -0.004779915421027742,
)


def atan2(y: Array, x: Array) -> Array:
    """``arctan2(y, x)`` in (-pi, pi]; a fast polynomial for float32/float16, exact for float64."""
    dtype = jnp.result_type(y, x)
    if dtype == jnp.float64:
        return jnp.arctan2(y, x)
    ax, ay = jnp.abs(x), jnp.abs(y)
    mx, mn = jnp.maximum(ax, ay), jnp.minimum(ax, ay)
    a = mn / jnp.where(mx > 0, mx, 1.0)
    s = a * a
    r = jnp.full_like(a, _ATAN_COEFFS[-1])
    for c in reversed(_ATAN_COEFFS[:-1]):
        r = r * s + c
    r = r * a
    r = jnp.where(ay > ax, np.float32(np.pi / 2) - r, r)
    r = jnp.where(x < 0, np.float32(np.pi) - r, r)
    return jnp.where(y < 0, -r, r).astype(dtype)


def _half_diff_fast(wi: Array, wo: Array, need_phi_h: bool) -> tuple[Array, ...]:
    """Rusinkiewicz angles without trigonometric round trips (same conventions as
    :func:`gonio.brdf.frames.half_diff`); hand-written because this is the hot path of lookups."""
    # per component, not jnp.sum over the last axis: a reduction would store h as (..., 3)
    hx, hy, hz = wi[..., 0] + wo[..., 0], wi[..., 1] + wo[..., 1], wi[..., 2] + wo[..., 2]
    inv_h = jax.lax.rsqrt(jnp.maximum(hx * hx + hy * hy + hz * hz, 1e-30))
    hx, hy, hz = hx * inv_h, hy * inv_h, hz * inv_h
    r2 = hx * hx + hy * hy
    pole = r2 <= 0
    inv_r = jnp.where(pole, 0.0, jax.lax.rsqrt(jnp.where(pole, 1.0, r2)))
    r = r2 * inv_r
    c = jnp.where(pole, 1.0, hx * inv_r)
    s = jnp.where(pole, 0.0, hy * inv_r)
    x, y, z = wi[..., 0], wi[..., 1], wi[..., 2]
    x1 = c * x + s * y
    y1 = -s * x + c * y
    dx = hz * x1 - r * z
    dz = r * x1 + hz * z
    theta_h = atan2(r, hz)
    theta_d = atan2(jnp.sqrt(dx * dx + y1 * y1), dz)
    two_pi = 2 * jnp.pi
    phi_d = atan2(y1, dx)
    phi_d = jnp.where(phi_d < 0, phi_d + two_pi, phi_d)
    if not need_phi_h:
        return theta_h, theta_d, phi_d
    phi_h = jnp.where(pole, 0.0, atan2(hy, hx))
    phi_h = jnp.where(phi_h < 0, phi_h + two_pi, phi_h)
    return theta_h, phi_h, theta_d, phi_d


def _coords(spec: LookupSpec, wi: Array, wo: Array) -> list[Array]:
    """Angles along each axis of the table for the direction pairs."""
    if spec.parameterization == "half_diff_iso":
        th, td, pd = _half_diff_fast(wi, wo, need_phi_h=False)
        if spec.fold >= 1:
            pd = jnp.where(pd >= jnp.pi, pd - jnp.pi, pd)
        if spec.fold >= 2:
            pd = jnp.minimum(pd, jnp.pi - pd)
        return [th, td, pd]
    th, ph, td, pd = _half_diff_fast(wi, wo, need_phi_h=True)
    return [th, ph, td, pd]


def _axis_corners(ax: Axis, angle: Array) -> tuple[Array, Array, Array]:
    """``(i0, i1, frac)`` of the two nodes bracketing ``angle`` and the weight of ``i1``."""
    return _index_corners(ax, _wrapped_index(ax, angle))


def _wrapped_index(ax: Axis, angle: Array) -> Array:
    """Continuous node index of ``angle``, wrapped into ``[0, n)`` on periodic axes."""
    t = ax.continuous_index(angle)
    if ax.periodic and ax.size > 1:
        t = jnp.mod(t, float(ax.size))
    return t


def _index_corners(ax: Axis, t: Array) -> tuple[Array, Array, Array]:
    """:func:`_axis_corners` from the output of :func:`_wrapped_index`."""
    n = ax.size
    if n == 1:
        zero = jnp.zeros(t.shape, jnp.int32)
        return zero, zero, jnp.zeros_like(t)
    if ax.periodic:
        i0f = jnp.floor(t)
        frac = t - i0f
        i0 = i0f.astype(jnp.int32)
        i0 = jnp.where(i0 >= n, i0 - n, i0)  # mod can round up to exactly n
        i1 = jnp.where(i0 + 1 >= n, 0, i0 + 1)
        return i0, i1, frac
    t = jnp.clip(t, 0.0, float(n - 1))
    i0 = jnp.minimum(jnp.floor(t).astype(jnp.int32), n - 2)
    frac = t - i0.astype(t.dtype)
    return i0, i0 + 1, frac


def _corner_params(spec: LookupSpec, coords: Sequence[Array]) -> list[tuple[Array, Array, Array]]:
    """Per axis ``(i0, i1, frac)`` (see :func:`_axis_corners`) from continuous indices stored
    once (:func:`gonio.brdf._xla.materialize`): otherwise XLA recomputes the angle-to-index
    arithmetic inside each of the gather loops, as scalar code (this and the stored denominator
    in :func:`interpolate` keep that work out of the loops; lookup throughput:
    ``benchmarks/bench_throughput.py``)."""
    ts = [_wrapped_index(ax, a) for ax, a in zip(spec.axes, coords, strict=True)]
    ts = materialize(ts, coords[0])
    return [_index_corners(ax, t) for ax, t in zip(spec.axes, ts, strict=True)]


def _strides(axes: Sequence[Axis]) -> list[int]:
    strides = [1] * len(axes)
    for a in range(len(axes) - 2, -1, -1):
        strides[a] = strides[a + 1] * axes[a + 1].size
    return strides


def corner_bits(mask: np.ndarray, axes: Sequence[Axis]) -> np.ndarray:
    """Per node, which corners of the interpolation cell it starts are valid: bit ``j`` of
    entry ``flat`` is the mask at corner ``j`` (in :func:`interpolate`'s order) of the cell
    whose first corner is node ``flat``. ``(*mask.shape)``, uint8 for 3-D tables (8 corners),
    uint16 for 4-D.

    One gather of these bits replaces a gather of the mask per corner in every lookup (a
    corner's second index is a function of its first: the next node, wrapped on periodic
    axes); the weights and sums are the same, so lookups are bit for bit those of the mask.
    """
    d = mask.ndim
    dtype = np.min_scalar_type(2 ** (2**d) - 1).type  # one bit per corner
    firsts, seconds = [], []
    for ax in axes:
        i0 = np.arange(ax.size)
        if ax.size == 1:
            i1 = i0
        elif ax.periodic:
            i1 = np.where(i0 + 1 >= ax.size, 0, i0 + 1)
        else:  # the last node never starts a cell (see _index_corners)
            i1 = np.minimum(i0 + 1, ax.size - 1)
        firsts.append(i0)
        seconds.append(i1)
    bits = np.zeros(mask.shape, dtype)
    for j, corner in enumerate(itertools.product((0, 1), repeat=d)):
        idx = np.ix_(*(s if b else f for f, s, b in zip(firsts, seconds, corner, strict=True)))
        bits |= mask[idx].astype(dtype) << dtype(j)
    return bits


def interpolate(
    spec: LookupSpec, data: tuple[Array, Array | None], coords: Sequence[Array]
) -> Array:
    """Multilinear or nearest lookup at axis angles.

    ``data`` is ``(values, bits)``: values ``(n_nodes, C)`` premultiplied by the mask (invalid
    nodes hold 0), and per node the validity of the corners of the cell it starts
    (:func:`corner_bits`), or None when every node is valid. Invalid corners get no weight:
    the result is the weighted mean of the valid ones (0 where none is).
    """
    vals, bits = data
    strides = _strides(spec.axes)
    dtype = coords[0].dtype
    per_axis = _corner_params(spec, coords)
    if spec.interpolation == "nearest" and bits is None:
        flat = sum(
            jnp.where(frac >= 0.5, i1, i0) * s
            for (i0, i1, frac), s in zip(per_axis, strides, strict=True)
        )
        return jnp.take(vals, flat, axis=0, mode="clip").astype(dtype)
    corners = []
    for corner in itertools.product((0, 1), repeat=len(per_axis)):
        flat = None
        w = None
        for (i0, i1, frac), b, s in zip(per_axis, corner, strides, strict=True):
            idx = (i1 if b else i0) * s
            flat = idx if flat is None else flat + idx
            wa = frac if b else 1 - frac
            w = wa if w is None else w * wa
        corners.append((flat, w))
    if bits is not None:
        # the cell's corner validity, one gather (corner 0 is the cell's first node)
        cell = jnp.take(bits, corners[0][0], axis=0, mode="clip").astype(jnp.int32)
        valid = [((cell >> j) & 1).astype(dtype) for j in range(len(corners))]
    if spec.interpolation == "nearest":
        best_w = None
        best_flat = None
        for (flat, w), m in zip(corners, valid, strict=True):
            score = w * m + m * 1e-6  # a valid corner always beats an invalid one
            if best_w is None:
                best_w, best_flat = score, flat
            else:
                better = score >= best_w  # ties go to the upper node: floor of the index
                best_w = jnp.where(better, score, best_w)
                best_flat = jnp.where(better, flat, best_flat)
        val = jnp.take(vals, best_flat, axis=0, mode="clip").astype(dtype)
        return jnp.where(best_w[..., None] > 0, val, 0.0)
    num = sum(w[..., None] * jnp.take(vals, flat, axis=0, mode="clip") for flat, w in corners)
    num = num.astype(dtype)
    if bits is None:
        return num
    den = sum(w * m for (_, w), m in zip(corners, valid, strict=True))
    (den,) = materialize([den.astype(dtype)], coords[0])  # once, not once per channel
    den = den[..., None]
    ok = den > 0
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


@partial(jax.jit, static_argnames=("spec",))
def eval_kernel(data: tuple[Array, Array | None], wi: Array, wo: Array, spec: LookupSpec) -> Array:
    coords = _coords(spec, wi, wo)
    val = interpolate(spec, data, coords)
    ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    return jnp.where(ok[..., None], val, 0.0)


__all__ = ["LookupSpec", "atan2", "corner_bits", "eval_kernel", "interpolate"]
