"""Scattered samples onto a half/diff grid: the log-linear Delaunay interpolant and binning."""

import math

import numpy as np
import pytest

from gonio.brdf import frames, gridding, models
from gonio.brdf.measured import MeasuredSamples
from gonio.errors import ParameterError


def _random_pairs(n, seed):
    rng = np.random.default_rng(seed)

    def hemi(k):
        u = rng.random((k, 2))
        r = np.sqrt(u[:, 0])
        p = 2 * np.pi * u[:, 1]
        return np.stack([r * np.cos(p), r * np.sin(p), np.sqrt(1 - u[:, 0])], -1)

    return hemi(n), hemi(n)


def _samples(model, n, seed=0, rel_sigma=None):
    wi, wo = _random_pairs(n, seed)
    f = np.asarray(model.f(wi, wo))
    sig = None if rel_sigma is None else rel_sigma * f
    return MeasuredSamples(wi, wo, f, sig)


PAINT = models.Lambert(albedo=[0.5, 0.3, 0.1]) + models.TorranceSparrow(
    alpha=0.3, fresnel=models.Schlick(f0=0.05)
)


def test_interpolant_passes_through_its_samples():
    s = _samples(PAINT, 200, seed=1)
    th, td, pd = gridding.half_diff_iso(s.wi, s.wo)
    # A grid whose nodes are exactly three of the samples' coordinates is not practical; evaluate
    # the interpolant's weights directly at the samples instead.
    pts = gridding._scattered_points(s)
    idx, w, inside = gridding._weights(pts.x, gridding.embed(th, td, pd))
    logf = np.log(pts.f)
    got = np.exp(np.einsum("qk,qkc->qc", w, logf[idx]))
    np.testing.assert_allclose(got, s.values, rtol=1e-6)
    assert inside.all()


def test_interpolant_error_shrinks_with_density():
    wi, wo = _random_pairs(2000, seed=9)
    truth = np.asarray(PAINT.f(wi, wo))
    errs = []
    for n in (200, 2000):
        t = gridding.interpolate_samples(
            _samples(PAINT, n, seed=2), gridding.render_axes(32, 16, 16)
        )
        t = t.replace(mask=None)
        got = np.asarray(t.f(wi, wo))
        errs.append(float(np.median(np.abs(got - truth) / truth)))
    assert errs[1] < errs[0]
    assert errs[1] < 0.05  # dense random samples of a smooth paint: a few percent at most


def test_isotropic_mirror_symmetry_fills_phi_d():
    # Samples only at phi_d in [0, pi/2): the mirror images cover (pi/2, pi) too.
    th = np.radians(np.linspace(1, 60, 12))
    td = np.radians(np.linspace(1, 70, 12))
    pd = np.radians(np.linspace(0, 80, 9))
    T, D, P = (a.reshape(-1) for a in np.meshgrid(th, td, pd, indexing="ij"))
    wi, wo = frames.half_diff_to_directions(T, 0 * T, D, P)
    wi, wo = np.asarray(wi), np.asarray(wo)
    ok = (wi[:, 2] > 0.05) & (wo[:, 2] > 0.05)
    m = models.Lambert(0.4)
    s = MeasuredSamples(wi[ok], wo[ok], np.asarray(m.f(wi[ok], wo[ok])))
    t = gridding.interpolate_samples(s, gridding.render_axes(12, 12, 16))
    pdn = t.axes[2].nodes()
    # Mask symmetric about phi_d = pi/2 (node i <-> node n - i).
    n = pdn.size
    np.testing.assert_array_equal(t.mask[:, :, 1:], t.mask[:, :, 1:][:, :, ::-1])
    # A Lambertian material interpolates to its constant everywhere.
    np.testing.assert_allclose(np.asarray(t.values)[t.mask], 0.4 / math.pi, rtol=1e-5)
    assert n == 16


def test_sigma_is_propagated_and_zero_outside_the_hull():
    s = _samples(PAINT, 400, seed=3, rel_sigma=0.02)
    t = gridding.interpolate_samples(s, gridding.render_axes(24, 16, 8))
    assert t.sigma is not None
    rel = np.asarray(t.sigma)[t.mask] / np.asarray(t.values)[t.mask]
    # A weighted mean of values with 2 % errors: at most 2 %, at least 2 %/sqrt(4).
    assert np.all(rel <= 0.02 + 1e-6) and np.all(rel >= 0.01 - 1e-6)
    assert np.all(np.asarray(t.sigma)[~t.mask] == 0)
    assert 0.2 < t.mask.mean() < 1.0


def test_binning_masks_empty_cells_and_keeps_counts():
    s = _samples(PAINT, 200, seed=4, rel_sigma=0.01)
    g = gridding.grid_samples(s, gridding.default_grid(8, 8, 6))
    assert g.counts.sum() == 200
    np.testing.assert_array_equal(g.mask, g.counts > 0)
    assert g.shape == (8, 8, 6)


def test_wrong_axes_are_refused():
    s = _samples(PAINT, 20)
    from gonio.brdf.tabulated import default_axes

    with pytest.raises(ParameterError):
        gridding.interpolate_samples(s, default_axes("half_diff_aniso", 4, 4, 4, 4))


def _half_diff_samples(model, th, td, pd):
    from gonio.brdf.frames import half_diff_to_directions

    wi, wo = half_diff_to_directions(th, np.zeros_like(th), td, pd)
    return MeasuredSamples(wi, wo, np.asarray(model.f(wi, wo)))


def test_samples_on_a_line_are_interpolated_along_it():
    # a 1-D file (ALTA's COS_TH): theta_d = 0 everywhere, theta_h from 0 to 80 degrees; Qhull
    # cannot tetrahedralize it (it raised on such data), so the interpolant works on the line
    th = np.radians(np.linspace(0.0, 80.0, 41))
    s = _half_diff_samples(PAINT, th, np.zeros_like(th), np.zeros_like(th))
    axes = gridding.render_axes(32, 16, 8)
    t = gridding.interpolate_samples(s, axes)
    th_n, td_n = axes[0].nodes(), axes[1].nodes()
    assert td_n[0] == 0.0 and th_n[-1] > th[-1]
    truth = np.asarray(s.values)
    # along the line: the log-linear interpolant of the samples in theta_h (inside the samples'
    # range; beyond it, the last sample)
    want = np.exp(np.stack([np.interp(th_n, th, np.log(truth[:, c])) for c in range(3)], -1))
    vals = np.asarray(t.values)
    np.testing.assert_allclose(vals[:, 0, 0], want, rtol=1e-5)
    # off the line every node takes the value at its projection (same theta_h), not covered
    np.testing.assert_allclose(vals[:, 5, 3], want, rtol=1e-5)
    mask = np.asarray(t.mask)
    assert mask[th_n <= th[-1], 0].all() and not mask[:, 1:].any() and not mask[th_n > th[-1]].any()


def test_samples_in_a_plane_are_interpolated_in_it():
    # an in-plane measurement (phi_d = 0 only, one plane of the embedding) of a smooth paint
    g = np.radians(np.linspace(0.0, 40.0, 9))  # theta_h + theta_d <= 80: both above the horizon
    th, td = (x.ravel() for x in np.meshgrid(g, g, indexing="ij"))
    s = _half_diff_samples(PAINT, th, td, np.zeros_like(th))
    pts = gridding._scattered_points(s)
    _, basis = gridding._affine_span(pts.x)
    assert basis.shape[0] == 2
    rng = np.random.default_rng(3)
    q_th, q_td = np.radians(rng.uniform(0, 40, 200)), np.radians(rng.uniform(0, 40, 200))
    q = gridding.embed(q_th, q_td, np.zeros(200))
    idx, w, inside = gridding._weights(pts.x, q)
    assert inside.all()
    truth = np.asarray(_half_diff_samples(PAINT, q_th, q_td, np.zeros(200)).values)
    got = np.exp(np.einsum("qk,qkc->qc", w, np.log(pts.f)[idx]))
    # a 5-degree grid of a smooth paint: log-linear in the plane within 3 %
    np.testing.assert_allclose(got, truth, rtol=0.03)
    # off the plane (phi_d = 45 degrees): the plane's value, not covered
    off = gridding.embed(q_th, q_td, np.full(200, np.pi / 4))
    idx2, w2, inside2 = gridding._weights(pts.x, off)
    assert not inside2[q_td > 1e-3].any()
    # embedded at (theta_h, 0, theta_d); its projection onto the samples' plane (third
    # coordinate 0) is (theta_h, 0, 0), whose interpolated value it takes
    idx3, w3, _ = gridding._weights(pts.x, off * np.array([1.0, 1.0, 0.0]))
    got2 = np.exp(np.einsum("qk,qkc->qc", w2, np.log(pts.f)[idx2]))
    got3 = np.exp(np.einsum("qk,qkc->qc", w3, np.log(pts.f)[idx3]))
    np.testing.assert_allclose(got2, got3, rtol=1e-9)
