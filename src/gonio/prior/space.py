"""The prior's mapped space and grid: where a material is a vector and how samples see it.

Mapped space
------------
A BRDF value ``f`` (sr⁻¹, no cosine) at a direction pair is mapped to

    m = log(f · cos θi · cos θo + ε),   ε = :data:`EPSILON` = 1e-3 sr⁻¹,

as in Nielsen, Jensen & Ramamoorthi (2015): the cosine-weighted value is what an image sees,
the logarithm turns the orders of magnitude between a diffuse floor and a specular peak into
comparable numbers, and ε keeps dark and grazing cells finite (there ``m`` tends to
``log ε``). The inverse is ``f = (exp(m) - ε) / (cos θi · cos θo)``, clipped at 0. A negative
measured ``f`` (noise around 0) is clipped at 0 before mapping.

Grid
----
The isotropic MERL grid (θh, θd, φd) subsampled (:func:`prior_axes`): all 90 θh nodes (MERL's
square-root warp, dense near the specular peak), every second θd node (45, 2° apart) and, since
an isotropic reciprocal BRDF is symmetric under ``φd -> π - φd``, every second φd node of
``[0, π/2)`` (45, 2° apart). Nodes sit at MERL's cell centres (0.5°, 2.5°, ... for θd and φd),
so a MERL file or a neural BRDF tabulated on MERL's grid is read exactly at its own nodes. A
cell is valid when both directions of its node are strictly above the horizon (MERL's invalid
cells, θi or θo beyond 90°, are masked): 182,250 cells, of which :func:`valid_mask` keeps those.

Samples
-------
A sample at any ``(wi, wo)`` sees the grid through multilinear interpolation in the warped
index coordinates of the valid corners (renormalized), as :class:`~gonio.brdf.tabulated.
TabulatedBRDF` interpolates a table: :func:`interpolation_weights`.
"""

from __future__ import annotations

import math

import numpy as np

from gonio.brdf.grid import Axis, node_directions

#: ε of the mapped space, sr⁻¹.
EPSILON = 1e-3
#: Name of the mapped space recorded in prior files.
SPACE = "log_cos"


def prior_axes(n_theta_h: int = 90, n_theta_d: int = 45, n_phi_d: int = 45) -> tuple[Axis, ...]:
    """The prior's (θh, θd, φd) axes; the defaults subsample MERL's centre nodes (module
    docstring). θd and φd of size ``n`` put node ``i`` at ``(i + 0.25) · (π/2) / n``: with
    ``n = 45`` that is MERL's centre node ``2 i``."""
    half = math.pi / 2
    return (
        Axis("theta_h", n_theta_h, 0.0, half, "sqrt", False, 0.5),
        Axis("theta_d", n_theta_d, 0.0, half, "linear", False, 0.25 if n_theta_d == 45 else 0.5),
        Axis("phi_d", n_phi_d, 0.0, half, "linear", False, 0.25 if n_phi_d == 45 else 0.5),
    )


def cos_product(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """``cos θi · cos θo`` of direction pairs ``(..., 3)``; 0 at or below the horizon."""
    return np.maximum(wi[..., 2], 0.0) * np.maximum(wo[..., 2], 0.0)


def to_mapped(f: np.ndarray, cc: np.ndarray, epsilon: float = EPSILON) -> np.ndarray:
    """``log(max(f, 0) · cc + ε)``; ``f`` ``(..., C)`` in sr⁻¹, ``cc`` ``(...)``."""
    return np.log(np.maximum(f, 0.0) * cc[..., None] + epsilon)


def from_mapped(m: np.ndarray, cc: np.ndarray, epsilon: float = EPSILON) -> np.ndarray:
    """Inverse of :func:`to_mapped`: ``max(exp(m) - ε, 0) / cc`` in sr⁻¹ (``cc > 0``)."""
    return np.maximum(np.exp(m) - epsilon, 0.0) / cc[..., None]


def sigma_to_mapped(
    f: np.ndarray, sigma: np.ndarray, cc: np.ndarray, epsilon: float = EPSILON
) -> np.ndarray:
    """σ of a measured ``f`` carried into the mapped space to first order (delta method):
    ``σ_m = cc σ / (max(f, 0) cc + ε)``."""
    c = cc[..., None]
    return c * sigma / (np.maximum(f, 0.0) * c + epsilon)


def sigma_from_mapped(m: np.ndarray, sigma_m: np.ndarray, cc: np.ndarray) -> np.ndarray:
    """σ of ``f = (exp(m) - ε)/cc`` from σ of ``m`` to first order: ``exp(m) σ_m / cc``."""
    return np.exp(m) * sigma_m / cc[..., None]


def grid_directions(axes: tuple[Axis, ...]) -> tuple[np.ndarray, np.ndarray]:
    """``(wi, wo)``, each ``(n_cells, 3)``, of every node in C order."""
    return node_directions(axes, "half_diff_iso")


def valid_mask(axes: tuple[Axis, ...]) -> np.ndarray:
    """``(n_θh, n_θd, n_φd)`` bool: both node directions strictly above the horizon."""
    wi, wo = grid_directions(axes)
    ok = (wi[:, 2] > 1e-9) & (wo[:, 2] > 1e-9)
    return ok.reshape(tuple(a.size for a in axes))


def half_diff_angles(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, ...]:
    """``(θh, θd, φd)`` (radians) of direction pairs ``(n, 3)`` (Rusinkiewicz 1998), φd folded
    into ``[0, π/2]`` by reciprocity and the isotropic mirror symmetry."""
    h = wi + wo
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    th = np.arccos(np.clip(h[:, 2], -1.0, 1.0))
    ph = np.arctan2(h[:, 1], h[:, 0])
    # wi in the frame whose pole is h: rotate by -φh about z, then by -θh about y
    c, s = np.cos(-ph), np.sin(-ph)
    x = c * wi[:, 0] - s * wi[:, 1]
    y = s * wi[:, 0] + c * wi[:, 1]
    z = wi[:, 2]
    ct, st = np.cos(-th), np.sin(-th)
    dx = ct * x + st * z
    dz = -st * x + ct * z
    td = np.arccos(np.clip(dz, -1.0, 1.0))
    pd = np.mod(np.arctan2(y, dx), math.pi)
    pd = np.minimum(pd, math.pi - pd)
    return th, td, pd


def _axis_index(ax: Axis, angle: np.ndarray) -> np.ndarray:
    x = (angle - ax.lo) / (ax.hi - ax.lo)
    if ax.warp == "sqrt":
        x = np.sqrt(np.maximum(x, 0.0))
    return np.clip(x * ax.size - ax.node_offset, 0.0, ax.size - 1.0)


def interpolation_weights(
    axes: tuple[Axis, ...], mask: np.ndarray, wi: np.ndarray, wo: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The grid cells a sample sees and their weights.

    Parameters
    ----------
    axes, mask : the prior's grid and validity mask.
    wi, wo : ``(n, 3)`` unit vectors, local frame.

    Returns
    -------
    cells : ``(n, 8)`` int64 flat C-order cell index of each corner.
    weights : ``(n, 8)`` float64 multilinear weights over the valid corners, summing to 1 per
        row, or all 0 where no corner is valid or a direction is at or below the horizon.
    """
    th, td, pd = half_diff_angles(wi, wo)
    sizes = [a.size for a in axes]
    lo_hi = []
    for ax, ang in zip(axes, (th, td, pd), strict=True):
        t = _axis_index(ax, ang)
        i0 = np.minimum(np.floor(t).astype(np.int64), ax.size - 1)
        i1 = np.minimum(i0 + 1, ax.size - 1)
        lo_hi.append((i0, i1, t - i0))
    n = wi.shape[0]
    cells = np.zeros((n, 8), np.int64)
    weights = np.ones((n, 8))
    for k in range(8):
        idx = []
        for a, (i0, i1, fr) in enumerate(lo_hi):
            bit = (k >> (2 - a)) & 1
            idx.append(i1 if bit else i0)
            weights[:, k] *= fr if bit else 1.0 - fr
        cells[:, k] = np.ravel_multi_index(idx, sizes)
    weights *= mask.reshape(-1)[cells]
    total = weights.sum(axis=1, keepdims=True)
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0) & (total[:, 0] > 1e-12)
    weights = np.where(above[:, None], weights / np.where(total > 0, total, 1.0), 0.0)
    return cells, weights
