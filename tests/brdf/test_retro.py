import numpy as np
import pytest

from gonio.brdf import models
from tests.brdf import model_checks as mc
from tests.brdf.quadrature import albedo_quadrature, direction, jitted

# default run: one chi-square test; the rest with -m slow (Sidak correction over all of them)
CHI2 = [(5.0, (50,))]
SLOW_CHI2 = [(5.0, (0, 85)), (200.0, (0, 60))]
N_CHI2 = sum(len(t) for _, t in CHI2 + SLOW_CHI2)


def test_peak_at_the_light():
    m = models.Retroreflection([0.5, 0.4, 0.3], 100.0)
    wo = direction(40.0, 0.7)
    peak = np.asarray(m.f(wo[None], wo[None]))[0]
    np.testing.assert_allclose(peak, np.array([0.5, 0.4, 0.3]) * 102 / (2 * np.pi), rtol=1e-9)
    mirror = wo * np.array([-1.0, -1.0, 1.0])
    assert np.all(np.asarray(m.f(mirror[None], wo[None]))[0] < 1e-6 * peak)


@pytest.mark.parametrize(
    "rho, n", [([0.1, 0.2, 0.3], 30.0), pytest.param(0.5, 0.0, marks=pytest.mark.slow),
               pytest.param(1.0, 2000.0, marks=pytest.mark.slow)],
)  # fmt: skip
def test_properties(rho, n):
    m = models.Retroreflection(rho, n)
    j = mc.Jitted(m)  # one compile per program for every parameter set
    mc.check_properties(m, j)


@pytest.mark.parametrize(
    "n, thetas", [(10.0, (0.0, 60.0)), pytest.param(0.0, (0.0, 30.0, 85.0), marks=pytest.mark.slow),
                  pytest.param(100.0, (0.0, 30.0, 60.0, 85.0), marks=pytest.mark.slow)],
)  # fmt: skip
def test_albedo_at_most_rho_and_tight_at_normal(n, thetas):
    m = models.Retroreflection(1.0, n)
    res = 360 if n >= 100 else 90
    a = [albedo_quadrature(m, direction(t, 0.0), res_theta=res)[0] for t in thetas]
    assert abs(a[0] - 1.0) < 2e-3, a
    assert max(a) <= 1.0 + 2e-3, a


@pytest.mark.parametrize("n, thetas", CHI2)
def test_chi2(n, thetas):
    mc.check_chi2(
        jitted(models.Retroreflection(0.5, n)),
        theta_o_deg=thetas,
        n_tests=N_CHI2,
        n_samples=200_000,
    )


@pytest.mark.slow
@pytest.mark.parametrize("n, thetas", SLOW_CHI2)
def test_chi2_slow(n, thetas):
    mc.check_chi2(jitted(models.Retroreflection(0.5, n)), theta_o_deg=thetas, n_tests=N_CHI2)
