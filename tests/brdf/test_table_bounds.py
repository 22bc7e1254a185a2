"""The interval bounds behind exact rejection sampling of tables
(gonio.brdf.sampling.table_rejection): half/difference angle ranges over boxes of directions, and
rectangle maxima."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.brdf import frames
from gonio.brdf.sampling.table_rejection import half_diff_ranges as _half_diff_ranges
from gonio.brdf.sampling.table_rejection import rect_max

HALF_PI = math.pi / 2


def _interval(a: float, b: float) -> tuple[float, float]:
    return (min(a, b), max(a, b))


@settings(max_examples=200, deadline=None)
@given(
    ti=st.tuples(st.floats(0, HALF_PI), st.floats(0, 0.2)),
    to=st.tuples(st.floats(0, HALF_PI), st.floats(0, 0.2)),
    dphi=st.tuples(st.floats(-2 * math.pi, 2 * math.pi), st.floats(0, 2 * math.pi)),
    seed=st.integers(0, 2**32 - 1),
)
def test_half_diff_ranges_contain_every_direction_pair(ti, to, dphi, seed):
    """Every (wi, wo) pair drawn inside a box (and on its corners) has its Rusinkiewicz
    theta_h and theta_d inside the computed ranges."""
    ti0, ti1 = ti[0], min(ti[0] + ti[1], HALF_PI)
    to0, to1 = to[0], min(to[0] + to[1], HALF_PI)
    d0, d1 = dphi[0], dphi[0] + dphi[1]
    (h_lo, h_hi), (d_lo, d_hi) = _half_diff_ranges(
        (np.array([ti0]), np.array([ti1])), (np.array([d0]), np.array([d1])), (to0, to1)
    )
    rng = np.random.default_rng(seed)
    n = 400
    th_i = np.concatenate([[ti0, ti1, ti0, ti1], rng.uniform(ti0, ti1, n)])
    th_o = np.concatenate([[to0, to1, to1, to0], rng.uniform(to0, to1, n)])
    ph = np.concatenate([[d0, d1, d1, d0], rng.uniform(d0, d1, n)])
    wi = np.asarray(frames.spherical_to_direction(th_i, ph))
    wo = np.asarray(frames.spherical_to_direction(th_o, np.zeros_like(th_o)))
    th, _, td, _ = (np.asarray(a) for a in frames.half_diff(wi, wo))
    tol = 1e-7  # radians: float64 rounding of both computations
    assert np.all(th >= h_lo[0] - tol) and np.all(th <= h_hi[0] + tol)
    assert np.all(td >= d_lo[0] - tol) and np.all(td <= d_hi[0] + tol)


def test_half_diff_ranges_are_tight_at_grazing_angles():
    """Near the mirror direction at grazing angles the half vector stays far from the normal
    (the term-by-term interval of cos theta_h = (cos i + cos o) / |wi + wo| says 0 there)."""
    ti = (np.radians([85.78125]), np.radians([87.1875]))
    dphi = (np.radians([174.375]), np.radians([177.1875]))
    (h_lo, _), _ = _half_diff_ranges(ti, dphi, (math.radians(87.1875), HALF_PI))
    # the true minimum, by brute force over the box
    a, b, c = np.meshgrid(
        np.linspace(*np.degrees(np.concatenate(ti)), 41),
        np.linspace(*np.degrees(np.concatenate(dphi)), 41),
        np.linspace(87.1875, 90.0, 41),
    )
    wi = np.asarray(frames.spherical_to_direction(np.radians(a), np.radians(b)))
    wo = np.asarray(frames.spherical_to_direction(np.radians(c), np.zeros_like(c)))
    true_min = float(np.min(np.asarray(frames.half_diff(wi, wo)[0])))
    assert math.degrees(true_min) > 20
    assert h_lo[0] > 0.8 * true_min


@settings(max_examples=100, deadline=None)
@given(
    shape=st.tuples(st.integers(1, 40), st.integers(1, 40)),
    seed=st.integers(0, 2**32 - 1),
)
def test_range_max_matches_brute_force(shape, seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=shape)
    n = 300
    r0 = rng.integers(0, shape[0], n)
    r1 = r0 + 1 + rng.integers(0, shape[0] - r0)
    c0 = rng.integers(0, shape[1], n)
    c1 = c0 + 1 + rng.integers(0, shape[1] - c0)
    got = rect_max(a, r0, r1, c0, c1)
    want = [a[i:j, k:m].max() for i, j, k, m in zip(r0, r1, c0, c1, strict=True)]
    np.testing.assert_array_equal(got, want)
