"""Outgoing-direction buckets and the incident-direction grid shared by the table samplers.

Outgoing directions are grouped in *buckets*: ``n_theta_o`` bins of theta_o (isotropic tables,
whose incident grid is then expressed relative to phi_o), or ``n_theta_o x 2 n_theta_o`` bins of
(theta_o, phi_o) (anisotropic tables). The incident grid has ``n_t`` rows uniform in theta_i
and ``n_p`` columns uniform in phi; a direction is placed in a cell uniformly in solid angle.
Per-bucket structures are built on demand and stacked (:class:`LazyBuckets`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf._xla import materialize
from gonio.brdf.lookup import atan2

Array = jnp.ndarray
HALF_PI = math.pi / 2
TWO_PI = 2 * math.pi


@dataclass(frozen=True)
class BucketGeometry:
    """Static geometry of the sampler (hashable, a jit static argument)."""

    iso: bool
    n_to: int
    n_po: int
    n_t: int
    n_p: int


def bucket_of(geo: BucketGeometry, wo: Array) -> Array:
    x, y, z = wo[..., 0], wo[..., 1], wo[..., 2]
    # the lookup's polynomial atan2 in float32 (see gonio.brdf.lookup.atan2 for why),
    # exact in float64; sample and pdf both bucket through here, so they always agree
    theta = atan2(jnp.sqrt(x * x + y * y), z)
    bt = jnp.clip(jnp.floor(theta * (geo.n_to / HALF_PI)).astype(jnp.int32), 0, geo.n_to - 1)
    if geo.iso:
        return bt
    phi = atan2(y, x)
    phi = jnp.where(phi < 0, phi + TWO_PI, phi)
    bp = jnp.clip(jnp.floor(phi * (geo.n_po / TWO_PI)).astype(jnp.int32), 0, geo.n_po - 1)
    return bt * geo.n_po + bp


def azimuth_frame(wo: Array) -> tuple[Array, Array]:
    """``(cos phi_o, sin phi_o)`` of ``wo``; ``(1, 0)`` at the pole (where atan2 gives 0)."""
    x, y = wo[..., 0], wo[..., 1]
    r2 = x * x + y * y
    pole = r2 <= 0
    inv = jnp.where(pole, 0.0, jax.lax.rsqrt(jnp.where(pole, 1.0, r2)))
    return jnp.where(pole, 1.0, x * inv), y * inv


def cell_of(geo: BucketGeometry, wi: Array, wo: Array, cos_asc: Array) -> tuple[Array, Array]:
    """Incident-grid cell ``(row, col)`` of ``wi`` (rows by cos theta, as the sampler builds)."""
    k = jnp.searchsorted(cos_asc, wi[..., 2], side="left").astype(jnp.int32)
    row = jnp.clip(geo.n_t - k, 0, geo.n_t - 1)
    x, y = wi[..., 0], wi[..., 1]
    if geo.iso:  # azimuth relative to wo's: rotate wi by -phi_o
        c, s = azimuth_frame(wo)
        x, y = c * x + s * y, c * y - s * x
    phi = atan2(y, x)
    phi = jnp.where(phi < 0, phi + TWO_PI, phi)
    phi = jnp.where(phi >= TWO_PI, 0.0, phi)
    col = jnp.clip(jnp.floor(phi * (geo.n_p / TWO_PI)).astype(jnp.int32), 0, geo.n_p - 1)
    return row, col


def direction_in_cell(
    geo: BucketGeometry,
    row: Array,
    col: Array,
    ry: Array,
    rx: Array,
    cos_desc: Array,
    wo: Array,
) -> Array:
    """A direction ``(..., 3)`` in cell ``(row, col)`` of the incident grid, at ``(ry, rx)``
    in [0, 1)^2 of the cell uniformly in solid angle (uniform in cos theta and phi)."""
    c0 = jnp.take(cos_desc, row)
    c1 = jnp.take(cos_desc, row + 1)
    ct = c0 - ry * (c0 - c1)
    cp, sp = _cos_sin_in_column(geo.n_p, col, rx, ct.dtype)
    # stored once (gonio.brdf._xla.materialize): otherwise XLA fuses the gathers above into the
    # loops below, which then run as scalar code once per output component (otherwise a large
    # share of the alias kernel's cost; benchmarks/bench_throughput.py times the samplers)
    ct, cp, sp = materialize([ct, cp, sp], ct)
    st = jnp.sqrt(jnp.maximum(1.0 - ct * ct, 0.0))
    if geo.iso:  # phi is relative to wo's azimuth: rotate by +phi_o
        c, s = azimuth_frame(wo)
        cp, sp = c * cp - s * sp, s * cp + c * sp
    return jnp.stack([st * cp, st * sp, ct], -1)


def _cos_sin_in_column(n_p: int, col: Array, rx: Array, dtype: Any) -> tuple[Array, Array]:
    """``cos phi, sin phi`` of ``phi = (col + rx) 2 pi / n_p`` (``rx`` in [0, 1)).

    The column's start angle comes from a table and the offset ``delta = rx 2 pi / n_p`` goes
    through short Taylor series (error below 1e-8 for ``delta <= pi / 4``), cheaper than XLA's
    CPU ``cos``/``sin`` (see :mod:`gonio.brdf._trig`) in the alias and inversion kernels."""
    width = TWO_PI / n_p
    if n_p < 8:  # offsets too wide for the series
        phi = (col.astype(dtype) + rx) * width
        return jnp.cos(phi), jnp.sin(phi)
    start = np.arange(n_p) * width
    c0 = jnp.take(jnp.asarray(np.cos(start), dtype), col)
    s0 = jnp.take(jnp.asarray(np.sin(start), dtype), col)
    d = rx * width
    d2 = d * d
    cd = 1.0 + d2 * (-1 / 2 + d2 * (1 / 24 + d2 * (-1 / 720 + d2 * (1 / 40320))))
    sd = d * (1.0 + d2 * (-1 / 6 + d2 * (1 / 120 + d2 * (-1 / 5040 + d2 * (1 / 362880)))))
    return c0 * cd - s0 * sd, s0 * cd + c0 * sd


def incident_grid(n_t: int, n_p: int) -> tuple[np.ndarray, np.ndarray]:
    """``(cos_desc (n_t + 1,), omega (n_t,))``: the row edges of an incident grid uniform in
    theta_i, as cosines from 1 down to exactly 0, and each row's cell solid angle (sr)."""
    cos_desc = np.cos(np.linspace(0.0, HALF_PI, n_t + 1))
    cos_desc[0], cos_desc[-1] = 1.0, 0.0
    return cos_desc, (cos_desc[:-1] - cos_desc[1:]) * (TWO_PI / n_p)


class LazyBuckets:
    """Per-bucket structures built on demand and stacked for the vectorized kernels."""

    def __init__(self, build: Any, combine: Any = None) -> None:
        """``build(buckets) -> {bucket: {name: ndarray}}``; ``combine``, optional, turns the
        stacked NumPy arrays ``{name: (slots, ...)}`` into the dict the kernels take (e.g. one
        batched distribution) instead of JAX copies of them."""
        self._build = build
        self._combine = combine
        self.items: dict[int, dict[str, np.ndarray]] = {}
        self._stack: tuple[Array, dict[str, Array]] | None = None
        self._cast: dict[Any, dict[str, Array]] = {}

    def ensure(self, buckets: np.ndarray) -> None:
        """Build the structures of the buckets in ``buckets`` (distinct indices) not built yet."""
        missing = [int(b) for b in buckets if int(b) not in self.items]
        if missing:
            # under an outer jit trace, build from the concrete table values, not staged ops
            with jax.ensure_compile_time_eval():
                self.items.update(self._build(missing))
            self._stack = None
            self._cast = {}

    def prepare(
        self, geo: BucketGeometry, wo: Any, dtype: Any = None, also_float32: bool = False
    ) -> tuple[Array, dict[str, Array]]:
        """Build the buckets that ``wo`` falls in (every bucket when ``wo`` is traced) and
        return :meth:`stacked`. ``wo``: directions ``(..., 3)``, or a list of such arrays (the
        union of their buckets). ``also_float32``: also the buckets of ``wo`` rounded to
        float32 (for samplers that propose in float32)."""
        n_buckets = geo.n_to * geo.n_po
        ws = list(wo) if isinstance(wo, list | tuple) else [wo]
        if any(isinstance(w, jax.core.Tracer) for w in ws):
            # inside jit the outgoing directions are unknown: build every bucket
            self.ensure(np.arange(n_buckets))
        else:
            flags = None
            for w in ws:
                met = buckets_met(geo, w)
                if also_float32 and w.dtype != jnp.float32:
                    met = met | buckets_met(geo, w.astype(jnp.float32))
                flags = met if flags is None else flags | met
            # one explicit copy of the flags (not of a bucket per direction)
            self.ensure(np.flatnonzero(jax.device_get(flags)))
        return self.stacked(n_buckets, dtype)

    def stacked(self, n_buckets: int, dtype: Any = None) -> tuple[Array, dict[str, Array]]:
        """``(slot_of, arrays)``: every built bucket's arrays stacked, floating-point ones in
        ``dtype`` if given (cast once per build, not per call)."""
        slot_of, arrays = self._stacked(n_buckets)
        if dtype is None:
            return slot_of, arrays
        cast = self._cast.get(dtype)
        if cast is None:
            with jax.ensure_compile_time_eval():
                cast = {
                    k: v.astype(dtype)
                    if isinstance(v, jax.Array) and jnp.issubdtype(v.dtype, jnp.floating)
                    else v
                    for k, v in arrays.items()
                }
            self._cast[dtype] = cast
        return slot_of, cast

    def _stacked(self, n_buckets: int) -> tuple[Array, dict[str, Array]]:
        if self._stack is None:
            keys = sorted(self.items)
            cap = 1 << max(0, (len(keys) - 1).bit_length())
            keys_padded = keys + [keys[0]] * (cap - len(keys))
            slot_of = np.zeros(n_buckets, np.int32)
            slot_of[keys] = np.arange(len(keys), dtype=np.int32)
            names = self.items[keys[0]].keys()
            # concrete arrays even when first asked for under a jit trace: the cache outlives
            # the trace (a staged constant would leak into the next trace)
            with jax.ensure_compile_time_eval():
                stacks = {
                    name: np.stack([self.items[k][name] for k in keys_padded]) for name in names
                }
                if self._combine is not None:
                    arrays = self._combine(stacks)
                else:
                    arrays = {name: jax.device_put(a) for name, a in stacks.items()}
                self._stack = (jax.device_put(slot_of), arrays)
        return self._stack


@partial(jax.jit, static_argnames=("geo",))
def buckets_met(geo: BucketGeometry, wo: Array) -> Array:
    """``(n_buckets,)`` bool: which outgoing buckets the directions ``wo (..., 3)`` fall in (a
    histogram on the device: only the flags come back, not a bucket per direction)."""
    b = bucket_of(geo, wo).reshape(-1)
    return jnp.zeros(geo.n_to * geo.n_po, bool).at[b].set(True)


def bucket_ranges(geo: BucketGeometry, b: int) -> tuple[float, float, float, float]:
    """``(theta_0, theta_1, phi_0, phi_1)`` of outgoing bucket ``b`` (radians; phi 0 for
    isotropic tables)."""
    bt, bp = divmod(b, geo.n_po)
    t0, t1 = bt * HALF_PI / geo.n_to, (bt + 1) * HALF_PI / geo.n_to
    if geo.iso:
        return t0, t1, 0.0, 0.0
    return t0, t1, bp * TWO_PI / geo.n_po, (bp + 1) * TWO_PI / geo.n_po


__all__ = [
    "BucketGeometry",
    "LazyBuckets",
    "azimuth_frame",
    "bucket_of",
    "bucket_ranges",
    "buckets_met",
    "cell_of",
    "direction_in_cell",
    "incident_grid",
]
