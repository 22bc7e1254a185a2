import numpy as np
import pytest

from gonio.brdf import models
from gonio.errors import ParameterError
from tests.brdf import model_checks as mc
from tests.brdf.quadrature import albedo_quadrature, direction, jitted, pdf_integral

# Chi-square tests in this file, default and slow together (Sidak correction over all of them).
FAST_CHI2 = [  # (rho_d, n, theta_o list)
    (0.3, 200.0, (0, 45, 85)),
    (0.0, 10.0, (0, 45, 85)),
    (0.0, 5000.0, (0, 45, 85)),  # n = 2/0.02^2 - 2 ~ roughness 0.02
]
SLOW_CHI2 = [
    (0.3, 10.0, (0, 30, 60, 85)),
    (0.3, 5000.0, (0, 30, 60, 85)),
    (0.0, 200.0, (0, 30, 60, 85)),
    (0.0, 1.0, (20, 70)),
    (0.8, 20000.0, (10, 80)),
]
N_CHI2 = sum(len(t) for _, _, t in FAST_CHI2 + SLOW_CHI2)


def reference_f(rho_d, rho_s, n, wi, wo):
    """The published formula with the mirror direction built from angles."""
    th, ph = np.arccos(wo[:, 2]), np.arctan2(wo[:, 1], wo[:, 0])
    mirror = np.stack(
        [np.sin(th) * np.cos(ph + np.pi), np.sin(th) * np.sin(ph + np.pi), np.cos(th)]
    )
    cos_a = np.einsum("ij,ji->i", wi, mirror)
    lobe = np.where(cos_a > 0, np.abs(cos_a) ** n, 0.0)  # the lobe ends 90 deg from the mirror
    return rho_d / np.pi + rho_s * (n + 2) / (2 * np.pi) * lobe


def test_value_against_formula():
    wi, wo = mc.random_upper(500, 20), mc.random_upper(500, 21)
    for n in (0.0, 3.0, 40.0):
        m = models.Phong(0.2, 0.7, n)
        np.testing.assert_allclose(
            np.asarray(m.f(wi, wo))[:, 0], reference_f(0.2, 0.7, n, wi, wo), rtol=1e-9
        )


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_peak_and_sharp_lobe_precision(dtype):
    n = 1e5
    m = models.Phong(0.1, 0.6, n)
    wo = direction(50.0, 1.0)
    mirror = wo * [-1, -1, 1]
    peak = np.asarray(m.f(mirror.astype(dtype), wo.astype(dtype)))[0]
    assert peak.dtype == dtype
    np.testing.assert_allclose(peak, 0.1 / np.pi + 0.6 * (n + 2) / (2 * np.pi), rtol=1e-6)
    # 3 mrad off the mirror direction: cos^n = exp(n log cos a) ~ exp(-0.45); float32 must keep it.
    a = 3e-3
    wi = direction(50.0 + np.degrees(a), 1.0 + np.pi)
    expect = 0.1 / np.pi + 0.6 * (n + 2) / (2 * np.pi) * np.cos(a) ** n
    got = np.asarray(m.f(wi.astype(dtype), wo.astype(dtype)))[0]
    np.testing.assert_allclose(got, expect, rtol=2e-3 if dtype == np.float32 else 1e-9)


@pytest.mark.parametrize(
    "rho_d, rho_s, n",
    [(0.2, 0.5, 50.0), (0.0, 1.0, 0.0), ([0.1, 0.2, 0.3], [0.5, 0.4, 0.3], 1e5), (0.5, 0.0, 10.0),
     (0.0, 0.0, 5.0)],
)  # fmt: skip
def test_properties(rho_d, rho_s, n):
    m = models.Phong(rho_d, rho_s, n)
    mc.check_properties(m)


@pytest.mark.parametrize("rho_d, n, thetas", FAST_CHI2)
def test_chi2(rho_d, n, thetas):
    mc.check_chi2(jitted(models.Phong(rho_d, 0.6, n)), theta_o_deg=thetas, n_tests=N_CHI2)


@pytest.mark.slow
@pytest.mark.parametrize("rho_d, n, thetas", SLOW_CHI2)
def test_chi2_sweep(rho_d, n, thetas):
    mc.check_chi2(jitted(models.Phong(rho_d, 0.6, n)), theta_o_deg=thetas, n_tests=N_CHI2)


def test_chi2_detects_a_wrong_exponent():
    class Wrong(models.Phong):
        def _sample_lobe(self, wo, u):  # draws a lobe twice as wide as the pdf says
            return models.Phong(0.0, 1.0, self.n / 4)._sample_lobe(wo, u)

    with pytest.raises(AssertionError, match=r"p ="):
        mc.check_chi2(
            jitted(Wrong(0.0, 0.6, 200.0)), theta_o_deg=(30,), n_tests=1, n_samples=200_000
        )


def test_pdf_integrates_to_at_most_one():
    for n in (0.0, 10.0, 1000.0):
        m = models.Phong(0.0, 1.0, n)
        # The whole lobe is above the horizon at normal incidence: the integral is 1.
        assert abs(pdf_integral(m, direction(0.0)) - 1.0) < 1e-5
        for t in (30, 60, 85):
            total = pdf_integral(m, direction(t, 0.3))
            assert total <= 1.0 + 1e-6, (n, t, total)
    # Mixture: the diffuse part always integrates to 1, the lobe loses its below-horizon part.
    assert 0.5 < pdf_integral(models.Phong(0.5, 0.5, 1.0), direction(85.0)) < 1.0


@pytest.mark.parametrize("n", [0.0, 1.0, 10.0, 100.0, 1000.0])
def test_energy(n):
    m = models.Phong(0.3, 0.7, n)
    # Normal incidence: the specular lobe reflects exactly rho_s (the normalization is right).
    np.testing.assert_allclose(albedo_quadrature(m, direction(0.0)), [1.0], rtol=2e-4)
    for t in (30.0, 60.0, 85.0):
        a = albedo_quadrature(m, direction(t))
        assert a[0] <= 1.0 + 1e-6, (t, a)
    mc.check_albedo_at_most_one(m, theta_o_deg=(0, 45, 85), tol=1e-3)


def test_energy_sharp_lobe_by_sampling():
    m = models.Phong(0.0, 1.0, 1e5)
    a = mc.check_albedo_at_most_one(m, theta_o_deg=(0, 45, 85), tol=1e-3)
    # Importance sampling a lobe with its own shape: albedo ~ cos(theta_o) at 1e5.
    np.testing.assert_allclose(a[:, 0], np.cos(np.radians([0, 45, 85])), rtol=2e-2)


@pytest.mark.parametrize(
    "kw, name",
    [({"n": -1.0}, "n"), ({"n": 2e5}, "n"), ({"rho_s": 1.5}, "rho_s"), ({"rho_d": -0.1}, "rho_d"),
     ({"n": [1.0, 2.0]}, "n")],
)  # fmt: skip
def test_bad_parameters_raise(kw, name):
    with pytest.raises(ParameterError, match=name):
        models.Phong(**kw)


def test_metadata_and_serialization():
    m = models.Phong([0.1, 0.2, 0.3], 0.4, 123.0)
    specs = m.param_specs()
    assert specs["n"].scale == "log" and specs["rho_s"].per_channel
    assert repr(models.Node.from_dict(m.to_dict())) == repr(m)
    mc.check_sample_weight_consistent(m + models.OrenNayar(0.3, 0.5))
