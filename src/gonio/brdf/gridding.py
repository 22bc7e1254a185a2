"""Scattered BRDF samples onto an isotropic half/diff grid: binning and interpolation.

Two ways, for two jobs:

:func:`grid_samples` (binning, the measurement step)
    Each sample falls into the grid cell of its ``(theta_h, theta_d, phi_d)`` (nearest node,
    ``phi_d`` folded into ``[0, pi)`` by reciprocity); a node's value is the inverse-variance
    weighted mean of its samples, with sigma ``1 / sqrt(sum w)``. Nodes without samples are
    masked invalid: the table never claims data it does not have. This is what
    ``RUN/table.brdf.h5`` stores in ``/gridded`` and what ``gonio grid --method bin`` writes.

:func:`interpolate_samples` (a scattered-data interpolant, for rendering and resampling)
    Piecewise-linear interpolation of ``log(f + floor)`` over a Delaunay tetrahedralization of
    the samples in the embedding ``(theta_h, theta_d cos 2 phi_d, theta_d sin 2 phi_d)``
    (radians). The embedding is continuous where the angles are not: ``phi_d`` has period ``pi``
    (reciprocity) and no meaning at ``theta_d = 0``, where every ``phi_d`` maps to one point.
    Every sample is mirrored to ``-phi_d`` and to ``-theta_h`` (an isotropic, reciprocal BRDF is
    even in both: tilting the half vector through the normal turns ``phi_d`` by ``pi``), so the
    hull covers the specular peak at ``theta_h = 0`` from both sides instead of ending there.
    Interpolating the logarithm keeps values positive and follows a specular lobe's
    exponential fall-off better than linear interpolation of ``f`` does; ``floor`` (per channel,
    1e-3 of the median positive value) keeps zeros and noisy negatives finite.
    The interpolant passes through every (de-duplicated) sample. Nodes outside the convex hull of
    the samples take the value of the nearest sample in the embedding and are masked invalid
    (the coverage mask); sigma is propagated through the interpolation weights (to first order in
    ``log f``: ``sigma^2 = sum_k (dF / df_k)^2 sigma_k^2``), and is 0 outside the hull.
    Samples that span only a plane or a line in the embedding (a 1-D file such as ALTA's
    ``COS_TH``, all at ``theta_d = 0``) are interpolated in that plane or along that line: each
    node takes the interpolated value at its projection onto it, and only nodes on it count as
    covered.

Only isotropic data is supported (``half_diff_iso``); the anisotropic part of a sample set is
averaged over ``phi_h`` by construction. Directions are unit vectors in the local frame (z the
normal), values in 1/sr.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from gonio.brdf.tabulated import Axis, TabulatedBRDF
from gonio.errors import ParameterError

__all__ = [
    "default_grid",
    "grid_samples",
    "half_diff_iso",
    "interpolate_samples",
    "render_axes",
]


def half_diff_iso(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(theta_h, theta_d, phi_d) in radians of direction pairs (N, 3); phi_d folded to [0, pi)."""
    from gonio.brdf import frames

    th, _, td, pd = (np.asarray(x, dtype=float) for x in frames.half_diff(wi, wo))
    return th, td, np.mod(pd, math.pi)


def default_grid(n_theta_h: int = 16, n_theta_d: int = 15, n_phi_d: int = 12) -> tuple[Axis, ...]:
    """A coarse isotropic half/diff grid suited to plans of tens to thousands of samples.

    theta_h is sqrt-warped (dense near the specular peak), theta_d linear, phi_d periodic over
    [0, pi); nodes at cell centres (``node_offset = 0.5``) so that every cell is centred on its
    node (theta_h's first node sits at 0, where the peak is).
    """
    half = math.pi / 2
    return (
        Axis("theta_h", n_theta_h, 0.0, half, "sqrt", False, 0.0),
        Axis("theta_d", n_theta_d, 0.0, half, "linear", False, 0.5),
        Axis("phi_d", n_phi_d, 0.0, math.pi, "linear", True, 0.5),
    )


def render_axes(n_theta_h: int = 64, n_theta_d: int = 32, n_phi_d: int = 32) -> tuple[Axis, ...]:
    """The grid the renderer tabulates a scattered interpolant on (sqrt-warped theta_h)."""
    half = math.pi / 2
    return (
        Axis("theta_h", n_theta_h, 0.0, half, "sqrt", False, 0.0),
        Axis("theta_d", n_theta_d, 0.0, half, "linear", False, 0.0),
        Axis("phi_d", n_phi_d, 0.0, math.pi, "linear", True, 0.0),
    )


def grid_samples(samples: Any, axes: tuple[Axis, ...] | None = None) -> TabulatedBRDF:
    """Bin scattered samples onto an isotropic half/diff grid (see the module docstring).

    Samples without sigma are weighted equally (sigma of the node: the standard error of the
    mean when the node has two or more samples, else none is claimed: the node's sigma is 0 and
    its count tells).
    """
    axes = axes or default_grid()
    _check_iso_axes(axes)
    th, td, pd = half_diff_iso(samples.wi, samples.wo)
    idx = [np.asarray(a.nearest_index(x)) for a, x in zip(axes, (th, td, pd), strict=True)]
    shape = tuple(a.size for a in axes)
    flat = np.ravel_multi_index(tuple(idx), shape)
    vals = np.asarray(samples.values, dtype=float)
    n_ch = vals.shape[1]
    if samples.sigma is not None:
        w = 1.0 / np.maximum(np.asarray(samples.sigma, dtype=float), 1e-30) ** 2
    else:
        w = np.ones_like(vals)
    n_cells = int(np.prod(shape))
    sw = np.zeros((n_cells, n_ch))
    swx = np.zeros((n_cells, n_ch))
    cnt = np.bincount(flat, minlength=n_cells)
    for c in range(n_ch):
        sw[:, c] = np.bincount(flat, weights=w[:, c], minlength=n_cells)
        swx[:, c] = np.bincount(flat, weights=w[:, c] * vals[:, c], minlength=n_cells)
    mask = cnt > 0
    mean = np.where(mask[:, None], swx / np.where(sw > 0, sw, 1.0), 0.0)
    if samples.sigma is not None:
        sig = np.where(mask[:, None], 1.0 / np.sqrt(np.where(sw > 0, sw, 1.0)), 0.0)
    else:
        sq = np.zeros((n_cells, n_ch))
        for c in range(n_ch):
            sq[:, c] = np.bincount(flat, weights=vals[:, c] ** 2, minlength=n_cells)
        n = np.maximum(cnt, 1)[:, None]
        var = np.maximum(sq / n - mean**2, 0.0) / np.maximum(n - 1, 1)
        sig = np.where(cnt[:, None] > 1, np.sqrt(var), 0.0)
    meta = dict(samples.meta)
    meta["resampling"] = (
        "inverse-variance mean of the samples in each half/diff cell (nearest node);"
        " cells without samples masked"
    )
    return TabulatedBRDF(
        values=mean.reshape(*shape, n_ch).astype(np.float32),
        axes=axes,
        parameterization="half_diff_iso",
        mask=mask.reshape(shape),
        sigma=sig.reshape(*shape, n_ch).astype(np.float32),
        counts=cnt.reshape(shape),
        channels=samples.channels,
        meta=meta,
        interpolation="nearest",
    )


def _check_iso_axes(axes: tuple[Axis, ...]) -> None:
    names = tuple(a.name for a in axes)
    if names != ("theta_h", "theta_d", "phi_d"):
        raise ParameterError(f"gridding needs axes (theta_h, theta_d, phi_d), got {names}")


def embed(th: np.ndarray, td: np.ndarray, pd: np.ndarray) -> np.ndarray:
    """The continuous embedding ``(theta_h, theta_d cos 2 phi_d, theta_d sin 2 phi_d)``, (N, 3)."""
    return np.stack([th, td * np.cos(2 * pd), td * np.sin(2 * pd)], axis=-1)


@dataclass(frozen=True)
class _Points:
    """De-duplicated embedded samples with their values and sigma (inverse-variance merged)."""

    x: np.ndarray  # (M, 3)
    f: np.ndarray  # (M, C)
    sigma: np.ndarray | None  # (M, C)


def _merge_duplicates(x: np.ndarray, f: np.ndarray, sigma: np.ndarray | None) -> _Points:
    key = np.round(x / 1e-7).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    m = first.size
    if m == x.shape[0]:
        return _Points(x, f, sigma)
    if sigma is not None:
        w = 1.0 / np.maximum(sigma, 1e-30) ** 2
    else:
        w = np.ones_like(f)
    sw = np.zeros((m, f.shape[1]))
    swx = np.zeros((m, f.shape[1]))
    np.add.at(sw, inv, w)
    np.add.at(swx, inv, w * f)
    sig = None if sigma is None else 1.0 / np.sqrt(sw)
    return _Points(x[first], swx / sw, sig)


def _scattered_points(samples: Any) -> _Points:
    th, td, pd = half_diff_iso(samples.wi, samples.wo)
    x = embed(th, td, pd)
    f = np.asarray(samples.values, dtype=float)
    sig = None if samples.sigma is None else np.asarray(samples.sigma, dtype=float)
    for axis in (2, 0):  # phi_d -> -phi_d, then theta_h -> -theta_h (see the module docstring)
        mirror = np.abs(x[:, axis]) > 1e-9  # points on the plane are their own mirror image
        flip = np.ones(3)
        flip[axis] = -1.0
        x = np.concatenate([x, x[mirror] * flip])
        f = np.concatenate([f, f[mirror]])
        if sig is not None:
            sig = np.concatenate([sig, sig[mirror]])
    return _merge_duplicates(x, f, sig)


def _affine_span(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre ``(3,)`` and orthonormal basis ``(k, 3)`` of the affine subspace the points span
    (``k`` = 0 for one point, 1 for points on a line, ...): directions along which their rms
    spread exceeds 1e-7 rad. A 1-D file (ALTA's ``COS_TH``, theta_d = 0) spans a line."""
    centre = points.mean(axis=0)
    if points.shape[0] < 2:
        return centre, np.zeros((0, 3))
    _, sv, vt = np.linalg.svd(points - centre, full_matrices=False)
    return centre, vt[sv / math.sqrt(points.shape[0]) > 1e-7]


def _weights(points: np.ndarray, query: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Barycentric interpolation over a Delaunay tetrahedralization of ``points`` (M, 3).

    Returns ``(vertex indices (Q, 4), weights (Q, 4), inside (Q,))``; outside the hull the
    nearest point gets weight 1. Points that span fewer than three dimensions are
    interpolated in the plane or on the line they span (:func:`_weights_low_dim`).
    """
    from scipy.spatial import ConvexHull, Delaunay, QhullError, cKDTree

    centre, basis = _affine_span(points)
    if basis.shape[0] < 3:
        return _weights_low_dim(points, query, centre, basis)
    q = query.shape[0]
    idx = np.zeros((q, 4), dtype=np.int64)
    wts = np.zeros((q, 4))
    inside = np.zeros(q, dtype=bool)
    tri = None
    if points.shape[0] >= 4:
        # Gonioreflectometer samples lie on regular grids: many are co-spherical, and Qhull's
        # default ("Qbb Qc Qz Q12") resolves those ties with flat slivers, whose barycentric
        # transforms and directed walks are slow (locating a dense RGL file's nodes, e.g.
        # retro-gray-tape.dat's, takes several times longer). Joggled input (QJ) breaks the ties
        # with ~1e-11 perturbations and gives a triangulation without slivers; any triangulation of
        # the samples is a valid linear interpolant, they differ only where the Delaunay one is not
        # unique.
        for options in ("QJ Qbb", None):
            try:
                tri = Delaunay(points, qhull_options=options)
                break
            except QhullError:  # numerically flat data: nearest sample everywhere
                tri = None
    if tri is not None:
        # find_simplex falls back to a brute-force search over every simplex for each point
        # outside the hull; test the hull's facet planes first so that only inside points walk.
        in_hull = np.ones(q, dtype=bool)
        try:
            eq = ConvexHull(points).equations
        except QhullError:  # every point walks instead
            eq = None
        for start in range(0, q, 8192) if eq is not None else ():
            part = query[start : start + 8192]
            in_hull[start : start + 8192] = np.all(part @ eq[:, :3].T + eq[:, 3] <= 1e-12, axis=1)
        simplex = np.full(q, -1, dtype=np.int64)
        simplex[in_hull] = tri.find_simplex(query[in_hull])
        inside = simplex >= 0
        s = simplex[inside]
        t = tri.transform[s]  # (n, 4, 3): affine map to barycentric coordinates
        b = np.einsum("nij,nj->ni", t[:, :3, :], query[inside] - t[:, 3, :])
        wts[inside, :3] = b
        wts[inside, 3] = 1.0 - b.sum(axis=1)
        idx[inside] = tri.simplices[s]
    out = ~inside
    if out.any():
        _, nearest = cKDTree(points).query(query[out])
        idx[out, 0] = nearest
        wts[out, 0] = 1.0
    return idx, np.clip(wts, 0.0, 1.0), inside


def _weights_low_dim(
    points: np.ndarray, query: np.ndarray, centre: np.ndarray, basis: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_weights` for points spanning ``k = len(basis) < 3`` dimensions: each query is
    projected onto their span and interpolated there (linearly between neighbours on a line,
    over a Delaunay triangulation in a plane; the nearest projected point beyond the ends).
    ``inside`` needs the query on the span (within 1e-7 rad) and inside the hull there; for a
    1-D file that is its own slice, the rest of the table extrapolates it."""
    from scipy.spatial import Delaunay, QhullError, cKDTree

    q = query.shape[0]
    idx = np.zeros((q, 4), dtype=np.int64)
    wts = np.zeros((q, 4))
    y = (points - centre) @ basis.T  # (M, k)
    yq = (query - centre) @ basis.T  # (Q, k)
    on_span = np.linalg.norm(query - centre - yq @ basis, axis=1) <= 1e-7
    k = basis.shape[0]
    if k == 0:
        wts[:, 0] = 1.0
        return idx, wts, on_span
    if k == 1:
        order = np.argsort(y[:, 0])
        ys = y[order, 0]
        j = np.clip(np.searchsorted(ys, yq[:, 0], side="right") - 1, 0, len(ys) - 2)
        t = np.clip((yq[:, 0] - ys[j]) / (ys[j + 1] - ys[j]), 0.0, 1.0)
        idx[:, 0], idx[:, 1] = order[j], order[j + 1]
        wts[:, 0], wts[:, 1] = 1.0 - t, t
        inside = (yq[:, 0] >= ys[0]) & (yq[:, 0] <= ys[-1])
        return idx, wts, inside & on_span
    inside = np.zeros(q, dtype=bool)
    try:
        tri = Delaunay(y, qhull_options="QJ Qbb")
    except QhullError:  # fewer than three points in the plane: nearest everywhere
        tri = None
    if tri is not None:
        simplex = tri.find_simplex(yq)
        inside = simplex >= 0
        s = simplex[inside]
        t = tri.transform[s]  # (n, 3, 2)
        b = np.einsum("nij,nj->ni", t[:, :2, :], yq[inside] - t[:, 2, :])
        wts[inside, :2] = b
        wts[inside, 2] = 1.0 - b.sum(axis=1)
        idx[inside, :3] = tri.simplices[s]
    out = ~inside
    if out.any():
        _, nearest = cKDTree(y).query(yq[out])
        idx[out, 0] = nearest
        wts[out, 0] = 1.0
    return idx, np.clip(wts, 0.0, 1.0), inside & on_span


def interpolate_samples(
    samples: Any,
    axes: tuple[Axis, ...] | None = None,
    *,
    interpolation: str = "linear",
) -> TabulatedBRDF:
    """Tabulate scattered samples through the log-linear Delaunay interpolant (module docstring).

    Parameters
    ----------
    samples : scattered measurements (any channel count), values in 1/sr.
    axes : isotropic half/diff axes (default :func:`render_axes`, 64 x 32 x 32).
    interpolation : lookup mode of the returned table.

    Returns
    -------
    TabulatedBRDF
        ``mask`` is the coverage: nodes inside the samples' convex hull (in the embedding) with
        both directions above the horizon. Nodes outside the hull hold the nearest sample's value
        (so that a renderer sees no holes; read them as extrapolation) and sigma 0; the table is
        ``filled`` (the native file keeps these values, the RGL writer uses them).
    """
    axes = axes or render_axes()
    _check_iso_axes(axes)
    if len(samples) < 1:
        raise ParameterError("no samples to interpolate")
    pts = _scattered_points(samples)
    nodes = np.meshgrid(*(a.nodes() for a in axes), indexing="ij")
    query = embed(*(n.reshape(-1) for n in nodes))
    idx, w, inside = _weights(pts.x, query)
    floor = _floor(pts.f)
    logf = np.log(np.maximum(pts.f, 0.0) + floor)
    val = np.exp(np.einsum("qk,qkc->qc", w, logf[idx])) - floor
    val = np.maximum(val, 0.0)
    sig = None
    if pts.sigma is not None:
        # dF/df_k = (F + floor) w_k / (f_k + floor)
        d = (val + floor)[:, None, :] * w[:, :, None] / (np.maximum(pts.f, 0.0) + floor)[idx]
        sig = np.sqrt(np.sum((d * pts.sigma[idx]) ** 2, axis=1))
        sig = np.where(inside[:, None], sig, 0.0)
    shape = tuple(a.size for a in axes)
    from gonio.brdf.grid import node_directions

    wi, wo = node_directions(axes, "half_diff_iso")
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    c = val.shape[1]
    meta = dict(samples.meta)
    meta["resampling"] = (
        "log-linear Delaunay interpolation in (theta_h, theta_d cos 2phi_d, theta_d sin 2phi_d);"
        " mask = inside the samples' convex hull; outside: nearest sample"
    )
    return TabulatedBRDF(
        values=val.reshape(*shape, c).astype(np.float32),
        axes=axes,
        parameterization="half_diff_iso",
        mask=(inside & above).reshape(shape),
        sigma=None if sig is None else sig.reshape(*shape, c).astype(np.float32),
        channels=samples.channels,
        meta=meta,
        interpolation=interpolation,
        filled=True,
    )


def above_horizon(table: TabulatedBRDF) -> np.ndarray:
    """``table.shape`` bool: the nodes whose directions are both above the horizon."""
    wi, wo = table.node_directions()
    return ((wi[:, 2] > 0) & (wo[:, 2] > 0)).reshape(table.shape)


def filled_interpolant(
    samples: Any, axes: tuple[Axis, ...] | None = None
) -> tuple[TabulatedBRDF, float]:
    """The documented interpolant of scattered samples as a material: every node with both
    directions above the horizon valid.

    :func:`interpolate_samples` on ``axes`` (default :func:`render_axes`), its mask widened to
    every above-horizon node (outside the samples' convex hull the nearest sample's value,
    i.e. extrapolation) and no sigma. This is how :class:`gonio.brdf.measured.MeasuredSamples`
    answers ``f``, ``pdf`` and ``sample``.

    Returns
    -------
    (table, covered) : the table, and the fraction of its above-horizon nodes that lie inside
        the samples' hull (the rest are extrapolated).
    """
    t = interpolate_samples(samples, axes)
    above = above_horizon(t)
    covered = float(np.asarray(t.mask).sum()) / max(int(above.sum()), 1)
    return t.replace(mask=above, sigma=None), covered


def _floor(f: np.ndarray) -> np.ndarray:
    """Per-channel floor of the log interpolation: 1e-3 of the median positive value."""
    out = np.empty(f.shape[1])
    for c in range(f.shape[1]):
        pos = f[:, c][f[:, c] > 0]
        out[c] = 1e-3 * float(np.median(pos)) if pos.size else 1e-6
    return np.maximum(out, 1e-12)
