import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import erfc as sp_erfc
from scipy.special import gammaln

from gonio.brdf import frames, models
from gonio.brdf.models.fresnel import Conductor, Dielectric
from gonio.brdf.models.htsg import HTSG, effective_roughness, kirchhoff_sum
from gonio.errors import ParameterError
from tests.brdf import model_checks as mc
from tests.brdf import zoo_checks as zc

N_CHI2 = 5

ALU = Conductor(eta=[1.2, 0.96, 0.62], k=[7.3, 6.7, 5.4])


def direct_sum(g, c, n=30000):
    m = np.arange(1, n + 1.0)
    return np.sum(np.exp(m * np.log(g) - g - gammaln(m + 1) - np.log(m) - c / m))


@pytest.mark.parametrize(
    ("g", "c"),
    [
        (1e-6, 0.0),
        (0.01, 0.0),
        (0.5, 3.0),
        (5.0, 0.1),
        (30.0, 1.0),
        (50.0, 200.0),
        (1000.0, 1e4),
        (3000.0, 10.0),
    ],
)
def test_series_against_direct_sum(g, c):
    ref = direct_sum(g, c)
    v64 = float(kirchhoff_sum(jnp.asarray(g), jnp.asarray(c), 32))
    v32 = float(kirchhoff_sum(jnp.asarray(g, jnp.float32), jnp.asarray(c, jnp.float32), 32))
    assert abs(v64 / ref - 1) < 1e-7
    assert abs(v32 / ref - 1) < 2e-5


def test_series_error_bound_holds_and_is_tight():
    wi, wo = mc.random_upper(120, 21), mc.random_upper(120, 22)
    wi, wo = jnp.asarray(wi), jnp.asarray(wo)
    for s0, tau, terms in ((0.03, 2.0, 12), (0.05, 1.0, 10)):
        few = HTSG(sigma0=s0, tau=tau, fresnel=ALU, terms=terms)
        ref = HTSG(sigma0=s0, tau=tau, fresnel=ALU, terms=256)
        dist = jax.jit(lambda m, a, b: m.distribution(a, b))
        d, d_ref = np.asarray(dist(few, wi, wo)), np.asarray(dist(ref, wi, wo))
        bound = np.asarray(few.series_error_bound(wi, wo))
        ok = np.isfinite(bound)  # stride-1 windows
        assert ok.sum() >= 40
        err = np.abs(d - d_ref)[ok]
        # the rigorous truncation bound, plus the float rounding of the terms themselves
        assert np.all(err <= bound[ok] + 1e-9 * d_ref[ok])
        assert np.max(err) > 0.5 * np.max(bound[ok])  # and it is tight where it matters


def test_effective_roughness_solves_the_implicit_equation_with_exact_gradient():
    s0, tau = 0.3, 1.5
    ci = jnp.asarray(np.cos(np.radians([0.0, 10, 45, 70, 85, 89.9])))
    co = jnp.asarray(np.cos(np.radians([80.0, 30, 45, 88, 5, 60])))
    sig = np.asarray(effective_roughness(ci, co, s0, tau))
    z0 = s0 * np.sqrt((s0 / sig) ** 2 - 1)

    def k(c):
        t = np.sqrt(1 - c * c) / c
        return t * sp_erfc(tau / (2 * s0 * t)) if t > 0 else 0.0

    for z, a, b in zip(z0, np.asarray(ci), np.asarray(co), strict=True):
        lhs = math.sqrt(math.pi / 2) * z
        rhs = s0 / 4 * (k(a) + k(b)) * math.exp(-z * z / (2 * s0 * s0))
        assert abs(lhs - rhs) <= 1e-9 * s0 + 1e-12 * lhs  # z0 from sigma loses digits
    # gradient w.r.t. sigma0 matches central differences
    g = jax.grad(lambda s: jnp.sum(effective_roughness(ci, co, s, tau)))(s0)
    h = 1e-6
    fd = (
        np.sum(np.asarray(effective_roughness(ci, co, s0 + h, tau)))
        - np.sum(np.asarray(effective_roughness(ci, co, s0 - h, tau)))
    ) / (2 * h)
    assert abs(float(g) - fd) < 1e-6 * max(1.0, abs(fd))


# under jit with the model an argument: eagerly, each of the series' operations compiles on its
# own for every shape (273 small programs, 16 s of this test)
_jit_specular = jax.jit(lambda m, wo: m.specular_reflectance(wo))


def test_smooth_limit_is_a_fresnel_mirror():
    for fres in (ALU, Dielectric(1.5)):
        wo = mc.random_upper(200, 23, max_theta=np.radians(85))
        exact = HTSG(sigma0=0.0, tau=3.0, fresnel=fres)
        np.testing.assert_allclose(
            np.asarray(_jit_specular(exact, wo)), np.asarray(fres.eval(wo[:, 2])), rtol=1e-12
        )
        wi = mc.random_upper(200, 24)
        assert np.all(np.asarray(zc.Jitted(exact).f(wi, wo)) < 1e-250)  # g is clamped to > 0
        near = HTSG(sigma0=1e-4, tau=3.0, fresnel=fres)
        np.testing.assert_allclose(
            np.asarray(_jit_specular(near, wo)), np.asarray(fres.eval(wo[:, 2])), rtol=1e-3
        )
        a = zc.albedo_jit(near, wo[:8], n=64)
        spec = np.asarray(_jit_specular(near, wo[:8]))
        assert np.all(np.abs(a - spec) < 1e-3)  # directional-diffuse part has vanished


def test_rough_limit_is_the_beckmann_microfacet_lobe():
    """For g >> 1 eq. 78 tends to geometric optics: F S D_B / (4 cos_i cos_o), Beckmann with
    slope m = 2 sigma / tau (sigma the effective roughness); the specular term vanishes."""
    s0, tau = 3.0, 20.0
    m = HTSG(sigma0=s0, tau=tau, fresnel=ALU)
    wo = mc.random_upper(400, 25, max_theta=np.radians(60))
    wi = np.asarray(frames.reflect(wo)) + 0.15 * np.random.default_rng(3).normal(size=(400, 3))
    wi[:, 2] = np.abs(wi[:, 2]) + 0.2
    wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
    sig = np.asarray(effective_roughness(jnp.asarray(wi[:, 2]), jnp.asarray(wo[:, 2]), s0, tau))
    slope = 2 * sig / tau
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    tan2 = (1 - h[:, 2] ** 2) / h[:, 2] ** 2
    d_b = np.exp(-tan2 / slope**2) / (np.pi * slope**2 * h[:, 2] ** 4)
    fres = np.asarray(ALU.eval(np.sum(wi * h, -1)))

    def shadow(c):
        a = tau * c / (2 * s0 * np.sqrt(1 - c * c))
        lam = 0.5 * (np.exp(-a * a) / (np.sqrt(np.pi) * a) - sp_erfc(a))
        return (1 - 0.5 * sp_erfc(a)) / (1 + lam)

    s = shadow(wi[:, 2]) * shadow(wo[:, 2])
    expect = fres * (s * d_b / (4 * wi[:, 2] * wo[:, 2]))[:, None]
    got = np.asarray(m.f(wi, wo))
    big = expect > 1e-3 * expect.max()
    np.testing.assert_allclose(got[big], expect[big], rtol=0.02)
    assert np.all(np.asarray(m.specular_reflectance(wo)) < 1e-12)


def test_energy_bounded_by_fresnel():
    for s0, tau in ((0.05, 3.0), (0.2, 3.0), (1.0, 10.0)):
        m = HTSG(sigma0=s0, tau=tau, fresnel=ALU)
        wo = np.asarray(frames.spherical_to_direction(np.radians([0.0, 30, 60, 80]), 0.0))
        a = zc.albedo_jit(m, wo, n=128)
        f = np.asarray(ALU.eval(wo[:, 2]))
        assert np.all(a <= f * 1.01), (s0, tau, a, f)
        assert np.all(a[:2] >= 0.95 * f[:2])  # little is lost near the normal


def test_properties():
    m = HTSG(sigma0=0.12, tau=2.5, rho_ud=[0.05, 0.1, 0.02], fresnel=ALU)
    assert m.channels == 3
    j = zc.Jitted(m)
    mc.check_reciprocity(j, n=300)
    mc.check_nonnegative_and_masked(j, n=300)
    mc.check_isotropy(j, n=200)
    mc.check_stress(j)
    zc.check_param_gradients_jit(m)


def test_sample_weights_consistent_and_delta_mass():
    m = HTSG(sigma0=0.05, tau=3.0, rho_ud=0.1, fresnel=ALU)
    wo = mc.random_upper(3000, 26, max_theta=np.radians(85))
    u = np.random.default_rng(1).random((3000, 2))
    j = zc.Jitted(m)
    s = j.sample(wo, u)
    delta = np.asarray(s.delta)
    assert 0 < delta.mean() < 1
    mirror = np.asarray(frames.reflect(wo))
    np.testing.assert_allclose(np.asarray(s.wi)[delta], mirror[delta], atol=1e-12)
    np.testing.assert_allclose(
        np.asarray(s.weight)[delta] * np.asarray(s.pdf)[delta][:, None],
        np.asarray(m.specular_reflectance(wo))[delta],
        rtol=1e-10,
    )
    ok = ~delta & (np.asarray(s.pdf) > 0)
    wi = np.asarray(s.wi)[ok]
    np.testing.assert_allclose(np.asarray(s.pdf)[ok], np.asarray(j.pdf(wi, wo[ok])), rtol=1e-6)
    expect = np.asarray(j.f(wi, wo[ok])) * wi[:, 2:3] / np.asarray(s.pdf)[ok][:, None]
    np.testing.assert_allclose(np.asarray(s.weight)[ok], expect, rtol=1e-6)


@pytest.mark.parametrize(
    ("s0", "tau", "thetas"),
    [(0.08, 2.0, (20, 70)), pytest.param(0.5, 3.0, (0, 50, 85), marks=pytest.mark.slow)],
)
def test_chi2(s0, tau, thetas):
    m = HTSG(sigma0=s0, tau=tau, rho_ud=0.1, fresnel=ALU, wavelengths_um=0.55)
    zc.check_chi2_jit(m, theta_o_deg=thetas, n_tests=N_CHI2, drop_delta=True)


def test_serialization_and_registration():
    m = HTSG(sigma0=0.1, tau=2.0, rho_ud=0.1, fresnel=ALU, terms=16)
    again = models.Node.from_dict(m.to_dict())
    assert repr(again) == repr(m)
    assert set(m.params()) == {"sigma0", "tau", "rho_ud", "fresnel.eta", "fresnel.k"}
    assert models.HTSG is HTSG


@pytest.mark.parametrize(
    "kw",
    [
        dict(sigma0=-1.0),
        dict(tau=0.0),
        dict(terms=0),
        dict(fresnel="gold"),
        dict(wavelengths_um=[0.5, 0.6]),
        dict(wavelengths_um=[-1.0]),
    ],
)
def test_bad_parameters_raise(kw):
    with pytest.raises(ParameterError):
        HTSG(**kw)


def test_inside_a_sum_the_smooth_part_stays_consistent():
    m = models.Lambert(0.1) + HTSG(sigma0=0.1, tau=2.0, rho_ud=0.05, fresnel=ALU)
    mc.check_sample_weight_consistent(zc.Jitted(m), n=1000)
