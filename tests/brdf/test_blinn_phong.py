import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad

from gonio.brdf import models
from gonio.errors import ParameterError
from tests.brdf import model_checks as mc
from tests.brdf.quadrature import SHARP_CHI2, albedo_quadrature, direction, jitted, pdf_integral

# Chi-square tests in this file, default and slow together (Sidak correction over all of them).
# (rho_d, n, theta_o list, histogram options)
FAST_CHI2 = [
    (0.3, 200.0, (0, 45, 85), {}),
    (0.0, 10.0, (0, 45, 85), {}),
    (0.0, 5000.0, (0, 45), {}),  # n = 2/0.02^2 - 2 ~ roughness 0.02
    (0.0, 5000.0, (85,), SHARP_CHI2),
]
SLOW_CHI2 = [
    (0.3, 10.0, (0, 30, 60, 85), {}),
    (0.3, 5000.0, (0, 30), {}),
    (0.3, 5000.0, (60, 85), SHARP_CHI2),
    (0.0, 200.0, (0, 30, 60, 85), {}),
    (0.0, 1.0, (20, 70), {}),
    (0.8, 20000.0, (10, 80), SHARP_CHI2),
]
N_CHI2 = sum(len(t) for _, _, t, _ in FAST_CHI2 + SLOW_CHI2)


def norm_k(n):
    """Giesen's normalization, typed from the formula."""
    return (n + 2) * (n + 4) / (8 * np.pi * (2 ** (-n / 2) + n))


def reference_f(rho_d, rho_s, n, wi, wo):
    h = wi + wo
    cos_h = h[:, 2] / np.linalg.norm(h, axis=1)
    return rho_d / np.pi + rho_s * norm_k(n) * cos_h**n


@pytest.mark.parametrize("n", [0.0, 1.0, 10.0, 1000.0])
def test_normalization_is_exact_at_normal_incidence(n):
    # wo on the normal: theta_h = theta_i / 2.
    k = norm_k(n)
    val = quad(lambda t: k * np.cos(t / 2) ** n * np.cos(t) * np.sin(t) * 2 * np.pi, 0, np.pi / 2)
    assert abs(val[0] - 1.0) < 1e-9
    m = models.BlinnPhong(0.0, 0.8, n)
    np.testing.assert_allclose(albedo_quadrature(m, direction(0.0)), [0.8], rtol=1e-4)


def test_value_against_formula():
    wi, wo = mc.random_upper(500, 30), mc.random_upper(500, 31)
    for n in (0.0, 3.0, 40.0):
        m = models.BlinnPhong(0.2, 0.7, n)
        np.testing.assert_allclose(
            np.asarray(m.f(wi, wo))[:, 0], reference_f(0.2, 0.7, n, wi, wo), rtol=1e-9
        )


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_peak_and_sharp_lobe_precision(dtype):
    n = 1e5
    m = models.BlinnPhong(0.1, 0.6, n)
    wo = direction(50.0, 1.0)
    mirror = wo * [-1, -1, 1]
    peak = np.asarray(m.f(mirror.astype(dtype), wo.astype(dtype)))[0]
    assert peak.dtype == dtype
    np.testing.assert_allclose(peak, 0.1 / np.pi + 0.6 * norm_k(n), rtol=1e-6)
    # theta_h = 3 mrad: cos^n ~ exp(-0.45) must survive float32.
    a = 3e-3
    wi = direction(50.0 + 2 * np.degrees(a), 1.0 + np.pi)
    expect = reference_f(0.1, 0.6, n, wi[None].astype(np.float64), wo[None])[0]
    assert 0.3 < (expect - 0.1 / np.pi) / (0.6 * norm_k(n)) < 0.9
    got = np.asarray(m.f(wi.astype(dtype), wo.astype(dtype)))[0]
    np.testing.assert_allclose(got, expect, rtol=2e-3 if dtype == np.float32 else 1e-9)


@pytest.mark.parametrize(
    "rho_d, rho_s, n",
    [(0.2, 0.5, 50.0), (0.0, 1.0, 0.0), ([0.1, 0.2, 0.3], [0.5, 0.4, 0.3], 1e5), (0.5, 0.0, 10.0),
     (0.0, 0.0, 5.0)],
)  # fmt: skip
def test_properties(rho_d, rho_s, n):
    m = models.BlinnPhong(rho_d, rho_s, n)
    j = mc.Jitted(m)  # one compile per program for every parameter set (op by op: 10-60 s each)
    mc.check_properties(m, j)


@pytest.mark.parametrize("rho_d, n, thetas, kw", FAST_CHI2)
def test_chi2(rho_d, n, thetas, kw):
    mc.check_chi2(jitted(models.BlinnPhong(rho_d, 0.6, n)), thetas, n_tests=N_CHI2, **kw)


@pytest.mark.slow
@pytest.mark.parametrize("rho_d, n, thetas, kw", SLOW_CHI2)
def test_chi2_sweep(rho_d, n, thetas, kw):
    mc.check_chi2(jitted(models.BlinnPhong(rho_d, 0.6, n)), thetas, n_tests=N_CHI2, **kw)


def test_chi2_detects_a_missing_jacobian():
    class Wrong(models.BlinnPhong):
        def _pdf(self, wi, wo):  # the half-vector density without the 1/(4 wo.h) Jacobian
            h = wi + wo
            c = h[..., 2] / jnp.sqrt((h * h).sum(-1))
            return (self.n + 1) / (2 * np.pi) * c**self.n

    with pytest.raises(AssertionError, match=r"p =|integrates"):
        mc.check_chi2(
            jitted(Wrong(0.0, 0.6, 200.0)), theta_o_deg=(30,), n_tests=1, n_samples=200_000
        )


def test_pdf_integrates_to_at_most_one():
    for n in (0.0, 10.0, 1000.0):
        m = models.BlinnPhong(0.0, 1.0, n)
        for t in (0, 30, 60, 85):
            total = pdf_integral(m, direction(t, 0.3), res_phi=720)
            assert total <= 1.0 + 1e-6, (n, t, total)
    # Sharp lobe away from the horizon loses nothing.
    assert abs(pdf_integral(models.BlinnPhong(0.0, 1.0, 1000.0), direction(0.0)) - 1) < 1e-5


@pytest.mark.parametrize("n", [0.0, 1.0, 10.0, 100.0, 1000.0])
def test_energy(n):
    m = models.BlinnPhong(0.3, 0.7, n)
    np.testing.assert_allclose(albedo_quadrature(m, direction(0.0)), [1.0], rtol=2e-4)
    prev = 1.0 + 1e-9
    for t in (30.0, 60.0, 85.0):
        a = albedo_quadrature(m, direction(t), res_phi=720)[0]
        assert a <= prev, (t, a)  # decreasing towards grazing, so <= rho_d + rho_s = 1
        prev = a
    mc.check_albedo_at_most_one(m, theta_o_deg=(0, 45, 85), tol=1e-3)


def test_energy_sharp_lobe_by_sampling():
    a = mc.check_albedo_at_most_one(models.BlinnPhong(0.0, 1.0, 1e5), theta_o_deg=(0, 45, 85))
    # For a sharp lobe the albedo is ~ cos^2(theta_o) (cos theta_i times the 4 wo.h Jacobian).
    np.testing.assert_allclose(a[:, 0], np.cos(np.radians([0, 45, 85])) ** 2, rtol=2e-2)


@pytest.mark.parametrize(
    "kw, name",
    [({"n": -1.0}, "n"), ({"n": 2e5}, "n"), ({"rho_s": 1.5}, "rho_s"), ({"rho_d": -0.1}, "rho_d"),
     ({"n": [1.0, 2.0]}, "n")],
)  # fmt: skip
def test_bad_parameters_raise(kw, name):
    with pytest.raises(ParameterError, match=name):
        models.BlinnPhong(**kw)


def test_metadata_and_serialization():
    m = models.BlinnPhong([0.1, 0.2, 0.3], 0.4, 123.0)
    specs = m.param_specs()
    assert specs["n"].scale == "log" and specs["rho_d"].scale == "logit"
    assert repr(models.Node.from_dict(m.to_dict())) == repr(m)
    mc.check_sample_weight_consistent(m + models.Phong(0.0, 0.3, 20.0))
