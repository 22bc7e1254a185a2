"""Exact rejection sampling of tabulated BRDFs: the reference density ``g cos / rho(wo)``.

The sampled density is exactly ``g(wi, wo) cos(theta_i) / rho(wo)``, ``g = max(mean over
channels of f, 0)`` (not piecewise constant like inversion and alias): the reference the faster
samplers are checked against, not a fast path. Proposals: ``"majorant"`` (default), per outgoing
bucket (:mod:`gonio.brdf.sampling.table_buckets`) a bound ``m_c`` of ``g cos`` over each cell
``c`` of an incident grid twice as fine as the inversion's and every ``wo`` in the bucket, cells
drawn in proportion to ``m_c Omega_c`` (acceptance ``rho / sum_c m_c Omega_c``); or
``"cosine"``, the cosine-weighted hemisphere with a bound of ``pi g`` over the bucket.

The bounds are rigorous: interval ranges of the Rusinkiewicz angles theta_h and theta_d over the
cell and the bucket (:func:`half_diff_ranges`), then the largest valid table node those ranges
use (interpolation with renormalized weights never exceeds it), times the cell's largest
``cos theta_i``; small margins cover float32 rounding. ``rho(wo) = int g cos dwi`` is a 128 x 256
midpoint quadrature over the half vector (sqrt-warped theta_h, as the tables' nodes) at 9
theta_o nodes per bucket (5 x 5 (theta_o, phi_o) nodes for anisotropic tables), interpolated
linearly in between. Proposals and acceptance tests run in float32 in one traced loop
(:func:`gonio.brdf.sampling.distributions.rejection_sample_traced`), eagerly or under ``jit``.
"""

from __future__ import annotations

import dataclasses
import math
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf.lookup import atan2
from gonio.brdf.sampling import warps
from gonio.brdf.sampling.distributions import (
    alias_arrays,
    alias_sample_2d,
    rejection_sample_traced,
    seeds_from_rng,
    seeds_from_u,
)
from gonio.brdf.sampling.table_buckets import (
    HALF_PI,
    TWO_PI,
    BucketGeometry,
    LazyBuckets,
    bucket_of,
    bucket_ranges,
    direction_in_cell,
    incident_grid,
)
from gonio.errors import ParameterError

Array = jnp.ndarray
PROPOSALS = ("majorant", "cosine")
_ONE_MINUS_EPS32 = float(np.nextafter(np.float32(1.0), np.float32(0.0)))
_RHO_NODES = {True: (9, 1), False: (5, 5)}  # (theta_o, phi_o) nodes of rho per bucket, by iso
_RHO_RES = (128, 256)
_COSINE_BOUND_RES = (16, 32)  # incident cells over which the cosine proposal bounds g
# Bound where g = 0 in the whole bucket: negative, so the acceptance test passes at once and the
# sample fails (pdf 0, as rho = 0) after one proposal instead of max_rounds of them.
_EMPTY = -1.0


class TableRejection:
    """Lazily built rejection structures of a :class:`gonio.brdf.tabulated.TabulatedBRDF`, per
    proposal and outgoing bucket of the sampler's geometry ``geo``."""

    def __init__(self, table: Any, geo: BucketGeometry) -> None:
        self.table = table
        self.geo = geo
        self.n_buckets = geo.n_to * geo.n_po
        self.geo_major = dataclasses.replace(geo, n_t=2 * geo.n_t, n_p=2 * geo.n_p)
        self.cos_desc_major, self.omega_major = incident_grid(geo.n_t * 2, geo.n_p * 2)
        with jax.ensure_compile_time_eval():  # the sampler may be created under a jit trace
            self._cos_desc32 = jnp.asarray(self.cos_desc_major, jnp.float32)
        self.stores = {p: LazyBuckets(partial(self._build, proposal=p)) for p in PROPOSALS}
        self.stats: dict[str, float] = {}
        self._node_max: np.ndarray | None = None

    # -- bounds ------------------------------------------------------------------------------
    def _cell_bounds(self, b: int, nt: int, npp: int) -> tuple[np.ndarray, np.ndarray]:
        """``(bound of g cos theta_i, bound of g)``, ``(nt, npp)`` each, over every cell of an
        ``nt x npp`` incident grid (uniform in theta_i, and in phi relative to phi_o for
        isotropic tables) and every outgoing direction of bucket ``b``."""
        t0, t1, p0, p1 = bucket_ranges(self.geo, b)
        te = np.linspace(0.0, HALF_PI, nt + 1)[:, None]
        pe = np.linspace(0.0, TWO_PI, npp + 1)[None, :]
        dphi = (pe[:, :-1], pe[:, 1:]) if self.geo.iso else (pe[:, :-1] - p1, pe[:, 1:] - p0)
        th, td = half_diff_ranges((te[:-1], te[1:]), dphi, (t0, t1))
        t = self.table
        if self._node_max is None:  # largest valid node value per (theta_h, theta_d) node
            names = [a.name for a in t.axes]
            v = np.where(t.mask, t.values.mean(axis=-1, dtype=np.float64), -np.inf)
            v = np.moveaxis(v, (names.index("theta_h"), names.index("theta_d")), (0, 1))
            self._node_max = np.maximum(v.reshape(*v.shape[:2], -1).max(axis=-1), 0.0)
        ax_h, ax_d = (next(a for a in t.axes if a.name == n) for n in ("theta_h", "theta_d"))
        g = rect_max(self._node_max, *_node_span(ax_h, *th), *_node_span(ax_d, *td))
        g = g * (1 + 1e-5)
        return g * np.cos(te[:-1]), g

    def _majorant(self, b: int) -> dict[str, np.ndarray]:
        """Alias table of bucket ``b``'s majorant cells and each cell's acceptance bound.

        Weights ``m_c Omega_c``; the proposal density is ``q_c = p_c / Omega_c`` with ``p_c``
        the probability the alias table *realizes*, so ``bound_c = M q_c`` with ``M = max_c
        m_c / q_c`` bounds ``g cos`` in cell ``c`` and accepting with probability ``g cos /
        bound_c`` samples ``g cos`` exactly."""
        geo = self.geo_major
        m = self._cell_bounds(b, geo.n_t, geo.n_p)[0].reshape(-1)
        omega = np.repeat(self.omega_major, geo.n_p)
        if not (m * omega).sum() > 0:  # g = 0 for the whole bucket
            return {**alias_arrays(omega), "bound": np.full(m.shape, _EMPTY)}
        arrays = alias_arrays(m * omega)
        q = arrays["p"] / omega
        M = float(np.max(m[q > 0] / q[q > 0]))
        # a cell the alias table never draws has m = 0 up to rounding: its bound stays m
        bound = np.where(q > 0, M * q, m) * (1 + 1e-6)
        return {**arrays, "bound": bound}

    def _rho_nodes(self, b: int) -> np.ndarray:
        """``rho = int g cos dwi`` at the bucket's ``(theta_o, phi_o)`` nodes (midpoint rule
        over the half vector, ``dwi = 4 (wo . h) dwh``)."""
        t0, t1, p0, p1 = bucket_ranges(self.geo, b)
        kt, kp = _RHO_NODES[self.geo.iso]
        nx, nph = _RHO_RES
        x = (np.arange(nx) + 0.5) / nx
        ph = (np.arange(nph) + 0.5) * (TWO_PI / nph)
        th = x * x * HALF_PI
        jac = np.sin(th) * (math.pi * x) * (1.0 / nx) * (TWO_PI / nph)  # dw_h per node
        st, ct = np.sin(th)[:, None], np.cos(th)[:, None]
        h = np.stack(np.broadcast_arrays(st * np.cos(ph), st * np.sin(ph), ct), -1).reshape(-1, 3)
        jac = np.repeat(jac, nph)
        rho = []
        for t in np.linspace(t0, t1, kt):
            for p in np.linspace(p0, p1, kp):
                wo = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
                wh = h @ wo
                wi = 2 * wh[:, None] * h - wo
                g = np.asarray(_g_of(self.table, wi, np.broadcast_to(wo, wi.shape)))
                ok = (wh > 0) & (wi[:, 2] > 0)
                rho.append(np.sum(np.where(ok, g * wi[:, 2] * 4 * wh * jac, 0.0)))
        return np.reshape(rho, (kt, kp))

    def _build(self, buckets: list[int], proposal: str) -> dict[int, dict[str, np.ndarray]]:
        out = {}
        for b in buckets:
            if proposal == "majorant":
                out[b] = self._majorant(b)
            else:  # cosine: g cos / (cos / pi) = pi g
                M = math.pi * float(self._cell_bounds(b, *_COSINE_BOUND_RES)[1].max())
                out[b] = {"bound": np.asarray(M if M > 0 else _EMPTY)}
            out[b]["rho"] = self._rho_nodes(b)
        return out

    # -- entry points ------------------------------------------------------------------------
    def state(self, wo: Any, proposal: Any, dt: Any) -> dict[str, Any]:
        """Device arrays of ``proposal``'s structures with the buckets of ``wo`` built (and of
        ``wo`` rounded to float32, where the proposals run): ``run`` in float32 for the
        proposal loop, ``pdf`` in ``dt``. Unlike inversion and alias, rejection needs every
        direction's own bucket (another bucket's bound need not bound it)."""
        store = self.stores[_checked(proposal)]
        # proposals run in float32, where a direction on a bucket edge may round into the
        # neighbouring bucket: that one is built too
        slot_of, run = store.prepare(self.geo, wo, jnp.float32, also_float32=True)
        _, pdf = store.stacked(self.n_buckets, dt)
        return {"slot_of": slot_of, "run": run, "pdf": pdf}

    def sample(self, wo: Array, u: Array, rng: Any, proposal: Any, dt: Any, state: Any):
        """``(wi, pdf)`` for ``wo (..., 3)``, ``u (..., 2)`` (``u`` below 1), in ``dt``;
        ``state`` from :meth:`state`."""
        shape = wo.shape[:-1]
        wo_f, u_f = wo.reshape(-1, 3), u.reshape(-1, 2)
        _checked(proposal)
        seeds = _seeds(u_f) if rng is None else seeds_from_rng(rng, (wo_f.shape[0],))
        wo32 = wo_f.astype(jnp.float32)
        u32 = jnp.clip(u_f.astype(jnp.float32), 0.0, _ONE_MINUS_EPS32)
        geo = self.geo_major if proposal == "majorant" else self.geo
        wi, ok, rounds = _run(geo, proposal, self.table, state["slot_of"], state["run"],
                              self._cos_desc32, wo32, u32, seeds)  # fmt: skip
        if not isinstance(rounds, jax.core.Tracer):
            self.stats["rejection_proposals"] = float(np.sum(rounds, dtype=np.int64))
            self.stats["rejection_samples"] = float(wo_f.shape[0])
        wi = wi.astype(dt)
        pdf = jnp.where(ok, self.pdf(wi, wo_f, proposal, dt, state), 0.0)
        return wi.reshape(*shape, 3), pdf.reshape(shape)

    def pdf(self, wi: Array, wo: Array, proposal: Any, dt: Any, state: Any) -> Array:
        _checked(proposal)
        return _pdf_kernel(self.geo, self.table, state["slot_of"], state["pdf"]["rho"], wi, wo)


def _checked(proposal: Any) -> str:
    if isinstance(proposal, str) and proposal in PROPOSALS:
        return proposal
    name = repr(proposal) if isinstance(proposal, str) else type(proposal).__name__
    raise ParameterError(
        f"proposal must be 'majorant' or 'cosine', got {name} (exact rejection needs a rigorous "
        "bound of its acceptance ratio; to sample by an analytic model, use the model itself)"
    )


_seeds = jax.jit(seeds_from_u)


def _g_of(table: Any, wi: Array, wo: Array) -> Array:
    """``g = max(mean over channels of f, 0)`` at ``(wi, wo)``, the sampled target."""
    return jnp.maximum(jnp.mean(table.f(wi, wo), axis=-1), 0.0)


@partial(jax.jit, static_argnames=("geo", "proposal"))
def _run(geo, proposal, table, slot_of, arrays, cos_desc, wo, u, seeds):
    """The traced loop of ``proposal``'s rounds: ``(wi, accepted, rounds)``."""

    def majorant_round(wo, up, ua):
        s = jnp.take(slot_of, bucket_of(geo, wo))
        n = geo.n_t * geo.n_p
        alias = arrays["alias"]
        alias_flat = (alias + (jnp.arange(alias.shape[0], dtype=jnp.int32) * n)[:, None]).ravel()
        q = arrays["q"].reshape(-1)
        k, ry, rx, _ = alias_sample_2d(q, alias_flat, q, s * n, n, up[..., 0], up[..., 1])
        wi = direction_in_cell(geo, k // geo.n_p, k % geo.n_p, ry, rx, cos_desc, wo)
        bound = jnp.take(arrays["bound"].reshape(-1), s * n + k)
        return wi, (ua * bound < _g_of(table, wi, wo) * wi[..., 2]) & (wi[..., 2] > 0)

    def cosine_round(wo, up, ua):
        M = jnp.take(arrays["bound"], jnp.take(slot_of, bucket_of(geo, wo)))
        wi = warps.square_to_cosine_hemisphere(up).astype(wo.dtype)
        return wi, (ua * M < _g_of(table, wi, wo) * jnp.pi) & (wi[..., 2] > 0)

    one = majorant_round if proposal == "majorant" else cosine_round
    return rejection_sample_traced(one, (wo,), u, seeds)


@partial(jax.jit, static_argnames=("geo",))
def _pdf_kernel(geo, table, slot_of, rho, wi, wo):
    """``g cos theta_i / rho(wo)``, ``rho`` bilinear in (theta_o, phi_o) between the bucket's
    nodes (linear in theta_o for isotropic tables)."""
    b = bucket_of(geo, wo)
    x, y, z = wo[..., 0], wo[..., 1], wo[..., 2]
    ft = atan2(jnp.sqrt(x * x + y * y), z) * (geo.n_to / HALF_PI) - (b // geo.n_po)
    fp = jnp.zeros_like(ft)
    if not geo.iso:
        phi = atan2(y, x)
        fp = jnp.where(phi < 0, phi + TWO_PI, phi) * (geo.n_po / TWO_PI) - (b % geo.n_po)
    kt, kp = rho.shape[1:]

    def node(frac, k):  # lower node and weight of the upper one
        pos = jnp.clip(frac, 0.0, 1.0) * (k - 1)
        i = jnp.clip(jnp.floor(pos).astype(jnp.int32), 0, max(k - 2, 0))
        return i, pos - i

    (i, a), (j, c) = node(ft, kt), node(fp, kp)
    base = jnp.take(slot_of, b) * (kt * kp) + i * kp + j
    dj = 1 if kp > 1 else 0
    v = partial(jnp.take, rho.reshape(-1))
    rho_o = (1 - a) * ((1 - c) * v(base) + c * v(base + dj))
    rho_o = rho_o + a * ((1 - c) * v(base + kp) + c * v(base + kp + dj))
    ok = rho_o > 0
    g = _g_of(table, wi, wo) * jnp.maximum(wi[..., 2], 0.0)
    return jnp.where(ok, g / jnp.where(ok, rho_o, 1.0), 0.0)


# -- interval bounds (host, float64) ---------------------------------------------------------
def half_diff_ranges(
    theta_i: tuple[np.ndarray, np.ndarray],
    dphi: tuple[np.ndarray, np.ndarray],
    theta_o: tuple[float, float],
) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Ranges ``(lo, hi)`` of theta_h and theta_d (radians) over boxes of direction pairs.

    Each box holds ``wi`` with theta_i in ``theta_i`` and an azimuth ``dphi`` away from
    ``wo``'s, and ``wo`` with theta_o in ``theta_o`` (both above the horizon); arrays broadcast.
    The forms stay tight where ``wi`` and ``wo`` are nearly opposite (grazing, near the mirror
    direction), where ``cos theta_h = (cos theta_i + cos theta_o) / |wi + wo|`` evaluated term
    by term loses everything to cancellation:

    * ``wi . wo = cos(theta_i - theta_o) - sin theta_i sin theta_o (1 - cos dphi)`` and
      ``cos theta_d = sqrt((1 + wi . wo) / 2)``;
    * ``tan^2 theta_h = ((sin theta_i - sin theta_o)^2 + 2 sin theta_i sin theta_o
      (1 + cos dphi)) / (cos theta_i + cos theta_o)^2``.
    """
    ti0, ti1 = theta_i
    t0, t1 = theta_o
    cp_lo, cp_hi = cos_range(*dphi)
    cdel_lo, cdel_hi = cos_range(ti0 - t1, ti1 - t0)
    ss_lo, ss_hi = np.sin(ti0) * math.sin(t0), np.sin(ti1) * math.sin(t1)
    p_lo = np.clip(cdel_lo - ss_hi * (1 - cp_lo), -1.0, 1.0)
    p_hi = np.clip(cdel_hi - ss_lo * (1 - cp_hi), -1.0, 1.0)
    td = (np.arccos(np.sqrt((1 + p_hi) / 2)), np.arccos(np.sqrt((1 + p_lo) / 2)))
    # sin theta_i - sin theta_o over the box (each variable once: exact), squared
    dlo, dhi = np.sin(ti0) - math.sin(t1), np.sin(ti1) - math.sin(t0)
    sq_lo = np.where((dlo <= 0) & (dhi >= 0), 0.0, np.minimum(dlo * dlo, dhi * dhi))
    sq_hi = np.maximum(dlo * dlo, dhi * dhi)
    num_lo = np.maximum(sq_lo + 2 * ss_lo * (1 + cp_lo), 0.0)
    num_hi = np.maximum(sq_hi + 2 * ss_hi * (1 + cp_hi), 0.0)
    den_lo = np.maximum(np.cos(ti1) + math.cos(t1), 0.0)  # cos theta_i + cos theta_o >= 0
    den_hi = np.cos(ti0) + math.cos(t0)
    th = (np.arctan2(np.sqrt(num_lo), den_hi), np.arctan2(np.sqrt(num_hi), den_lo))
    return th, td


def cos_range(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range of cos over each interval ``[lo, hi]`` (``hi - lo <= 2 pi``)."""
    c_lo = np.minimum(np.cos(lo), np.cos(hi))
    c_hi = np.maximum(np.cos(lo), np.cos(hi))
    has_max = np.ceil(lo / TWO_PI) * TWO_PI <= hi  # a multiple of 2 pi inside: max 1
    has_min = np.ceil((lo - math.pi) / TWO_PI) * TWO_PI + math.pi <= hi
    return np.where(has_min, -1.0, c_lo), np.where(has_max, 1.0, c_hi)


def rect_max(a: np.ndarray, r0: Any, r1: Any, c0: Any, c1: Any) -> np.ndarray:
    """Maximum of ``a[r0:r1, c0:c1]`` per rectangle (integer arrays, non-empty ranges).

    Row-wise running maxima ``m[i, j0, j1] = max a[i, j0:j1]``, then one pass over the rows."""
    a = np.asarray(a, np.float64)
    nr, nc = a.shape
    m = np.full((nr, nc, nc + 1), -np.inf)
    for j in range(nc):
        m[:, j, j + 1 :] = np.maximum.accumulate(a[:, j:], axis=1)
    r0, r1, c0, c1 = np.broadcast_arrays(*(np.asarray(x, np.int64) for x in (r0, r1, c0, c1)))
    out = np.full(r0.shape, -np.inf)
    for i in range(int(r0.min(initial=nr)), int(r1.max(initial=0))):
        out = np.maximum(out, np.where((r0 <= i) & (i < r1), m[i, c0, c1], -np.inf))
    return out


def _node_span(ax: Any, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Node indices ``[i0, i1)`` that a lookup of angles in ``[lo, hi]`` on axis ``ax`` can use
    (with a margin of 0.01 of a cell for float32 rounding of the lookup's angles)."""
    tl = np.asarray(ax.continuous_index(jnp.asarray(lo, jnp.float64)))
    th = np.asarray(ax.continuous_index(jnp.asarray(hi, jnp.float64)))
    tl = np.clip(tl - 0.01, 0, ax.size - 1)
    th = np.clip(th + 0.01, 0, ax.size - 1)
    return np.floor(tl).astype(int), np.minimum(np.floor(th).astype(int) + 2, ax.size)


__all__ = ["PROPOSALS", "TableRejection", "cos_range", "half_diff_ranges", "rect_max"]
