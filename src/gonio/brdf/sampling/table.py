"""Importance sampling of ``f cos`` for tabulated BRDFs (used by :class:`TabulatedBRDF`).

The sampled density is proportional to ``g(wi, wo) cos(theta_i)`` where ``g = max(mean over
channels of f, 0)``. Outgoing directions are grouped in buckets and incident directions on a
grid (:mod:`gonio.brdf.sampling.table_buckets`); every per-bucket structure is built the first
time a direction in that bucket is sampled or evaluated, and cached; nothing is built for
buckets nobody asks about. ``cache_size(method)`` says how many buckets are built.

Methods
-------
``"inversion"``
    Incident directions on an ``n_theta_i x n_phi_i`` grid (uniform in theta_i and phi); each
    cell's weight is the mean of ``g cos`` over 2 x 2 points per cell and 2 (isotropic) or 4
    (anisotropic) outgoing directions in the bucket, times the cell's solid angle, plus 0.1 % of
    a uniform density so that no cell where ``f > 0`` has zero probability. A cell is picked
    by marginal/conditional CDF inversion (one batched
    :class:`gonio.brdf.sampling.distributions.Distribution2D`, a distribution per bucket) and the
    direction is
    uniform in (cos theta, phi) inside it, so the pdf is piecewise constant per unit solid
    angle: ``P_cell / Omega_cell``.
``"alias"``
    The same density, with the cell drawn from an alias table (O(1) per sample; one uniform
    number picks the column, the other decides between the column and its alias, so that
    float32 keeps every cell's probability to 2^-24).
``"rejection"``
    Exact sampling of ``g cos / rho(wo)`` (:mod:`gonio.brdf.sampling.table_rejection`), the
    reference density.
"""

from __future__ import annotations

import math
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf.sampling.distributions import Distribution2D, alias_arrays, alias_sample_2d
from gonio.brdf.sampling.table_buckets import (
    TWO_PI,
    BucketGeometry,
    LazyBuckets,
    bucket_of,
    bucket_ranges,
    cell_of,
    direction_in_cell,
    incident_grid,
)
from gonio.brdf.sampling.table_rejection import TableRejection
from gonio.errors import ParameterError

Array = jnp.ndarray
_UNIFORM_FLOOR = 1e-3


class TableSampler:
    """Lazily built sampling structures of one table (see the module docstring)."""

    def __init__(self, table: Any) -> None:
        self.table = table
        n_to, n_t, n_p = table.sampling_res
        self.geo = BucketGeometry(
            table.isotropic, n_to, 1 if table.isotropic else 2 * n_to, n_t, n_p
        )
        self.n_buckets = self.geo.n_to * self.geo.n_po
        cos_desc, self.omega = incident_grid(n_t, n_p)
        self.cos_desc = cos_desc
        with jax.ensure_compile_time_eval():  # the sampler may be created under a jit trace
            self._consts = {
                dt: (
                    jax.device_put(cos_desc.astype(dt)),
                    jax.device_put(cos_desc[::-1].astype(dt)),
                    jax.device_put(self.omega.astype(dt)),
                )
                for dt in (jnp.float32, jnp.float64)
            }
        self._grid = LazyBuckets(self._build_grid, combine=_grid_distribution)
        self._alias = LazyBuckets(self._build_alias)
        self.rejection = TableRejection(table, self.geo)
        self.stats = self.rejection.stats

    # -- cache ---------------------------------------------------------------------------------
    def _stores(self, method: str | None) -> list[LazyBuckets]:
        rej = list(self.rejection.stores.values())
        return {"inversion": [self._grid], "alias": [self._alias], "rejection": rej}.get(
            method, [self._grid, self._alias, *rej]
        )

    def cache_size(self, method: str | None = None) -> int:
        return sum(len(s.items) for s in self._stores(method))

    def built_buckets(self, method: str) -> list[int]:
        return sorted({b for s in self._stores(method) for b in s.items})

    def _store(self, method: str) -> LazyBuckets:
        if method == "inversion":
            return self._grid
        if method == "alias":
            return self._alias
        raise ParameterError(
            f"unknown sampling method {method!r} (expected inversion, alias or rejection)"
        )

    # -- inversion / alias ---------------------------------------------------------------------
    def _g(self, wi: Any, wo: Any) -> np.ndarray:
        v = np.asarray(self.table.f(wi, wo))
        return np.maximum(v.mean(axis=-1), 0.0)

    def _bucket_wos(self, b: int) -> np.ndarray:
        t0, t1, p0, p1 = bucket_ranges(self.geo, b)
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
        return {b: {"w": self._cell_weights(b)} for b in buckets}

    def _build_alias(self, buckets: list[int]) -> dict[int, dict[str, np.ndarray]]:
        return {b: alias_arrays(self._cell_weights(b).reshape(-1)) for b in buckets}

    # -- public entry points -------------------------------------------------------------------
    def state(self, method: str, wo: Any, proposal: Any, dt: Any) -> dict[str, Any]:
        """The device arrays :meth:`sample` and :meth:`pdf` read for ``method``, with the
        buckets of the directions ``wo (..., 3)`` (or a list of such arrays) built (every bucket
        when ``wo`` is traced).

        A pytree of arrays: passed to a jitted caller as an argument, it lets that caller trace
        :meth:`sample` and :meth:`pdf` (``state=``) with no host work and no host round trip;
        a direction in a bucket that was not built uses another built bucket's structures in
        both (inversion and alias stay unbiased, their densities covering every cell).
        """
        if method == "rejection":
            return self.rejection.state(wo, proposal, dt)
        slot_of, arrays = self._store(method).prepare(self.geo, wo, dt)
        return {"slot_of": slot_of, "arrays": arrays, "consts": self._consts[dt]}

    def sample(self, wo: Array, u: Array, method: str, rng: Any, proposal: Any, state=None):
        """``(wi, pdf)`` for ``wo (..., 3)``, ``u (..., 2)``, in ``wo``'s precision; ``state``
        from :meth:`state` (default: built here for ``wo``)."""
        dt = jnp.float64 if wo.dtype == jnp.float64 else jnp.float32
        if state is None:
            state = self.state(method, wo, proposal, dt)
        if method == "rejection":  # proposals and acceptance tests run in float32
            return self.rejection.sample(wo, u, rng, proposal, dt, state)
        slot_of, arrays = state["slot_of"], state["arrays"]
        cos_desc, _cos_asc, omega = state["consts"]
        if method == "inversion":
            return _inversion_kernel(self.geo, slot_of, arrays["dist"], cos_desc, omega, wo, u)
        q, alias, p = arrays["q"], arrays["alias"], arrays["p"]
        return _alias_kernel(self.geo, slot_of, q, alias, p, cos_desc, omega, wo, u)

    def pdf(self, wi: Array, wo: Array, method: str, proposal: Any, state=None) -> Array:
        dt = jnp.float64 if wo.dtype == jnp.float64 else jnp.float32
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        if state is None:
            state = self.state(method, wo, proposal, dt)
        if method == "rejection":
            return jnp.where(ok, self.rejection.pdf(wi, wo, proposal, dt, state), 0.0)
        slot_of, arrays = state["slot_of"], state["arrays"]
        _cos_desc, cos_asc, omega = state["consts"]
        if method == "inversion":
            p = _inversion_pdf(self.geo, slot_of, arrays["dist"], cos_asc, omega, wi, wo)
        else:
            p = _alias_pdf(self.geo, slot_of, arrays["p"], cos_asc, omega, wi, wo)
        return jnp.where(ok, p, 0.0)


def _grid_distribution(stacks: dict[str, np.ndarray]) -> dict[str, Distribution2D]:
    """The inversion's per-bucket cell weights ``(slots, n_t, n_p)`` as one batched
    distribution (``which`` = the bucket's slot)."""
    return {"dist": Distribution2D(stacks["w"])}


@partial(jax.jit, static_argnames=("geo",))
def _inversion_kernel(geo, slot_of, dist, cos_desc, omega, wo, u):
    s = jnp.take(slot_of, bucket_of(geo, wo))
    (row, col), (ry, rx), p = dist.sample_cell(u, s, clip=False)  # u: clipped by the caller
    wi = direction_in_cell(geo, row, col, ry, rx, cos_desc, wo)
    return wi, p / jnp.take(omega, row)


@partial(jax.jit, static_argnames=("geo",))
def _inversion_pdf(geo, slot_of, dist, cos_asc, omega, wi, wo):
    s = jnp.take(slot_of, bucket_of(geo, wo))
    row, col = cell_of(geo, wi, wo, cos_asc)
    return dist.cell_prob(row, col, s, wi.dtype) / jnp.take(omega, row)


@partial(jax.jit, static_argnames=("geo",))
def _alias_kernel(geo, slot_of, q, alias, p, cos_desc, omega, wo, u):
    s = jnp.take(slot_of, bucket_of(geo, wo))
    n = geo.n_t * geo.n_p
    alias_flat = (alias + (jnp.arange(alias.shape[0], dtype=jnp.int32) * n)[:, None]).reshape(-1)
    k, ry, rx, pk = alias_sample_2d(
        q.reshape(-1), alias_flat, p.reshape(-1), s * n, n, u[..., 0], u[..., 1]
    )
    wi = direction_in_cell(geo, k // geo.n_p, k % geo.n_p, ry, rx, cos_desc, wo)
    return wi, pk / jnp.take(omega, k // geo.n_p)


@partial(jax.jit, static_argnames=("geo",))
def _alias_pdf(geo, slot_of, p, cos_asc, omega, wi, wo):
    s = jnp.take(slot_of, bucket_of(geo, wo))
    row, col = cell_of(geo, wi, wo, cos_asc)
    n = geo.n_t * geo.n_p
    return jnp.take(p.reshape(-1), s * n + row * geo.n_p + col) / jnp.take(omega, row)


__all__ = ["TableSampler"]
