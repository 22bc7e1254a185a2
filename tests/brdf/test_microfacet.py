"""Microfacet distributions, Smith and V-cavity shadowing, and half-vector samplers."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special

from gonio.brdf import frames
from gonio.brdf.chi2 import chi2_test
from gonio.brdf.models import microfacet as mf
from gonio.errors import ParameterError
from tests.brdf import model_checks as mc

DISTS = mf.DISTRIBUTIONS
# Chi-square tests in this file (Sidak correction): 3 D samplers x 2 alphas + 3 x 2 visible.
N_CHI2 = 12


def gl_theta(n_panels=2000, order=8, lo=0.0, hi=np.pi / 2, warp=3.0):
    """Composite Gauss-Legendre nodes/weights on [lo, hi], panels denser near ``lo``."""
    x, w = np.polynomial.legendre.leggauss(order)
    edges = lo + (hi - lo) * np.linspace(0, 1, n_panels + 1) ** warp
    a, b = edges[:-1, None], edges[1:, None]
    nodes = (a + b) / 2 + (b - a) / 2 * x
    weights = (b - a) / 2 * w
    return nodes.ravel(), weights.ravel()


def textbook_d(theta, alpha, dist):
    """The distributions as usually printed (tan and cos^4), evaluated in plain NumPy."""
    c = np.cos(theta)
    t2 = np.tan(theta) ** 2
    if dist == "beckmann":
        return np.exp(-t2 / alpha**2) / (np.pi * alpha**2 * c**4)
    if dist == "ggx":
        return alpha**2 / (np.pi * c**4 * (alpha**2 + t2) ** 2)
    e = 2 / alpha**2 - 2
    return (e + 2) / (2 * np.pi) * c**e


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("alpha", [0.02, 0.1, 0.5, 1.0])
def test_distribution_is_normalized(dist, alpha):
    th, w = gl_theta()
    h = np.asarray(frames.spherical_to_direction(th, 0.0))
    d = np.asarray(mf.ndf(jnp.asarray(h), alpha, dist))
    integral = 2 * np.pi * np.sum(w * d * np.cos(th) * np.sin(th))
    assert abs(integral - 1) < 1e-6, f"{dist} alpha={alpha}: int D cos = {integral}"


@pytest.mark.parametrize("dist", DISTS)
def test_distribution_values_and_isotropy(dist):
    rng = np.random.default_rng(5)
    th = rng.uniform(0, 1.4, 500)
    ph = rng.uniform(0, 2 * np.pi, 500)
    h = np.asarray(frames.spherical_to_direction(th, ph))
    for alpha in (0.05, 0.3, 1.0):
        np.testing.assert_allclose(
            np.asarray(mf.ndf(h, alpha, dist)), textbook_d(th, alpha, dist), rtol=1e-9, atol=1e-300
        )
    assert np.all(np.asarray(mf.ndf(h * [1, 1, -1], 0.3, dist)) == 0)


def test_unknown_names_raise():
    with pytest.raises(ParameterError, match="distribution"):
        mf.ndf(jnp.ones((1, 3)), 0.1, "phong")
    with pytest.raises(ParameterError, match="shadowing"):
        mf.check_shadowing("walter")


@pytest.mark.parametrize("dist", DISTS)
def test_g1_limits(dist):
    for alpha in (1e-4, 0.1, 1.0):
        assert float(mf.smith_g1(jnp.array([0.0, 0.0, 1.0]), alpha, dist)) == 1.0
        assert float(mf.smith_g1(jnp.array([1.0, 0.0, 0.0]), alpha, dist)) == 0.0
    th = np.linspace(0, np.pi / 2 * 0.999, 50)
    g = np.asarray(mf.smith_g1(frames.spherical_to_direction(th, 0.4), 0.3, dist))
    assert np.all(np.diff(g) <= 1e-15), "G1 must decrease toward grazing"


def test_smith_lambda_closed_forms():
    th = np.linspace(0.01, np.pi / 2 - 0.01, 80)
    w = np.asarray(frames.spherical_to_direction(th, 1.0))
    for alpha in (0.02, 0.3, 1.0):
        a = 1 / (alpha * np.tan(th))
        beck = (special.erf(a) - 1) / 2 + np.exp(-(a**2)) / (2 * a * np.sqrt(np.pi))
        ggx = (np.sqrt(1 + alpha**2 * np.tan(th) ** 2) - 1) / 2
        for dist, expect in (("beckmann", beck), ("blinn", beck), ("ggx", ggx)):
            got = np.asarray(mf.smith_lambda(w, alpha, dist))
            np.testing.assert_allclose(got, expect, rtol=1e-9, atol=1e-15, err_msg=dist)


@pytest.mark.parametrize("dist", ["beckmann", "ggx"])
@pytest.mark.parametrize("alpha", [0.1, 0.5, 1.0])
def test_smith_projected_area_identity(dist, alpha):
    """Exact Smith: int G1(wo) max(0, wo.h) D(h) dh = cos(theta_o) for every wo."""
    th, wt = gl_theta(n_panels=600, order=8, warp=2.0)
    ph = (np.arange(512) + 0.5) / 512 * 2 * np.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    h = np.asarray(frames.spherical_to_direction(T, P))
    d = np.asarray(mf.ndf(h, alpha, dist))
    dw = (wt * np.sin(th))[:, None] * (2 * np.pi / 512)
    for theta_o in np.radians([0.0, 45.0, 80.0]):
        wo = np.asarray(frames.spherical_to_direction(theta_o, 0.0))
        proj = np.sum(np.maximum(h @ wo, 0.0) * d * dw)
        g1 = float(mf.smith_g1(jnp.asarray(wo), alpha, dist))
        assert abs(g1 * proj - np.cos(theta_o)) < 2e-5, (dist, alpha, theta_o, g1 * proj)


def test_vcavity_term():
    wi, wo = mc.random_upper(3000, 1), mc.random_upper(3000, 2)
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    nh, oh = h[:, 2], np.sum(wo * h, -1)
    expect = np.minimum(1, np.minimum(2 * nh * wo[:, 2] / oh, 2 * nh * wi[:, 2] / oh))
    got = np.asarray(mf.shadowing_g(wi, wo, 0.3, "beckmann", "vcavity"))
    np.testing.assert_allclose(got, expect, rtol=1e-10)
    g_swapped = np.asarray(mf.shadowing_g(wo, wi, 0.3, "beckmann", "vcavity"))
    np.testing.assert_allclose(got, g_swapped, rtol=1e-12)


@pytest.mark.parametrize("dist", DISTS)
def test_smith_g2_is_height_correlated(dist):
    wi, wo = mc.random_upper(500, 3), mc.random_upper(500, 4)
    g = np.asarray(mf.shadowing_g(wi, wo, 0.4, dist, "smith"))
    li = np.asarray(mf.smith_lambda(wi, 0.4, dist))
    lo = np.asarray(mf.smith_lambda(wo, 0.4, dist))
    np.testing.assert_allclose(g, 1 / (1 + li + lo), rtol=1e-9)
    assert np.all((g > 0) & (g <= 1 + 1e-12))


# -- samplers -----------------------------------------------------------------------------------
def _ndf_sampler(alpha, dist):
    def sample(u):
        h = mf.sample_ndf(jnp.asarray(u), alpha, dist)
        return np.asarray(h), np.asarray(mf.ndf_pdf(h, alpha, dist))

    def pdf(h):
        return np.asarray(mf.ndf_pdf(jnp.asarray(h), alpha, dist))

    return sample, pdf


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("alpha", [0.02, 0.5])
def test_chi2_distribution_sampling(dist, alpha):
    sample, pdf = _ndf_sampler(alpha, dist)
    cap = {"axis": np.array([0.0, 0.0, 1.0]), "theta_max": 10 * alpha} if alpha < 0.1 else {}
    r = chi2_test(sample, pdf, n_tests=N_CHI2, res_theta=60, res_phi=120, **cap)
    assert r.passed, f"{dist} alpha={alpha}: {r.message}"
    assert abs(r.pdf_integral - 1) < 1e-3


@pytest.mark.parametrize("theta_o", [0.0, 60.0, 85.0])
@pytest.mark.parametrize("alpha", [0.02, 0.5])
def test_chi2_visible_ggx(theta_o, alpha):
    wo = jnp.asarray(frames.spherical_to_direction(np.radians(theta_o), 0.3))

    def sample(u):
        h = mf.sample_visible(jnp.broadcast_to(wo, (len(u), 3)), jnp.asarray(u), alpha, "ggx")
        return np.asarray(h), np.asarray(mf.visible_pdf(wo, h, alpha, "ggx"))

    def pdf(h):
        return np.asarray(mf.visible_pdf(wo, jnp.asarray(h), alpha, "ggx"))

    cap = {"axis": np.array([0.0, 0.0, 1.0]), "theta_max": 10 * alpha} if alpha < 0.1 else {}
    r = chi2_test(sample, pdf, n_tests=N_CHI2, res_theta=60, res_phi=120, **cap)
    assert r.passed, f"theta_o={theta_o} alpha={alpha}: {r.message}"
    assert abs(r.pdf_integral - 1) < 1e-3  # visible normals integrate to exactly 1


def test_visible_sampling_only_where_exact():
    with pytest.raises(ParameterError, match="visible"):
        mf.sample_visible(jnp.array([0.0, 0.0, 1.0]), jnp.array([0.5, 0.5]), 0.1, "blinn")


# -- stress --------------------------------------------------------------------------------------
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("dist", DISTS)
def test_extreme_roughness_is_finite(dist, dtype):
    d = mc.stress_directions().astype(dtype)
    wi = np.repeat(d, len(d), axis=0)
    wo = np.tile(d, (len(d), 1))
    ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    wi, wo = jnp.asarray(wi[ok]), jnp.asarray(wo[ok])
    h = frames.normalize(wi + wo)
    u = jnp.asarray(np.array([[0, 0], [mc.EPS1, mc.EPS1], [0.5, 0.5], [1e-12, mc.EPS1]], dtype))
    for alpha in (1e-4, 1e-3, 0.5, 1.0):

        def total(a, alpha=alpha):
            a = jnp.asarray(a, dtype)
            out = jnp.sum(mf.ndf(h, a, dist)) + jnp.sum(mf.ndf(d, a, dist))
            out += jnp.sum(mf.smith_mu(wi, a, dist)) + jnp.sum(mf.smith_g1(d, a, dist))
            for sh in mf.SHADOWINGS:
                out += jnp.sum(mf.visibility(wi, wo, h, a, dist, sh))
            hs = mf.sample_ndf(u, a, dist)
            out += jnp.sum(hs) + jnp.sum(mf.ndf_pdf(hs, a, dist))
            if dist in mf.VISIBLE_SAMPLING:
                wov = jnp.repeat(d[d[:, 2] > 0], len(u), axis=0)
                uu = jnp.tile(u, (int((d[:, 2] > 0).sum()), 1))
                hv = mf.sample_visible(wov, uu, a, dist)
                out += jnp.sum(hv) + jnp.sum(mf.visible_pdf(wov, hv, a, dist))
            return out

        val, grad = jax.value_and_grad(total)(np.asarray(alpha, dtype))
        assert np.isfinite(val), f"{dist} alpha={alpha} {dtype}: {val}"
        assert np.isfinite(grad), f"{dist} alpha={alpha} {dtype}: gradient {grad}"
    # The peak value at alpha = 1e-4 is 1/(pi alpha^2) for every distribution.
    peak = float(mf.ndf(jnp.asarray([0, 0, 1], dtype), dtype(1e-4), dist))
    np.testing.assert_allclose(peak, 1 / (np.pi * 1e-8), rtol=1e-5)
