"""Interval bounds behind exact rejection sampling of tables (:mod:`gonio.brdf.table_rejection`):
ranges of the Rusinkiewicz half/difference angles over boxes of direction pairs, the
interpolation cells of an axis, and maxima over index rectangles.

Every function here works on the host (NumPy, float64) and is rigorous: a returned range contains
every value taken inside its box (up to float64 rounding, which callers cover with small margins).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

TWO_PI = 2 * math.pi


class RangeMax2D:
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


def axis_cells(ax: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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


def half_diff_ranges(
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
    num_lo = sq_lo + 2 * ss_lo * (1 + cp_lo)
    num_hi = sq_hi + 2 * ss_hi * (1 + cp_hi)
    den_lo = np.cos(ti1) + math.cos(t1)  # cos theta_i + cos theta_o >= 0
    den_hi = np.cos(ti0) + math.cos(t0)
    th = (
        np.arctan2(np.sqrt(np.maximum(num_lo, 0.0)), den_hi),
        np.arctan2(np.sqrt(np.maximum(num_hi, 0.0)), np.maximum(den_lo, 0.0)),
    )
    return th, td


def cos_range(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range of cos over each interval [lo, hi] (hi - lo <= 2 pi)."""
    c_lo = np.minimum(np.cos(lo), np.cos(hi))
    c_hi = np.maximum(np.cos(lo), np.cos(hi))
    k_max = np.ceil(lo / TWO_PI)  # a multiple of 2 pi inside -> max 1
    has_max = k_max * TWO_PI <= hi
    k_min = np.ceil((lo - math.pi) / TWO_PI)
    has_min = k_min * TWO_PI + math.pi <= hi
    return np.where(has_min, -1.0, c_lo), np.where(has_max, 1.0, c_hi)


__all__ = ["RangeMax2D", "axis_cells", "cos_range", "half_diff_ranges"]
