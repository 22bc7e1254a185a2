"""Exact rejection sampling of tabulated BRDFs: the reference density ``g cos / rho(wo)``.

The sampled density is proportional to ``g(wi, wo) cos(theta_i)`` with ``g = max(mean over
channels of f, 0)``, exactly (not piecewise constant like inversion and alias): it serves as the
reference that the faster samplers are checked against. Two proposals ``q``:

``"majorant"`` (default)
    Per outgoing bucket (:mod:`gonio.brdf.table_buckets`), a rigorous bound ``m_c`` of
    ``g cos`` over each cell of an incident grid twice as fine as the inversion's
    (``_MAJORANT_REFINE``) and every outgoing direction in the bucket; cells are drawn in
    proportion to ``m_c Omega_c`` from an alias table, the direction is uniform in the cell, and
    it is accepted with probability ``g cos / bound_c`` (``bound_c >= m_c``, computed from the
    probability the alias table realizes). Acceptance is ``rho / sum m_c Omega_c``: 0.83 on
    average over the hemisphere for the benchmark's MERL-grid table.
``"cosine"``
    A cosine-weighted hemisphere, accepted with probability ``g cos / (M q)``, ``M`` a bound of
    ``pi g`` over the bucket. Simple, but a glossy lobe makes ``M`` large.
a BRDF model
    The model's own sampling mixed with 10 % cosine sampling, ``M`` a bound of ``g cos / q``
    over the bucket. The bucket's theta_o range is bounded in 4 parts, and the lower bound of the
    model's pdf per cell of a 48 x 96 grid comes from evaluating it at 3 x 3 points x 12
    outgoing directions per part (the one heuristic part; the cosine part of the mixture keeps
    the bound finite).

The table bounds are rigorous: interval bounds of theta_h and theta_d over each incident-grid
cell and the bucket (in forms that stay tight near grazing mirror configurations, see
``half_diff_ranges``), interval bounds of ``cos theta_o`` and ``cos theta_i`` over each table
cell, which say which cells, phi_d included, the bucket can reach at all and how large
``g cos theta_i`` can be in them, and multilinear interpolation never exceeds the largest valid
node it uses. ``rho(wo) = int g cos dwi`` is computed by a 128 x 256 midpoint quadrature over
the half vector (sqrt-warped theta_h, where the tables put their nodes) at 9 theta_o nodes per
bucket (5 x 5 (theta_o, phi_o) nodes for anisotropic tables) and interpolated linearly in
between. Proposals and acceptance tests run in float32, in one traced loop
(:func:`gonio.brdf.sampling.rejection_sample_traced`) whether called eagerly or under ``jit``.
"""

from __future__ import annotations

import dataclasses
import math
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf import warp
from gonio.brdf.lookup import atan2, eval_kernel
from gonio.brdf.sampling import (
    alias_arrays,
    alias_sample_2d,
    rejection_sample_traced,
    seeds_from_rng,
    seeds_from_u,
)
from gonio.brdf.table_bounds import RangeMax2D, axis_cells, cos_range, half_diff_ranges
from gonio.brdf.table_buckets import (
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
_ONE_MINUS_EPS32 = float(np.nextafter(np.float32(1.0), np.float32(0.0)))
_RHO_NODES = 9
_RHO_NODES_ANISO = 5
_RHO_RES = (128, 256)
_BOUND_RES = (16, 32)  # incident cells for the cosine-proposal bound
_MAJORANT_REFINE = 2  # the majorant's incident grid is this much finer than sampling_res's
_PROPOSAL_EPS = 0.1  # share of cosine sampling in a model proposal's mixture
_BOUND_RES_MODEL = (48, 96)  # finer: a model proposal's pdf varies within a cell
_MODEL_BOUND_SPLIT = 4  # theta_o parts per bucket bounded separately for a model proposal
# Rejection bound of a bucket where g = 0 everywhere: negative, so that the acceptance test
# (u * bound < g cos) passes at once; the sample's pdf is then 0 (rho = 0) and it fails as it
# should, after one proposal instead of max_rounds rejected ones.
_EMPTY = -1.0
PROPOSALS = ("majorant", "cosine")


class TableRejection:
    """Lazily built rejection structures of one table, per proposal and outgoing bucket.

    Parameters
    ----------
    table : the :class:`gonio.brdf.tabulated.TabulatedBRDF`.
    geo : the sampler's bucket geometry (the majorant refines its incident grid).
    """

    def __init__(self, table: Any, geo: BucketGeometry) -> None:
        self.table = table
        self.geo = geo
        self.n_buckets = geo.n_to * geo.n_po
        # the majorant's cells are finer: its acceptance is limited by how much g cos varies
        # within a cell (0.77 -> 0.84 on the benchmark table for twice the resolution)
        self.geo_major = dataclasses.replace(
            geo, n_t=_MAJORANT_REFINE * geo.n_t, n_p=_MAJORANT_REFINE * geo.n_p
        )
        self.cos_desc_major, self.omega_major = incident_grid(
            self.geo_major.n_t, self.geo_major.n_p
        )
        with jax.ensure_compile_time_eval():  # the sampler may be created under a jit trace
            self._major_cos_desc = jnp.asarray(self.cos_desc_major, jnp.float32)
        self.stores = {p: LazyBuckets(partial(self._build, proposal=p)) for p in PROPOSALS}
        self._node_max: RangeMax2D | None = None
        self._sup_cache: dict[str, np.ndarray] | None = None
        self._runs: dict[str, Any] = {}
        self.stats: dict[str, float] = {}

    def store(self, proposal: Any) -> LazyBuckets:
        key = _proposal_key(proposal)
        if key not in self.stores:  # an analytic model, kept by the store's build function
            self.stores[key] = LazyBuckets(partial(self._build, proposal=proposal))
        return self.stores[key]

    def _bucket_ranges(self, b: int) -> tuple[float, float, float, float]:
        return bucket_ranges(self.geo, b)

    def _g(self, wi: Any, wo: Any) -> np.ndarray:
        v = np.asarray(self.table.f(wi, wo))
        return np.maximum(v.mean(axis=-1), 0.0)

    # -- bounds of g cos ------------------------------------------------------------------------
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

    def _reachable(self, t0: float, t1: float) -> tuple[float, RangeMax2D, RangeMax2D]:
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
        cells = RangeMax2D(m.max(axis=2)[order])
        m *= np.clip(st["wi_hi"] + eps, 0.0, 1.0)
        cos_cells = RangeMax2D(m.max(axis=2)[order])
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
        h_lo, h_hi, h_a, h_b = axis_cells(t.axes[names.index("theta_h")])
        d_lo, d_hi, d_a, d_b = axis_cells(t.axes[names.index("theta_d")])
        p_lo, p_hi, p_a, p_b = axis_cells(t.axes[names.index("phi_d")])
        # largest corner of every cell, as a bound of g = max(mean, 0)
        cmax = np.zeros((len(h_a), len(d_a), len(p_a)))
        for hs in (h_a, h_b):
            for ds in (d_a, d_b):
                for ps in (p_a, p_b):
                    cmax = np.maximum(cmax, v[np.ix_(hs, ds, ps)])
        ca = (np.cos(h_hi)[:, None] * np.cos(d_hi)[None, :], np.cos(h_lo)[:, None] * np.cos(d_lo))
        sb = (np.sin(h_lo)[:, None] * np.sin(d_lo)[None, :], np.sin(h_hi)[:, None] * np.sin(d_hi))
        c_lo, c_hi = cos_range(p_lo, p_hi)
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
        reach: tuple[float, RangeMax2D, RangeMax2D],
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``g`` and of ``g cos theta_i`` over boxes of (theta_h, theta_d) angle
        ranges (arrays of lo, hi), for the outgoing range whose :meth:`_reachable` is
        ``reach`` (the bound of ``g`` is at most that range's ``sup``)."""
        t = self.table
        ax_h = next(a for a in t.axes if a.name == "theta_h")
        ax_d = next(a for a in t.axes if a.name == "theta_d")
        if self._node_max is None:
            self._node_max = RangeMax2D(self._h_max())

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
        th, td = half_diff_ranges((ti0, ti1), (d0, d1), (t0, t1))
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

    def _build(self, buckets: list[int], proposal: Any) -> dict[int, dict[str, np.ndarray]]:
        out = {}
        for b in buckets:
            if proposal == "majorant":
                out[b] = {**self._majorant(b), "rho": self._rho_nodes(b)}
                continue
            if proposal == "cosine":  # g cos / (cos / pi) = pi g
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
            return {**alias_arrays(omega), "bound": np.full(m.shape, _EMPTY)}
        arrays = alias_arrays(w)
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

    # -- entry points ----------------------------------------------------------------------------
    def sample(self, wo: Array, u: Array, rng: Any, proposal: Any, dt: Any):
        """``(wi, pdf, f)`` for ``wo (..., 3)``, ``u (..., 2)``: ``f (..., C)`` is the table at
        ``(wi, wo)`` when the acceptance test looked it up in the caller's precision (float32),
        else None."""
        shape = wo.shape[:-1]
        wo_f = wo.reshape(-1, 3)
        u_f = u.reshape(-1, 2)
        store = self.store(proposal)
        # proposals run in float32, where a direction on a bucket edge may round into the
        # neighbouring bucket: that one is built too
        slot_of, arrays = store.prepare(self.geo, wo_f, jnp.float32, also_float32=True)
        if rng is not None:
            seeds = seeds_from_rng(rng, (wo_f.shape[0],))
        else:
            seeds = _seeds_jit(u_f)
        # the caller's u is already clipped below 1 (in its own dtype)
        wo32, u32 = (wo_f, u_f) if dt == jnp.float32 else _as_float32(wo_f, u_f)
        if proposal == "majorant":
            keys = ("q", "alias", "bound")
            consts = (slot_of, *(arrays[k] for k in keys), self._major_cos_desc)
        else:  # cosine or a model
            consts = (slot_of, arrays["bound"])
        t = self.table
        if isinstance(wo, jax.core.Tracer) or isinstance(u, jax.core.Tracer):
            x, ok, _ = _run(self._round_fn(proposal), t, consts, wo32, u32, seeds)
        else:
            x, ok, rounds = _run_jit(self._round_fn(proposal), t, consts, wo32, u32, seeds)
            self.stats["rejection_proposals"] = float(np.sum(rounds, dtype=np.int64))
            self.stats["rejection_samples"] = float(wo_f.shape[0])
        wi, f = x
        if dt == jnp.float32:  # the acceptance test looked f up at (wi, wo) in float32
            pdf = _pdf_from_f(self.geo, slot_of, arrays["rho"], f, wi, wo_f, ok)
            return wi.reshape(*shape, 3), pdf.reshape(shape), f.reshape(*shape, f.shape[-1])
        wi = wi.astype(dt)
        _, arrays = store.stacked(self.n_buckets, dt)
        pdf = jnp.where(ok, self._pdf(slot_of, arrays, wi, wo_f), 0.0)
        return wi.reshape(*shape, 3), pdf.reshape(shape), None

    def _round_fn(self, proposal: Any) -> Any:
        """The proposal function for :func:`_run` (one object per proposal, so that the
        jit cache of :func:`_run_jit` is hit on every call)."""
        key = _proposal_key(proposal)
        fn = self._runs.get(key)
        if fn is None:
            if proposal == "majorant":
                fn = partial(_majorant_round, self.geo_major)
            elif proposal == "cosine":
                fn = partial(_cosine_round, self.geo)
            else:
                fn = partial(_model_round, self.geo, proposal)
            self._runs[key] = fn
        return fn

    def pdf(self, wi: Array, wo: Array, proposal: Any, dt: Any) -> Array:
        slot_of, arrays = self.store(proposal).prepare(self.geo, wo, dt, also_float32=True)
        return self._pdf(slot_of, arrays, wi, wo)

    def _pdf(self, slot_of: Array, arrays: dict[str, Array], wi: Array, wo: Array) -> Array:
        t = self.table
        return _pdf_kernel(self.geo, t._spec, t._data, slot_of, arrays["rho"], wi, wo)


def _proposal_key(proposal: Any) -> Any:
    if isinstance(proposal, str):
        if proposal not in PROPOSALS:
            raise ParameterError(
                f"proposal must be 'majorant', 'cosine' or a BRDF model, got {proposal!r}"
            )
        return proposal
    if not (hasattr(proposal, "sample") and hasattr(proposal, "pdf")):
        raise ParameterError(
            "proposal must be 'majorant', 'cosine' or a BRDF model with sample and pdf"
        )
    return id(proposal)


def _run(round_fn, table, consts, wo, u, seeds):
    """:func:`rejection_sample_traced` of ``round_fn(table, *consts, wo, u_prop, u_acc)``."""
    return rejection_sample_traced(
        lambda w, up, ua: round_fn(table, *consts, w, up, ua), (wo,), u, seeds
    )


_run_jit = jax.jit(_run, static_argnums=0)


@partial(jax.jit, static_argnames=("geo", "spec"))
def _pdf_kernel(geo, spec, data, slot_of, rho, wi, wo):
    g = _g_of(eval_kernel(data, wi, wo, spec))
    return _pdf_of_g(geo, slot_of, rho, g, wi, wo, None)


@partial(jax.jit, static_argnames=("geo",))
def _pdf_from_f(geo, slot_of, rho, f, wi, wo, accepted=None):
    """``g cos theta_i / rho(wo)`` from the table's values ``f (..., C)`` at ``(wi, wo)`` (0
    where ``accepted`` is False)."""
    return _pdf_of_g(geo, slot_of, rho, _g_of(f), wi, wo, accepted)


def _pdf_of_g(geo, slot_of, rho, g, wi, wo, accepted):
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
    """``g = max(mean over channels of f, 0)`` from ``f (..., C)``, the sampled target."""
    return jnp.maximum(jnp.mean(f, axis=-1), 0.0)


def _rho_interp(geo: BucketGeometry, slot_of: Array, rho: Array, wo: Array) -> Array:
    b = bucket_of(geo, wo)
    s = jnp.take(slot_of, b)
    x, y, z = wo[..., 0], wo[..., 1], wo[..., 2]
    theta = atan2(jnp.sqrt(x * x + y * y), z)
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
    phi = atan2(y, x)
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


def _majorant_round(geo, table, slot_of, q, alias, bound, cos_desc, wo, up, ua):
    """One proposal from the bucket's piecewise-constant majorant (:meth:`TableRejection._majorant`)
    and its acceptance test per query: ``((wi, f), accepted)``."""
    s = jnp.take(slot_of, bucket_of(geo, wo))
    n = geo.n_t * geo.n_p
    alias_flat = (alias + (jnp.arange(alias.shape[0], dtype=jnp.int32) * n)[:, None]).reshape(-1)
    base = s * n
    k, ry, rx, _ = alias_sample_2d(
        q.reshape(-1), alias_flat, q.reshape(-1), base, n, up[..., 0], up[..., 1]
    )
    wi = direction_in_cell(geo, k // geo.n_p, k % geo.n_p, ry, rx, cos_desc, wo)
    f = table.f(wi, wo)
    g = _g_of(f)
    accept = ua * jnp.take(bound.reshape(-1), base + k) < g * wi[..., 2]
    return (wi, f.astype(wi.dtype)), accept & (wi[..., 2] > 0)


def _cosine_round(geo, table, slot_of, bound, wo, up, ua):
    """One cosine-weighted proposal and its acceptance test per query: ``((wi, f), accepted)``."""
    M = jnp.take(bound, jnp.take(slot_of, bucket_of(geo, wo)))
    wi = warp.square_to_cosine_hemisphere(up).astype(wo.dtype)
    f = table.f(wi, wo)
    accept = ua * M < _g_of(f) * jnp.pi
    return (wi, f.astype(wi.dtype)), accept & (wi[..., 2] > 0)


def _model_round(geo, model, table, slot_of, bound, wo, up, ua):
    """One proposal from ``model`` mixed with cosine sampling and its acceptance test per
    query: ``((wi, f), accepted)``."""
    M = jnp.take(bound, jnp.take(slot_of, bucket_of(geo, wo)))
    eps = _PROPOSAL_EPS
    use_cos = up[..., 0] < eps
    u0 = jnp.where(use_cos, up[..., 0] / eps, (up[..., 0] - eps) / (1 - eps))
    uu = jnp.clip(jnp.stack([u0, up[..., 1]], -1), 0.0, 1.0 - 1e-7)
    wi_c = warp.square_to_cosine_hemisphere(uu).astype(wo.dtype)
    wi_m = model.sample(wo, uu).wi.astype(wo.dtype)
    wi = jnp.where(use_cos[..., None], wi_c, wi_m)
    q = eps * jnp.maximum(wi[..., 2], 0.0) / jnp.pi + (1 - eps) * model.pdf(wi, wo).astype(wo.dtype)
    f = table.f(wi, wo)
    accept = ua * M * q < _g_of(f) * wi[..., 2]
    return (wi, f.astype(wi.dtype)), accept & (wi[..., 2] > 0)


__all__ = ["PROPOSALS", "TableRejection"]
