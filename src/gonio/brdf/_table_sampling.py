"""Importance sampling of ``f cos`` for tabulated BRDFs (used by :class:`TabulatedBRDF`).

The sampled density is proportional to ``g(wi, wo) cos(theta_i)`` where ``g = max(mean over
channels of f, 0)``.

Outgoing directions are grouped in *buckets*: ``n_theta_o`` bins of theta_o (isotropic tables,
whose incident grid is then expressed relative to phi_o), or ``n_theta_o x 2 n_theta_o`` bins of
(theta_o, phi_o) (anisotropic tables). Every per-bucket structure is built the first time a
direction in that bucket is sampled or evaluated, and cached; nothing is built for buckets nobody
asks about. ``cache_size(method)`` says how many buckets are built.

Methods
-------
``"inversion"``
    Incident directions on an ``n_theta_i x n_phi_i`` grid (uniform in theta_i and phi); each
    cell's weight is the mean of ``g cos`` over 2 x 2 points per cell and 2 (isotropic) or 4
    (anisotropic) outgoing directions in the bucket, times the cell's solid angle, plus 0.1 % of
    a uniform density so that no cell where ``f > 0`` has zero probability. A cell is picked
    by marginal/conditional CDF inversion and the direction is uniform in (cos theta, phi)
    inside it, so the pdf is piecewise constant per unit solid angle: ``P_cell / Omega_cell``.
``"alias"``
    The same density, with the cell drawn from an alias table (O(1) per sample; one uniform
    number picks the column, the other decides between the column and its alias, so that
    float32 keeps every cell's probability to 2^-24).
``"rejection"``
    Exact sampling of ``g cos / rho(wo)`` by rejection, with one of three proposals ``q``:

    ``"majorant"`` (default)
        Per bucket, a rigorous bound ``m_c`` of ``g cos`` over each cell of an incident grid
        twice as fine as the inversion's (``_MAJORANT_REFINE``) and every outgoing direction
        in the bucket; cells are drawn in proportion to ``m_c Omega_c`` from an alias table,
        the direction is uniform in the cell, and it is accepted with probability
        ``g cos / m_c`` (using the probability the alias table realizes). Acceptance is
        ``rho / sum m_c Omega_c``: 0.83 on average over the hemisphere for the benchmark's
        MERL-grid table, 0.96 near the normal and 0.59 in the last, grazing bucket.
    ``"cosine"``
        A cosine-weighted hemisphere, accepted with probability ``g cos / (M q)``, ``M`` a bound
        of ``pi g`` over the bucket. Simple, but a glossy lobe makes ``M`` large (acceptance
        0.003 on the benchmark table).
    a BRDF model
        The model's own sampling mixed with 10 % cosine sampling, ``M`` a bound of
        ``g cos / q`` over the bucket. The bucket's theta_o range is bounded in 4 parts, and
        the lower bound of the model's pdf per cell of a 48 x 96 grid comes from evaluating it
        at 3 x 3 points x 12 outgoing directions per part (the one heuristic part; the cosine
        part of the mixture keeps the bound finite).

    The table bounds are rigorous: interval bounds of theta_h and theta_d over each
    incident-grid cell and the bucket (in forms that stay tight near grazing mirror
    configurations, see ``_half_diff_ranges``), interval bounds of ``cos theta_o`` and
    ``cos theta_i`` over each table cell, which say which cells, phi_d included, the bucket can
    reach at all and how large ``g cos theta_i`` can be in them, and multilinear interpolation
    never exceeds the largest valid node it uses.
    ``rho(wo) = int g cos dwi`` is computed by a 128 x 256 midpoint quadrature over the half
    vector (sqrt-warped theta_h, where the tables put their nodes) at 9 theta_o nodes per bucket
    (5 x 5 (theta_o, phi_o) nodes for anisotropic tables) and interpolated linearly in between.
    Proposals and acceptance tests run in float32; in float32 the table value looked up for
    the accepted proposal is returned with it, so pdf and weight need no second lookup.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf import warp
from gonio.brdf._xla import materialize
from gonio.brdf.sampling import (
    _normalized_cdf,
    _sample_discrete_cdf,
    _vose,
    alias_sample_2d,
    rejection_sample,
    rejection_sample_traced,
    rejection_step,
    seeds_from_rng,
    seeds_from_u,
)
from gonio.brdf.tabulated import atan2 as _atan2
from gonio.errors import ParameterError

Array = jnp.ndarray
HALF_PI = math.pi / 2
TWO_PI = 2 * math.pi
_UNIFORM_FLOOR = 1e-3
_ONE_MINUS_EPS32 = float(np.nextafter(np.float32(1.0), np.float32(0.0)))
_PROPOSAL_EPS = 0.1
_RHO_NODES = 9
_RHO_NODES_ANISO = 5
_RHO_RES = (128, 256)
_BOUND_RES = (16, 32)  # incident cells for the cosine-proposal bound
_MAJORANT_REFINE = 2  # the majorant's incident grid is this much finer than sampling_res's
_BOUND_RES_MODEL = (48, 96)  # finer: a model proposal's pdf varies within a cell
_MODEL_BOUND_SPLIT = 4  # theta_o parts per bucket bounded separately for a model proposal
# Rejection bound of a bucket where g = 0 everywhere: negative, so that the acceptance test
# (u * bound < g cos) passes at once; the sample's pdf is then 0 (rho = 0) and it fails as it
# should, after one proposal instead of max_rounds rejected ones.
_EMPTY = -1.0


@dataclass(frozen=True)
class _Geo:
    """Static geometry of the sampler (hashable, a jit static argument)."""

    iso: bool
    n_to: int
    n_po: int
    n_t: int
    n_p: int


def _bucket_of(geo: _Geo, wo: Array) -> Array:
    x, y, z = wo[..., 0], wo[..., 1], wo[..., 2]
    # fast polynomial atan2 in float32 (XLA's is ~25x slower on CPU), exact in float64; sample
    # and pdf both bucket through here, so they always agree
    theta = _atan2(jnp.sqrt(x * x + y * y), z)
    bt = jnp.clip(jnp.floor(theta * (geo.n_to / HALF_PI)).astype(jnp.int32), 0, geo.n_to - 1)
    if geo.iso:
        return bt
    phi = _atan2(y, x)
    phi = jnp.where(phi < 0, phi + TWO_PI, phi)
    bp = jnp.clip(jnp.floor(phi * (geo.n_po / TWO_PI)).astype(jnp.int32), 0, geo.n_po - 1)
    return bt * geo.n_po + bp


def _azimuth_frame(wo: Array) -> tuple[Array, Array]:
    """``(cos phi_o, sin phi_o)`` of ``wo``; ``(1, 0)`` at the pole (where atan2 gives 0)."""
    x, y = wo[..., 0], wo[..., 1]
    r2 = x * x + y * y
    pole = r2 <= 0
    inv = jnp.where(pole, 0.0, jax.lax.rsqrt(jnp.where(pole, 1.0, r2)))
    return jnp.where(pole, 1.0, x * inv), y * inv


def _cell_of(geo: _Geo, wi: Array, wo: Array, cos_asc: Array) -> tuple[Array, Array]:
    """Incident-grid cell ``(row, col)`` of ``wi`` (rows by cos theta, as the sampler builds)."""
    k = jnp.searchsorted(cos_asc, wi[..., 2], side="left").astype(jnp.int32)
    row = jnp.clip(geo.n_t - k, 0, geo.n_t - 1)
    x, y = wi[..., 0], wi[..., 1]
    if geo.iso:  # azimuth relative to wo's: rotate wi by -phi_o
        c, s = _azimuth_frame(wo)
        x, y = c * x + s * y, c * y - s * x
    phi = _atan2(y, x)
    phi = jnp.where(phi < 0, phi + TWO_PI, phi)
    phi = jnp.where(phi >= TWO_PI, 0.0, phi)
    col = jnp.clip(jnp.floor(phi * (geo.n_p / TWO_PI)).astype(jnp.int32), 0, geo.n_p - 1)
    return row, col


def _direction_in_cell(
    geo: _Geo, row: Array, col: Array, ry: Array, rx: Array, cos_desc: Array, wo: Array
) -> Array:
    """A direction ``(..., 3)`` in cell ``(row, col)`` of the incident grid, at ``(ry, rx)``
    in [0, 1)^2 of the cell uniformly in solid angle."""
    # stacked along a new leading axis and transposed: XLA's CPU backend then evaluates each
    # component in its own vectorized loop instead of one scalar loop over (..., 3)
    x, y, z = _direction_components(geo, row, col, ry, rx, cos_desc, wo)
    return jnp.moveaxis(jnp.stack([x, y, z], 0), 0, -1)


def _direction_components(
    geo: _Geo, row: Array, col: Array, ry: Array, rx: Array, cos_desc: Array, wo: Array
) -> tuple[Array, Array, Array]:
    """:func:`_direction_in_cell` as its three components."""
    c0 = jnp.take(cos_desc, row)
    c1 = jnp.take(cos_desc, row + 1)
    ct = c0 - ry * (c0 - c1)
    cp, sp = _cos_sin_in_column(geo.n_p, col, rx, ct.dtype)
    # stored once: otherwise XLA fuses the gathers above into the loop below, which then runs
    # as scalar code, once per output component
    ct, cp, sp = materialize([ct, cp, sp], ct)
    st = jnp.sqrt(jnp.maximum(1.0 - ct * ct, 0.0))
    if geo.iso:  # phi is relative to wo's azimuth: rotate by +phi_o
        c, s = _azimuth_frame(wo)
        cp, sp = c * cp - s * sp, s * cp + c * sp
    return st * cp, st * sp, ct


def _cos_sin_in_column(n_p: int, col: Array, rx: Array, dtype: Any) -> tuple[Array, Array]:
    """``cos phi, sin phi`` of ``phi = (col + rx) 2 pi / n_p`` (``rx`` in [0, 1)).

    The column's start angle comes from a table and the offset ``delta = rx 2 pi / n_p`` goes
    through short Taylor series (error below 1e-8 for ``delta <= pi / 4``): XLA's CPU
    backend evaluates ``cos``/``sin`` about 10x slower than other elementwise functions, a
    tenth of a table-rejection round."""
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


def _incident_grid(n_t: int, n_p: int) -> tuple[np.ndarray, np.ndarray]:
    """``(cos_desc (n_t + 1,), omega (n_t,))``: the row edges of an incident grid uniform in
    theta_i, as cosines from 1 down to exactly 0, and each row's cell solid angle (sr)."""
    cos_desc = np.cos(np.linspace(0.0, HALF_PI, n_t + 1))
    cos_desc[0], cos_desc[-1] = 1.0, 0.0
    return cos_desc, (cos_desc[:-1] - cos_desc[1:]) * (TWO_PI / n_p)


class _Lazy:
    """Per-bucket structures built on demand and stacked for the vectorized kernels."""

    def __init__(self, build) -> None:
        self._build = build
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
                    k: v.astype(dtype) if jnp.issubdtype(v.dtype, jnp.floating) else v
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
                arrays = {
                    name: jnp.asarray(np.stack([self.items[k][name] for k in keys_padded]))
                    for name in names
                }
                self._stack = (jnp.asarray(slot_of), arrays)
        return self._stack


class TableSampler:
    """Lazily built sampling structures of one table (see the module docstring)."""

    def __init__(self, table: Any) -> None:
        self.table = table
        n_to, n_t, n_p = table.sampling_res
        self.geo = _Geo(table.isotropic, n_to, 1 if table.isotropic else 2 * n_to, n_t, n_p)
        self.n_buckets = self.geo.n_to * self.geo.n_po
        cos_desc, self.omega = _incident_grid(n_t, n_p)
        self.cos_desc = cos_desc
        # the majorant's cells are finer: its acceptance is limited by how much g cos varies
        # within a cell (0.77 -> 0.84 on the benchmark table for twice the resolution)
        self.geo_major = dataclasses.replace(
            self.geo, n_t=_MAJORANT_REFINE * n_t, n_p=_MAJORANT_REFINE * n_p
        )
        self.cos_desc_major, self.omega_major = _incident_grid(
            self.geo_major.n_t, self.geo_major.n_p
        )
        with jax.ensure_compile_time_eval():  # the sampler may be created under a jit trace
            self._major_cos_desc = jnp.asarray(self.cos_desc_major, jnp.float32)
            self._consts = {
                dt: (
                    jnp.asarray(cos_desc, dt),
                    jnp.asarray(cos_desc[::-1].copy(), dt),
                    jnp.asarray(self.omega, dt),
                )
                for dt in (jnp.float32, jnp.float64)
            }
        self._grid = _Lazy(self._build_grid)
        self._alias = _Lazy(self._build_alias)
        self._rejection: dict[Any, _Lazy] = {}
        self._node_max: _RangeMax2D | None = None
        self._sup_cache: dict[str, np.ndarray] | None = None
        self._round_fns: dict[Any, Any] = {}
        self.stats: dict[str, float] = {}

    # -- cache ---------------------------------------------------------------------------------
    def cache_size(self, method: str | None = None) -> int:
        if method == "inversion":
            return len(self._grid.items)
        if method == "alias":
            return len(self._alias.items)
        if method == "rejection":
            return sum(len(v.items) for v in self._rejection.values())
        return (
            len(self._grid.items)
            + len(self._alias.items)
            + sum(len(v.items) for v in self._rejection.values())
        )

    def built_buckets(self, method: str) -> list[int]:
        if method == "inversion":
            return sorted(self._grid.items)
        if method == "alias":
            return sorted(self._alias.items)
        return sorted({b for v in self._rejection.values() for b in v.items})

    def _store(self, method: str, proposal: Any) -> _Lazy:
        if method == "inversion":
            return self._grid
        if method == "alias":
            return self._alias
        if method != "rejection":
            raise ParameterError(
                f"unknown sampling method {method!r} (expected inversion, alias or rejection)"
            )
        key = _proposal_key(proposal)
        if key not in self._rejection:
            self._rejection[key] = _Lazy(partial(self._build_rejection, proposal=proposal))
        return self._rejection[key]

    def _prepare(
        self, method: str, proposal: Any, wo: Array, dtype: Any = None
    ) -> tuple[Array, dict[str, Array]]:
        store = self._store(method, proposal)
        if isinstance(wo, jax.core.Tracer):
            # inside jit the outgoing directions are unknown: build every bucket
            store.ensure(np.arange(self.n_buckets))
        else:
            met = np.asarray(_buckets_met(self.geo, wo))
            if method == "rejection" and wo.dtype != jnp.float32:
                # proposals run in float32, where a direction on a bucket edge may round into
                # the neighbouring bucket: build that one too
                met = met | np.asarray(_buckets_met(self.geo, wo.astype(jnp.float32)))
            store.ensure(np.flatnonzero(met))
        return store.stacked(self.n_buckets, dtype)

    # -- scalar target g cos -------------------------------------------------------------------
    def _g(self, wi: Any, wo: Any) -> np.ndarray:
        v = np.asarray(self.table.f(wi, wo))
        return np.maximum(v.mean(axis=-1), 0.0)

    def _bucket_ranges(self, b: int) -> tuple[float, float, float, float]:
        bt, bp = divmod(b, self.geo.n_po)
        t0, t1 = bt * HALF_PI / self.geo.n_to, (bt + 1) * HALF_PI / self.geo.n_to
        if self.geo.iso:
            return t0, t1, 0.0, 0.0
        return t0, t1, bp * TWO_PI / self.geo.n_po, (bp + 1) * TWO_PI / self.geo.n_po

    def _bucket_wos(self, b: int) -> np.ndarray:
        t0, t1, p0, p1 = self._bucket_ranges(b)
        ts = [t0 + 0.25 * (t1 - t0), t0 + 0.75 * (t1 - t0)]
        ps = [0.0] if self.geo.iso else [p0 + 0.25 * (p1 - p0), p0 + 0.75 * (p1 - p0)]
        return np.array(
            [
                [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)]
                for t in ts
                for p in ps
            ]
        )

    # -- inversion / alias ---------------------------------------------------------------------
    def _cell_weights(self, b: int) -> np.ndarray:
        g = self.geo
        sub = np.array([0.25, 0.75])
        cd = self.cos_desc
        ct = cd[:-1, None] - sub[None, :] * (cd[:-1] - cd[1:])[:, None]  # (n_t, 2)
        ph = (np.arange(g.n_p)[:, None] + sub[None, :]) * (TWO_PI / g.n_p)  # (n_p, 2)
        st = np.sqrt(1 - ct**2)
        wi = np.stack(
            np.broadcast_arrays(
                st[:, :, None, None] * np.cos(ph)[None, None],
                st[:, :, None, None] * np.sin(ph)[None, None],
                ct[:, :, None, None],
            ),
            -1,
        )  # (n_t, 2, n_p, 2, 3)
        acc = np.zeros((g.n_t, g.n_p))
        wos = self._bucket_wos(b)
        for wo in wos:
            wi_w = wi
            if g.iso:
                po = math.atan2(wo[1], wo[0])
                c, s = math.cos(po), math.sin(po)
                wi_w = np.stack(
                    [c * wi[..., 0] - s * wi[..., 1], s * wi[..., 0] + c * wi[..., 1], wi[..., 2]],
                    -1,
                )
            val = self._g(wi_w.astype(np.float32), np.broadcast_to(wo, wi.shape).astype(np.float32))
            acc += (val * ct[:, :, None, None]).mean(axis=(1, 3))
        dens = acc / len(wos)
        F = dens * self.omega[:, None]
        total = F.sum()
        floor = _UNIFORM_FLOOR * (total / TWO_PI if total > 0 else 1.0)
        return F + floor * self.omega[:, None]

    def _build_grid(self, buckets: list[int]) -> dict[int, dict[str, np.ndarray]]:
        out = {}
        for b in buckets:
            w = self._cell_weights(b)
            out[b] = {"mcdf": _normalized_cdf(w.sum(axis=1)), "ccdf": _normalized_cdf(w)}
        return out

    def _build_alias(self, buckets: list[int]) -> dict[int, dict[str, np.ndarray]]:
        return {b: _alias_arrays(self._cell_weights(b).reshape(-1)) for b in buckets}

    # -- rejection -----------------------------------------------------------------------------
    def _h_max(self) -> np.ndarray:
        """Largest valid node value (channel mean, at least 0) per (theta_h, theta_d) node."""
        v = self._node_means()
        names = [a.name for a in self.table.axes]
        ih, idd = names.index("theta_h"), names.index("theta_d")
        other = tuple(k for k in range(v.ndim) if k not in (ih, idd))
        return np.maximum(v.max(axis=other), 0.0)

    def _node_means(self) -> np.ndarray:
        """Channel mean of every node (float64), -inf where the node is invalid."""
        t = self.table
        return np.where(t.mask, t.values.mean(axis=-1, dtype=np.float64), -np.inf)

    def _reachable(self, t0: float, t1: float) -> tuple[float, _RangeMax2D, _RangeMax2D]:
        """``(sup, g_cells, gcos_cells)`` for outgoing directions with theta_o in ``[t0, t1]``:
        a bound of ``g`` over them and every ``wi`` above the horizon, and per (theta_h,
        theta_d) table cell (sorted by angle, see ``_sup_static``) bounds of ``g`` and of
        ``g cos theta_i`` over the cells reachable from them, ready for rectangle maxima.

        ``cos theta_o = A + B cos phi_d`` and ``cos theta_i = A - B cos phi_d`` with
        ``A = cos theta_h cos theta_d``, ``B = sin theta_h sin theta_d`` (the Rusinkiewicz
        angles of :func:`gonio.brdf.frames.half_diff`). Interval arithmetic over each
        interpolation cell of the table says whether the cell can be reached with theta_o in
        the range and ``cos theta_i > 0``, and how large ``cos theta_i`` can be there;
        multilinear interpolation with renormalized weights never exceeds the largest valid
        corner of its cell, so the largest corner over the reachable cells bounds ``g``
        (rigorously, up to the small margins below). Bounding ``g cos theta_i`` per table cell
        matters near grazing: there ``g`` peaks where ``cos theta_i`` is smallest.

        Not cached: each outgoing range is bounded once per build, and the two rectangle-max
        structures take a few MB each.
        """
        st = self._sup_static()
        eps = 1e-4  # covers float32 rounding of the lookup's angles and of the bucketing
        reach = (st["wo_hi"] >= math.cos(t1) - eps) & (st["wo_lo"] <= math.cos(t0) + eps)
        reach &= st["wi_hi"] > -eps
        m = np.where(reach, st["cmax"], 0.0)
        sup = float(m.max()) * (1 + 1e-5)
        order = np.ix_(st["oh"], st["od"])
        cells = _RangeMax2D(m.max(axis=2)[order])
        m *= np.clip(st["wi_hi"] + eps, 0.0, 1.0)
        cos_cells = _RangeMax2D(m.max(axis=2)[order])
        return sup, cells, cos_cells

    def _sup_static(self) -> dict[str, np.ndarray]:
        """Table-only parts of :meth:`_reachable`, computed once."""
        if self._sup_cache is not None:
            return self._sup_cache
        t = self.table
        names = [a.name for a in t.axes]
        ih, idd, ip = names.index("theta_h"), names.index("theta_d"), names.index("phi_d")
        v = self._node_means()
        if v.ndim == 4:  # anisotropic: theta_o does not depend on phi_h
            v = v.max(axis=names.index("phi_h"))
            ih, idd, ip = (0, 1, 2)
        v = np.moveaxis(v, (ih, idd, ip), (0, 1, 2))
        h_lo, h_hi, h_a, h_b = _axis_cells(t.axes[names.index("theta_h")])
        d_lo, d_hi, d_a, d_b = _axis_cells(t.axes[names.index("theta_d")])
        p_lo, p_hi, p_a, p_b = _axis_cells(t.axes[names.index("phi_d")])
        # largest corner of every cell, as a bound of g = max(mean, 0)
        cmax = np.zeros((len(h_a), len(d_a), len(p_a)))
        for hs in (h_a, h_b):
            for ds in (d_a, d_b):
                for ps in (p_a, p_b):
                    cmax = np.maximum(cmax, v[np.ix_(hs, ds, ps)])
        ca = (np.cos(h_hi)[:, None] * np.cos(d_hi)[None, :], np.cos(h_lo)[:, None] * np.cos(d_lo))
        sb = (np.sin(h_lo)[:, None] * np.sin(d_lo)[None, :], np.sin(h_hi)[:, None] * np.sin(d_hi))
        c_lo, c_hi = _cos_range(p_lo, p_hi)
        if t._spec.fold >= 1:  # the folded cell also serves phi_d + pi (and pi - phi_d): cos < 0
            c_lo, c_hi = np.minimum(c_lo, -c_hi), np.maximum(c_hi, -c_lo)
        A_lo, A_hi = ca[0][:, :, None], ca[1][:, :, None]
        B_lo, B_hi = sb[0][:, :, None], sb[1][:, :, None]
        bc_lo = np.where(c_lo >= 0, B_lo * c_lo, B_hi * c_lo)  # B >= 0
        bc_hi = np.where(c_hi >= 0, B_hi * c_hi, B_lo * c_hi)
        # cells sorted by angle, so that the cells meeting an angle range are contiguous
        oh, od = np.argsort(h_lo), np.argsort(d_lo)
        self._sup_cache = {
            "cmax": cmax,
            "wo_lo": A_lo + bc_lo,
            "wo_hi": A_hi + bc_hi,
            "wi_hi": A_hi - bc_lo,
            "oh": oh,
            "od": od,
            "h_cells": (h_lo[oh], h_hi[oh]),
            "d_cells": (d_lo[od], d_hi[od]),
        }
        return self._sup_cache

    def _table_bound(
        self,
        th: tuple[np.ndarray, np.ndarray],
        td: tuple[np.ndarray, np.ndarray],
        reach: tuple[float, _RangeMax2D, _RangeMax2D],
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``g`` and of ``g cos theta_i`` over boxes of (theta_h, theta_d) angle
        ranges (arrays of lo, hi), for the outgoing range whose :meth:`_reachable` is
        ``reach`` (the bound of ``g`` is at most that range's ``sup``)."""
        t = self.table
        ax_h = next(a for a in t.axes if a.name == "theta_h")
        ax_d = next(a for a in t.axes if a.name == "theta_d")
        if self._node_max is None:
            self._node_max = _RangeMax2D(self._h_max())

        def node_range(ax, lo, hi):
            tl = np.asarray(ax.continuous_index(jnp.asarray(lo, jnp.float64)))
            thi = np.asarray(ax.continuous_index(jnp.asarray(hi, jnp.float64)))
            tl = np.clip(tl - 0.01, 0, ax.size - 1)
            thi = np.clip(thi + 0.01, 0, ax.size - 1)
            return np.floor(tl).astype(int), np.minimum(np.floor(thi).astype(int) + 2, ax.size)

        node_bound = self._node_max.query(*node_range(ax_h, *th), *node_range(ax_d, *td))
        # phi_d-aware: the table cells meeting the boxes that the outgoing range can reach
        sup, cells, cos_cells = reach
        st = self._sup_static()
        (hl, hh), (dl, dh) = st["h_cells"], st["d_cells"]
        margin = 1e-6  # radians, beyond the float64 rounding of the boxes
        ch0 = np.searchsorted(hh, th[0] - margin, side="left")  # first cell ending at/after lo
        ch1 = np.searchsorted(hl, th[1] + margin, side="right")  # past the last starting <= hi
        cd0 = np.searchsorted(dh, td[0] - margin, side="left")
        cd1 = np.searchsorted(dl, td[1] + margin, side="right")
        ch1, cd1 = np.maximum(ch1, ch0 + 1), np.maximum(cd1, cd0 + 1)
        found = (ch0 < len(hh)) & (cd0 < len(dh))  # else no cell: keep the node bound
        ch0, cd0 = np.minimum(ch0, len(hh) - 1), np.minimum(cd0, len(dh) - 1)
        ch1, cd1 = np.minimum(ch1, len(hh)), np.minimum(cd1, len(dh))
        g = np.where(found, np.minimum(node_bound, cells.query(ch0, ch1, cd0, cd1)), node_bound)
        gcos = np.where(found, cos_cells.query(ch0, ch1, cd0, cd1), np.inf)
        return np.minimum(g * (1 + 1e-5), sup), gcos * (1 + 1e-5)

    def _cell_bounds(
        self, b: int, res: tuple[int, int], theta_o: tuple[float, float] | None = None
    ) -> tuple[np.ndarray, ...]:
        """Per coarse incident cell: (bound of g, bound of g cos theta_i, min cos theta_i), for
        the outgoing directions of bucket ``b`` (with theta_o restricted to ``theta_o`` if
        given)."""
        nt, npp = res
        t0, t1, p0, p1 = self._bucket_ranges(b)
        if theta_o is not None:
            t0, t1 = theta_o
        te = np.linspace(0, HALF_PI, nt + 1)
        pe = np.linspace(0, TWO_PI, npp + 1)
        ti0, ti1 = (
            np.broadcast_to(te[:-1, None], (nt, npp)),
            np.broadcast_to(te[1:, None], (nt, npp)),
        )
        pi0, pi1 = (
            np.broadcast_to(pe[None, :-1], (nt, npp)),
            np.broadcast_to(pe[None, 1:], (nt, npp)),
        )
        if self.geo.iso:
            d0, d1 = pi0, pi1
        else:
            d0, d1 = pi0 - p1, pi1 - p0
        ci = (np.cos(ti1), np.cos(ti0))
        th, td = _half_diff_ranges((ti0, ti1), (d0, d1), (t0, t1))
        U, gcos = self._table_bound(th, td, self._reachable(t0, t1))
        return U, np.minimum(U * ci[1], gcos), ci[0]

    def _rho_nodes(self, b: int) -> np.ndarray:
        t0, t1, p0, p1 = self._bucket_ranges(b)
        if self.geo.iso:
            wos = [(t, 0.0) for t in np.linspace(t0, t1, _RHO_NODES)]
        else:
            k = _RHO_NODES_ANISO
            wos = [(t, p) for t in np.linspace(t0, t1, k) for p in np.linspace(p0, p1, k)]
        nx, nph = _RHO_RES
        x = (np.arange(nx) + 0.5) / nx
        ph = (np.arange(nph) + 0.5) * (TWO_PI / nph)
        th = x * x * HALF_PI
        jac = np.sin(th) * (math.pi * x) * (1.0 / nx) * (TWO_PI / nph)  # dw_h per node
        st, ct = np.sin(th)[:, None], np.cos(th)[:, None]
        h = np.stack(np.broadcast_arrays(st * np.cos(ph), st * np.sin(ph), ct), -1).reshape(-1, 3)
        jac = np.broadcast_to(jac[:, None], (nx, nph)).reshape(-1)
        out = []
        for t, p in wos:
            wo = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
            wh = h @ wo
            wi = 2 * wh[:, None] * h - wo
            ok = (wh > 0) & (wi[:, 2] > 0)
            g = self._g(wi, np.broadcast_to(wo, wi.shape))
            out.append(np.sum(np.where(ok, g * wi[:, 2] * 4 * wh * jac, 0.0)))
        rho = np.asarray(out)
        return rho if self.geo.iso else rho.reshape(_RHO_NODES_ANISO, _RHO_NODES_ANISO)

    def _build_rejection(
        self, buckets: list[int], proposal: Any
    ) -> dict[int, dict[str, np.ndarray]]:
        out = {}
        for b in buckets:
            if proposal == "majorant":
                out[b] = {**self._majorant(b), "rho": self._rho_nodes(b)}
                continue
            if proposal == "cosine":
                # g cos / (cos / pi) = pi g
                U, _, _ = self._cell_bounds(b, _BOUND_RES)  # U <= the bucket's sup of g
                M = math.pi * U.max()
            else:
                M = self._model_bound(b, proposal)
            out[b] = {"bound": np.asarray(M if M > 0 else _EMPTY), "rho": self._rho_nodes(b)}
        return out

    def _majorant(self, b: int) -> dict[str, np.ndarray]:
        """Piecewise-constant proposal of bucket ``b`` on the incident grid, and its bound.

        Cell ``c``'s weight is ``m_c Omega_c`` with ``m_c`` a rigorous bound of ``g cos``
        over the cell and every outgoing direction in the bucket (:meth:`_cell_bounds`: the
        smaller of the table bound times the largest ``cos theta_i`` of the cell and the
        largest per-table-cell bound of ``g cos theta_i`` over the table cells it reaches).
        Cells are drawn from an alias table and the direction is uniform in solid angle
        inside the cell, so the proposal density is ``q = p_c / Omega_c`` with ``p_c`` the
        probability the table *realizes*. ``bound_c = M q_c`` with ``M = max_c m_c / q_c``
        then bounds ``g cos`` in cell ``c`` (``bound_c >= m_c``), and accepting with
        probability ``g cos / bound_c`` samples ``g cos`` exactly. The acceptance rate is
        ``rho / sum_c m_c Omega_c``.
        """
        geo = self.geo_major
        _, gcos, _ = self._cell_bounds(b, (geo.n_t, geo.n_p))
        m = gcos.reshape(-1)
        omega = np.repeat(self.omega_major, geo.n_p)
        w = m * omega
        if not w.sum() > 0:  # g = 0 for the whole bucket
            return {**_alias_arrays(omega), "bound": np.full(m.shape, _EMPTY)}
        arrays = _alias_arrays(w)
        q = arrays["p"] / omega
        with np.errstate(divide="ignore", invalid="ignore"):
            M = float(np.max(np.where(q > 0, m / np.where(q > 0, q, 1.0), 0.0)))
        # a cell the alias table never draws has m = 0 up to rounding: its bound stays m
        bound = np.where(q > 0, M * q, m) * (1 + 1e-6)
        return {**arrays, "bound": bound}

    def _model_bound(self, b: int, model: Any) -> float:
        """Bound of ``g cos / q`` over bucket ``b`` for the mixture proposal ``q``.

        The bucket's theta_o range is split in ``_MODEL_BOUND_SPLIT`` parts, each bounded on
        its own (the table bound and the proposal's pdf move together with theta_o; one bound
        over the whole bucket pairs the largest table value at one end with the smallest pdf
        at the other, which near grazing angles overstates the ratio a hundredfold).
        """
        nt, npp = _BOUND_RES_MODEL
        t0, t1, p0, p1 = self._bucket_ranges(b)
        k = _MODEL_BOUND_SPLIT
        s = np.linspace(0, 1, 3)
        te = np.linspace(0, HALF_PI, nt + 1)
        pe = np.linspace(0, TWO_PI, npp + 1)
        tt = te[:-1, None] + s[None, :] * (te[1:] - te[:-1])[:, None]  # (nt, 3)
        pp = pe[:-1, None] + s[None, :] * (pe[1:] - pe[:-1])[:, None]  # (npp, 3)
        tt = np.clip(tt, 0, HALF_PI - 1e-4)
        thetas = np.linspace(t0, t1, 2 * k + 1)  # ends and middles of the k parts
        phis = (
            (0, 0.5 * math.pi, math.pi, 1.5 * math.pi) if self.geo.iso else np.linspace(p0, p1, 4)
        )
        st = np.sin(tt)[:, :, None, None]
        wis, wos = [], []
        for t in thetas:
            for p in phis:
                wo = np.array(
                    [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), max(math.cos(t), 1e-4)]
                )
                phi = pp[None, None] + (p if self.geo.iso else 0.0)
                wi = np.stack(
                    np.broadcast_arrays(
                        st * np.cos(phi), st * np.sin(phi), np.cos(tt)[:, :, None, None]
                    ),
                    -1,
                ).reshape(-1, 3)  # (nt, 3, npp, 3) points
                wis.append(wi)
                wos.append(np.broadcast_to(wo / np.linalg.norm(wo), wi.shape))
        q = np.asarray(model.pdf(np.concatenate(wis), np.concatenate(wos)), np.float64)
        q = q.reshape(len(thetas), len(phis), nt, 3, npp, 3).min(axis=(1, 3, 5))  # (thetas, cells)
        eps = _PROPOSAL_EPS
        out = 0.0
        for j in range(k):
            U, gcos, cmin = self._cell_bounds(
                b, _BOUND_RES_MODEL, (thetas[2 * j], thetas[2 * j + 2])
            )
            qmin = q[2 * j : 2 * j + 3].min(axis=0)
            lower = eps * cmin / math.pi + (1 - eps) * 0.5 * np.maximum(qmin, 0.0)
            with np.errstate(divide="ignore"):
                ratio = np.where(lower > 0, gcos / np.where(lower > 0, lower, 1.0), np.inf)
            ratio = np.minimum(ratio, math.pi * U / eps)
            out = max(out, float(ratio.max()))
        return out

    # -- public entry points -------------------------------------------------------------------
    def sample(self, wo: Array, u: Array, method: str, rng: Any, proposal: Any):
        """``(wi, pdf, f)``: ``f (..., C)`` is the table at ``(wi, wo)`` when the sampler has
        already looked it up (rejection in float32), else None."""
        dt = jnp.float64 if wo.dtype == jnp.float64 else jnp.float32
        if method == "rejection":  # proposals and acceptance tests run in float32
            return self._sample_rejection(wo, u, rng, proposal, dt)
        slot_of, arrays = self._prepare(method, proposal, wo, dt)
        cos_desc, _cos_asc, omega = self._consts[dt]
        if method == "inversion":
            wi, pdf = _inversion_kernel(
                self.geo,
                slot_of,
                arrays["mcdf"],
                arrays["ccdf"],
                cos_desc,
                omega,
                wo,
                u,
            )
            return wi, pdf, None
        if method == "alias":
            wi, pdf = _alias_kernel(
                self.geo,
                slot_of,
                arrays["q"],
                arrays["alias"],
                arrays["p"],
                cos_desc,
                omega,
                wo,
                u,
            )
            return wi, pdf, None

    def _sample_rejection(self, wo, u, rng, proposal, dt):
        shape = wo.shape[:-1]
        wo_f = wo.reshape(-1, 3)
        u_f = u.reshape(-1, 2)
        slot_of, arrays = self._prepare("rejection", proposal, wo_f, jnp.float32)
        # proposals and acceptance tests run in float32 whatever the caller's precision (the
        # returned pdf is evaluated afterwards at the returned direction, in the caller's dtype)
        if rng is not None:
            seeds = seeds_from_rng(rng, (wo_f.shape[0],))
        else:
            seeds = _seeds_jit(u_f)
        # the caller's u is already clipped below 1 (in its own dtype)
        wo32, u32 = (wo_f, u_f) if dt == jnp.float32 else _as_float32(wo_f, u_f)
        key = _proposal_key(proposal)
        if proposal == "majorant":
            round_fn = partial(_majorant_round, self.table, self.geo_major)
            consts = (slot_of, arrays["q"], arrays["alias"], arrays["bound"], self._major_cos_desc)
        else:
            model = None if proposal == "cosine" else proposal
            round_fn = partial(_rejection_round, self.table, model, self.geo)
            consts = (slot_of, arrays["bound"])
        if isinstance(wo, jax.core.Tracer) or isinstance(u, jax.core.Tracer):
            x, ok, _ = rejection_sample_traced(
                lambda w, a, b: round_fn(*consts, w, a, b), (wo32,), u32, seeds
            )
        else:
            step = self._round_fns.get(key)
            if step is None:
                step = rejection_step(lambda w, a, b, *c: round_fn(*c, w, a, b))
                self._round_fns[key] = step
            x, ok, rounds = rejection_sample(step, (wo32,), u32, seeds, consts=consts)
            self.stats["rejection_proposals"] = float(np.sum(rounds, dtype=np.int64))
            self.stats["rejection_samples"] = float(wo_f.shape[0])
        wi, f = x
        if dt == jnp.float32:  # the acceptance test looked f up at (wi, wo) in float32
            pdf = _rejection_pdf_from_f(self.geo, slot_of, arrays["rho"], f, wi, wo_f, ok)
            return wi.reshape(*shape, 3), pdf.reshape(shape), f.reshape(*shape, f.shape[-1])
        wi = wi.astype(dt)
        _, arrays = self._store("rejection", proposal).stacked(self.n_buckets, dt)
        pdf = jnp.where(ok, self.pdf_rejection(slot_of, arrays, wi, wo_f), 0.0)
        return wi.reshape(*shape, 3), pdf.reshape(shape), None

    def pdf_rejection(self, slot_of, arrays, wi, wo):
        t = self.table
        return _rejection_pdf_kernel(self.geo, t._spec, t._data, slot_of, arrays["rho"], wi, wo)

    def pdf(self, wi: Array, wo: Array, method: str, proposal: Any) -> Array:
        dt = jnp.float64 if wo.dtype == jnp.float64 else jnp.float32
        slot_of, arrays = self._prepare(method, proposal, wo, dt)
        _cos_desc, cos_asc, omega = self._consts[dt]
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        if method == "inversion":
            p = _inversion_pdf(
                self.geo, slot_of, arrays["mcdf"], arrays["ccdf"], cos_asc, omega, wi, wo
            )
        elif method == "alias":
            p = _alias_pdf(self.geo, slot_of, arrays["p"], cos_asc, omega, wi, wo)
        else:
            p = self.pdf_rejection(slot_of, arrays, wi, wo)
        return jnp.where(ok, p, 0.0)


class _RangeMax2D:
    """Maxima of a 2-D array over index rectangles, vectorized over many rectangles.

    A 2-D sparse table: ``levels[k, l, i, j]`` is the maximum of ``a[i : i + 2**k, j : j +
    2**l]``, so any rectangle is covered by four (overlapping) blocks, O(1) per query. Written
    here because neither NumPy nor SciPy answers batches of rectangle-maximum queries.
    """

    def __init__(self, a: np.ndarray) -> None:
        a = np.asarray(a, np.float64)
        nr, nc = a.shape
        kr, kc = nr.bit_length(), nc.bit_length()
        lv = np.full((kr, kc, nr, nc), -np.inf)
        lv[0, 0] = a
        for k in range(kr):
            if k:
                h = 1 << (k - 1)
                lv[k, 0, : nr - h] = np.maximum(lv[k - 1, 0, : nr - h], lv[k - 1, 0, h:])
            for m in range(1, kc):
                h = 1 << (m - 1)
                lv[k, m, :, : nc - h] = np.maximum(lv[k, m - 1, :, : nc - h], lv[k, m - 1, :, h:])
        self.levels = lv

    def query(self, r0: Any, r1: Any, c0: Any, c1: Any) -> np.ndarray:
        """Maximum over ``a[r0:r1, c0:c1]`` (integer arrays, non-empty ranges)."""
        r0, r1, c0, c1 = np.broadcast_arrays(*(np.asarray(x, np.int64) for x in (r0, r1, c0, c1)))
        k = np.frexp(r1 - r0)[1] - 1  # floor(log2(length)), exact for integers
        m = np.frexp(c1 - c0)[1] - 1
        r2, c2 = r1 - (1 << k), c1 - (1 << m)
        lv = self.levels
        return np.maximum(
            np.maximum(lv[k, m, r0, c0], lv[k, m, r2, c0]),
            np.maximum(lv[k, m, r0, c2], lv[k, m, r2, c2]),
        )


def _proposal_key(proposal: Any) -> Any:
    if isinstance(proposal, str):
        if proposal not in ("majorant", "cosine"):
            raise ParameterError(
                f"proposal must be 'majorant', 'cosine' or a BRDF model, got {proposal!r}"
            )
        return proposal
    if not (hasattr(proposal, "sample") and hasattr(proposal, "pdf")):
        raise ParameterError(
            "proposal must be 'majorant', 'cosine' or a BRDF model with sample and pdf"
        )
    return id(proposal)


def _alias_arrays(w: np.ndarray) -> dict[str, np.ndarray]:
    """Alias table of the weights ``w (n,)`` (positive sum): thresholds ``q``, ``alias`` and
    the probabilities ``p`` the table realizes."""
    q, alias = _vose(w / w.sum())
    n = w.size
    realized = q / n
    np.add.at(realized, alias, (1.0 - q) / n)
    return {"q": q, "alias": alias, "p": realized}


def _axis_cells(ax: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Interpolation cells of an axis: angle ranges ``(lo, hi)`` and their two nodes ``(a, b)``.

    Cells between consecutive nodes, plus the end ranges that the lookup clamps to one node
    (``a == b``), or, on a periodic axis, the cell that wraps from the last node to the first.
    """
    nodes = ax.nodes()
    n = ax.size
    lo, hi, a, b = list(nodes[:-1]), list(nodes[1:]), list(range(n - 1)), list(range(1, n))
    if ax.periodic:
        lo.append(nodes[-1])
        hi.append(nodes[0] + (ax.hi - ax.lo))
        a.append(n - 1)
        b.append(0)
    else:
        if nodes[0] > ax.lo:
            lo.append(ax.lo), hi.append(nodes[0]), a.append(0), b.append(0)
        if nodes[-1] < ax.hi or n == 1:
            lo.append(nodes[-1]), hi.append(ax.hi), a.append(n - 1), b.append(n - 1)
    return np.asarray(lo), np.asarray(hi), np.asarray(a), np.asarray(b)


def _half_diff_ranges(
    theta_i: tuple[np.ndarray, np.ndarray],
    dphi: tuple[np.ndarray, np.ndarray],
    theta_o: tuple[float, float],
) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Ranges ``(lo, hi)`` of theta_h and theta_d (radians) over boxes of directions.

    Each box holds ``wi`` with theta_i in ``theta_i`` and an azimuth ``dphi`` away from
    ``wo``'s, and ``wo`` with theta_o in ``theta_o`` (both above the horizon). The expressions
    are chosen so that interval arithmetic stays tight where ``wi`` and ``wo`` are nearly
    opposite (grazing, near the mirror direction), where ``cos theta_h = (cos theta_i +
    cos theta_o) / |wi + wo|`` evaluated term by term loses everything to cancellation:

    * ``wi . wo = cos(theta_i - theta_o) - sin theta_i sin theta_o (1 - cos dphi)`` and
      ``cos theta_d = sqrt((1 + wi . wo) / 2)``;
    * ``tan^2 theta_h = ((sin theta_i - sin theta_o)^2 + 2 sin theta_i sin theta_o
      (1 + cos dphi)) / (cos theta_i + cos theta_o)^2``.
    """
    ti0, ti1 = theta_i
    t0, t1 = theta_o
    cp_lo, cp_hi = _cos_range(*dphi)
    cdel_lo, cdel_hi = _cos_range(ti0 - t1, ti1 - t0)
    ss_lo, ss_hi = np.sin(ti0) * math.sin(t0), np.sin(ti1) * math.sin(t1)
    p_lo = np.clip(cdel_lo - ss_hi * (1 - cp_lo), -1.0, 1.0)
    p_hi = np.clip(cdel_hi - ss_lo * (1 - cp_hi), -1.0, 1.0)
    td = (np.arccos(np.sqrt((1 + p_hi) / 2)), np.arccos(np.sqrt((1 + p_lo) / 2)))
    # sin theta_i - sin theta_o over the box (each variable once: exact), squared
    dlo, dhi = np.sin(ti0) - math.sin(t1), np.sin(ti1) - math.sin(t0)
    sq_lo = np.where((dlo <= 0) & (dhi >= 0), 0.0, np.minimum(dlo * dlo, dhi * dhi))
    sq_hi = np.maximum(dlo * dlo, dhi * dhi)
    num_lo = sq_lo + 2 * ss_lo * (1 + cp_lo)
    num_hi = sq_hi + 2 * ss_hi * (1 + cp_hi)
    den_lo = np.cos(ti1) + math.cos(t1)  # cos theta_i + cos theta_o >= 0
    den_hi = np.cos(ti0) + math.cos(t0)
    th = (
        np.arctan2(np.sqrt(np.maximum(num_lo, 0.0)), den_hi),
        np.arctan2(np.sqrt(np.maximum(num_hi, 0.0)), np.maximum(den_lo, 0.0)),
    )
    return th, td


def _cos_range(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range of cos over each interval [lo, hi] (hi - lo <= 2 pi)."""
    c_lo = np.minimum(np.cos(lo), np.cos(hi))
    c_hi = np.maximum(np.cos(lo), np.cos(hi))
    k_max = np.ceil(lo / TWO_PI)  # a multiple of 2 pi inside -> max 1
    has_max = k_max * TWO_PI <= hi
    k_min = np.ceil((lo - math.pi) / TWO_PI)
    has_min = k_min * TWO_PI + math.pi <= hi
    return np.where(has_min, -1.0, c_lo), np.where(has_max, 1.0, c_hi)


@partial(jax.jit, static_argnames=("geo",))
def _buckets_met(geo: _Geo, wo: Array) -> Array:
    """``(n_buckets,)`` bool: which outgoing buckets the directions ``wo (..., 3)`` fall in (a
    histogram on the device: only the flags come back, not a bucket per direction)."""
    b = _bucket_of(geo, wo).reshape(-1)
    return jnp.zeros(geo.n_to * geo.n_po, bool).at[b].set(True)


@partial(jax.jit, static_argnames=("geo",))
def _inversion_kernel(geo, slot_of, mcdf, ccdf, cos_desc, omega, wo, u):
    s = jnp.take(slot_of, _bucket_of(geo, wo))
    mflat = mcdf.reshape(-1)
    cflat = ccdf.reshape(-1)
    row, ry, py = _sample_discrete_cdf(mflat, s * (geo.n_t + 1), geo.n_t, u[..., 0])
    col, rx, px = _sample_discrete_cdf(
        cflat, (s * geo.n_t + row) * (geo.n_p + 1), geo.n_p, u[..., 1]
    )
    wi = _direction_in_cell(geo, row, col, ry, rx, cos_desc, wo)
    pdf = py * px / jnp.take(omega, row)
    return wi, pdf


@partial(jax.jit, static_argnames=("geo",))
def _inversion_pdf(geo, slot_of, mcdf, ccdf, cos_asc, omega, wi, wo):
    s = jnp.take(slot_of, _bucket_of(geo, wo))
    row, col = _cell_of(geo, wi, wo, cos_asc)
    mflat = mcdf.reshape(-1)
    cflat = ccdf.reshape(-1)
    mb = s * (geo.n_t + 1) + row
    cb = (s * geo.n_t + row) * (geo.n_p + 1) + col
    py = jnp.take(mflat, mb + 1) - jnp.take(mflat, mb)
    px = jnp.take(cflat, cb + 1) - jnp.take(cflat, cb)
    return py * px / jnp.take(omega, row)


@partial(jax.jit, static_argnames=("geo",))
def _alias_kernel(geo, slot_of, q, alias, p, cos_desc, omega, wo, u):
    wi, _, k, pk = _alias_direction(geo, slot_of, q, alias, p, cos_desc, wo, u)
    return wi, pk / jnp.take(omega, k // geo.n_p)


def _alias_direction(geo, slot_of, q, alias, p, cos_desc, wo, u):
    """A cell of the bucket's alias table and a direction uniform in it: ``(wi, base, k, p_k)``
    with ``k`` the cell within the bucket's table, whose entries start at ``base``."""
    base, k, ry, rx, pk = _alias_cell(geo, slot_of, q, alias, p, wo, u)
    wi = _direction_in_cell(geo, k // geo.n_p, k % geo.n_p, ry, rx, cos_desc, wo)
    return wi, base, k, pk


def _alias_cell(geo, slot_of, q, alias, p, wo, u):
    """The alias-table draw of :func:`_alias_direction`: ``(base, k, ry, rx, p_k)`` with
    ``(ry, rx)`` the position inside cell ``k``."""
    s = jnp.take(slot_of, _bucket_of(geo, wo))
    n = geo.n_t * geo.n_p
    alias_flat = (alias + (jnp.arange(alias.shape[0], dtype=jnp.int32) * n)[:, None]).reshape(-1)
    base = s * n
    k, ry, rx, pk = alias_sample_2d(
        q.reshape(-1), alias_flat, p.reshape(-1), base, n, u[..., 0], u[..., 1]
    )
    return base, k, ry, rx, pk


@partial(jax.jit, static_argnames=("geo",))
def _alias_pdf(geo, slot_of, p, cos_asc, omega, wi, wo):
    s = jnp.take(slot_of, _bucket_of(geo, wo))
    row, col = _cell_of(geo, wi, wo, cos_asc)
    n = geo.n_t * geo.n_p
    return jnp.take(p.reshape(-1), s * n + row * geo.n_p + col) / jnp.take(omega, row)


@partial(jax.jit, static_argnames=("geo", "spec"))
def _rejection_pdf_kernel(geo, spec, data, slot_of, rho, wi, wo):
    from gonio.brdf.tabulated import _eval_kernel

    g = _g_of(_eval_kernel(data, wi, wo, spec))
    return _rejection_pdf_of_g(geo, slot_of, rho, g, wi, wo, None)


@partial(jax.jit, static_argnames=("geo",))
def _rejection_pdf_from_f(geo, slot_of, rho, f, wi, wo, accepted=None):
    """``g cos theta_i / rho(wo)`` from the table's values ``f (..., C)`` at ``(wi, wo)`` (0
    where ``accepted`` is False)."""
    # the channels summed elementwise: here f is an input, not a fused lookup (see _g_of),
    # and XLA's CPU reduction would be the slowest part of this kernel
    total = f[..., 0]
    for c in range(1, f.shape[-1]):
        total = total + f[..., c]
    return _rejection_pdf_of_g(
        geo, slot_of, rho, jnp.maximum(total / f.shape[-1], 0.0), wi, wo, accepted
    )


def _rejection_pdf_of_g(geo, slot_of, rho, g, wi, wo, accepted):
    rho_o = _rho_interp(geo, slot_of, rho, wo)
    ok = rho_o > 0
    if accepted is not None:
        ok &= accepted
    return jnp.where(ok, g * jnp.maximum(wi[..., 2], 0.0) / jnp.where(ok, rho_o, 1.0), 0.0)


_seeds_jit = jax.jit(seeds_from_u)


@jax.jit
def _as_float32(wo: Array, u: Array) -> tuple[Array, Array]:
    """Float32 ``(wo, u)`` for the proposals, ``u`` kept below 1 after rounding."""
    return wo.astype(jnp.float32), jnp.clip(u.astype(jnp.float32), 0.0, _ONE_MINUS_EPS32)


def _g_of(f: Array) -> Array:
    """``g = max(mean over channels of f, 0)`` from ``f (..., C)``, the sampled target.

    Kept a reduction on purpose: in a rejection round it is what stops XLA's CPU backend from
    fusing the table lookup's gathers into each consumer of ``f`` (summing the channels as
    elementwise adds instead splits the eight corner gathers into separately stored arrays,
    and the round runs about 25 % slower).
    """
    return jnp.maximum(jnp.mean(f, axis=-1), 0.0)


def _rho_interp(geo: _Geo, slot_of: Array, rho: Array, wo: Array) -> Array:
    b = _bucket_of(geo, wo)
    s = jnp.take(slot_of, b)
    x, y, z = wo[..., 0], wo[..., 1], wo[..., 2]
    theta = _atan2(jnp.sqrt(x * x + y * y), z)
    bt = b // geo.n_po
    ft = jnp.clip(theta * (geo.n_to / HALF_PI) - bt.astype(theta.dtype), 0.0, 1.0)
    if geo.iso:
        k = _RHO_NODES - 1
        tpos = ft * k
        i0 = jnp.clip(jnp.floor(tpos).astype(jnp.int32), 0, k - 1)
        fr = tpos - i0.astype(tpos.dtype)
        flat = rho.reshape(-1)
        base = s * _RHO_NODES + i0
        return (1 - fr) * jnp.take(flat, base) + fr * jnp.take(flat, base + 1)
    k = _RHO_NODES_ANISO - 1
    phi = _atan2(y, x)
    phi = jnp.where(phi < 0, phi + TWO_PI, phi)
    bp = b % geo.n_po
    fp = jnp.clip(phi * (geo.n_po / TWO_PI) - bp.astype(phi.dtype), 0.0, 1.0)
    tp, pp = ft * k, fp * k
    i0 = jnp.clip(jnp.floor(tp).astype(jnp.int32), 0, k - 1)
    j0 = jnp.clip(jnp.floor(pp).astype(jnp.int32), 0, k - 1)
    a, c = tp - i0.astype(tp.dtype), pp - j0.astype(pp.dtype)
    flat = rho.reshape(-1)
    kk = _RHO_NODES_ANISO
    base = s * kk * kk + i0 * kk + j0
    v00, v01 = jnp.take(flat, base), jnp.take(flat, base + 1)
    v10, v11 = jnp.take(flat, base + kk), jnp.take(flat, base + kk + 1)
    return (1 - a) * ((1 - c) * v00 + c * v01) + a * ((1 - c) * v10 + c * v11)


def _majorant_round(table, geo, slot_of, q, alias, bound, cos_desc, wo, up, ua):
    """One proposal from the bucket's piecewise-constant majorant (:meth:`TableSampler._majorant`)
    and its acceptance test per query: ``((wi, f), accepted)``."""
    base, k, ry, rx, _ = _alias_cell(geo, slot_of, q, alias, q, wo, up)
    # stacked from its components directly (not :func:`_direction_in_cell`'s transpose): here
    # XLA then fuses the components into the lookup and stores wi once (about 4 % faster)
    wi = jnp.stack(_direction_components(geo, k // geo.n_p, k % geo.n_p, ry, rx, cos_desc, wo), -1)
    f = table.f(wi, wo)
    g = _g_of(f)
    accept = ua * jnp.take(bound.reshape(-1), base + k) < g * wi[..., 2]
    return (wi, f.astype(wi.dtype)), accept & (wi[..., 2] > 0)


def _rejection_round(table, model, geo, slot_of, bound, wo, up, ua):
    """One proposal (cosine or ``model`` mixed with cosine) and acceptance test per query:
    ``((wi, f), accepted)``."""
    s = jnp.take(slot_of, _bucket_of(geo, wo))
    M = jnp.take(bound, s)
    if model is None:
        wi = warp.square_to_cosine_hemisphere(up).astype(wo.dtype)
        f = table.f(wi, wo)
        ratio_num = _g_of(f) * jnp.pi
        accept = ua * M < ratio_num
        return (wi, f.astype(wi.dtype)), accept & (wi[..., 2] > 0)
    eps = _PROPOSAL_EPS
    use_cos = up[..., 0] < eps
    u0 = jnp.where(use_cos, up[..., 0] / eps, (up[..., 0] - eps) / (1 - eps))
    uu = jnp.clip(jnp.stack([u0, up[..., 1]], -1), 0.0, 1.0 - 1e-7)
    wi_c = warp.square_to_cosine_hemisphere(uu).astype(wo.dtype)
    wi_m = model.sample(wo, uu).wi.astype(wo.dtype)
    wi = jnp.where(use_cos[..., None], wi_c, wi_m)
    q = eps * jnp.maximum(wi[..., 2], 0.0) / jnp.pi + (1 - eps) * model.pdf(wi, wo).astype(wo.dtype)
    f = table.f(wi, wo)
    g = _g_of(f)
    accept = ua * M * q < g * wi[..., 2]
    return (wi, f.astype(wi.dtype)), accept & (wi[..., 2] > 0)
