import numpy as np
import pytest

from gonio.brdf import models
from gonio.brdf.models import microfacet as mf
from gonio.brdf.models.gtr import gtr_ndf
from tests.brdf import model_checks as mc
from tests.brdf.quadrature import albedo_quadrature, direction, jitted, pdf_integral

# default run: one chi-square test; the rest with -m slow (Sidak correction over all of them)
CHI2 = [(0.1, 1.2, (60,))]
SLOW_CHI2 = [(0.3, 2.0, (0, 45, 80)), (0.1, 1.2, (0,)), (0.05, 6.0, (30,))]
N_CHI2 = sum(len(t) for _, _, t in CHI2 + SLOW_CHI2)


def test_gamma_two_is_ggx():
    h = mc.random_upper(500, 5)
    for a in (0.01, 0.2, 0.9):
        np.testing.assert_allclose(gtr_ndf(h, a, 2.0), mf.ndf(h, a, "ggx"), rtol=1e-9)


@pytest.mark.parametrize("alpha, gamma", [(0.05, 1.1), (0.95, 1.05)])
def test_ndf_normalized(alpha, gamma):
    from gonio.brdf.chi2 import integrate_pdf_cells

    def projected(h):
        return np.asarray(gtr_ndf(h, alpha, gamma)) * h[:, 2]

    total = integrate_pdf_cells(projected, 180, 4, order=8).sum()
    assert abs(total - 1.0) < 2e-3, total


@pytest.mark.parametrize(
    "alpha, gamma", [pytest.param(0.02, 1.3, marks=pytest.mark.slow),
                     pytest.param(0.2, 2.0, marks=pytest.mark.slow),
                     pytest.param(0.6, 8.0, marks=pytest.mark.slow)],
)  # fmt: skip
def test_properties(alpha, gamma):
    m = models.GTR([0.9, 0.5, 0.2], alpha, gamma, 0.3)
    j = mc.Jitted(m)  # one compile per program for every parameter set
    mc.check_properties(m, j)


def test_param_gradients_finite():
    # what a fit needs of the model in the default run; test_properties checks the rest (slow)
    mc.check_param_gradients(models.GTR([0.9, 0.5, 0.2], 0.02, 1.3, 0.3))


@pytest.mark.parametrize(
    "alpha, gamma, thetas", [(0.3, 1.1, (40.0,)),
                             pytest.param(0.1, 2.0, (0.0, 75.0), marks=pytest.mark.slow),
                             pytest.param(0.8, 1.5, (0.0, 40.0, 75.0), marks=pytest.mark.slow)],
)  # fmt: skip
def test_energy_at_most_rho_s(alpha, gamma, thetas):
    m = models.GTR(1.0, alpha, gamma, 1.0)
    for t in thetas:
        a = albedo_quadrature(m, direction(t, 0.0), res_theta=90, res_phi=90)
        assert a[0] <= 1.0 + 2e-3, (t, a)
        assert pdf_integral(m, direction(t, 0.0), res_theta=90, res_phi=90) <= 1.0 + 2e-3


@pytest.mark.parametrize("alpha, gamma, thetas", CHI2)
def test_chi2(alpha, gamma, thetas):
    m = jitted(models.GTR(0.7, alpha, gamma))
    mc.check_chi2(m, theta_o_deg=thetas, n_tests=N_CHI2, n_samples=200_000)


@pytest.mark.slow
@pytest.mark.parametrize("alpha, gamma, thetas", SLOW_CHI2)
def test_chi2_slow(alpha, gamma, thetas):
    mc.check_chi2(jitted(models.GTR(0.7, alpha, gamma)), theta_o_deg=thetas, n_tests=N_CHI2)
