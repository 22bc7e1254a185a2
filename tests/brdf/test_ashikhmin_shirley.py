import numpy as np
import pytest

from gonio.brdf import models
from gonio.errors import ParameterError
from tests.brdf import model_checks as mc
from tests.brdf import zoo_checks as zc

N_CHI2 = 6


def reference_f(rd, rs, nu, nv, wi, wo):
    """Independent NumPy transcription of Ashikhmin & Shirley (2000), eqs. 4 and 5."""
    rd, rs = np.atleast_1d(rd)[None, :], np.atleast_1d(rs)[None, :]
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    kh = np.sum(wi * h, -1)
    cos_phi2 = h[:, 0] ** 2 / (h[:, 0] ** 2 + h[:, 1] ** 2)
    e = nu * cos_phi2 + nv * (1 - cos_phi2)
    spec = np.sqrt((nu + 1) * (nv + 1)) / (8 * np.pi) * h[:, 2] ** e
    spec /= kh * np.maximum(wi[:, 2], wo[:, 2])
    fres = rs + (1 - rs) * (1 - kh[:, None]) ** 5
    diff = 28 * rd / (23 * np.pi) * (1 - rs)
    diff = diff * ((1 - (1 - wi[:, 2] / 2) ** 5) * (1 - (1 - wo[:, 2] / 2) ** 5))[:, None]
    return spec[:, None] * fres + diff


@pytest.mark.parametrize(
    ("rd", "rs", "nu", "nv"),
    [
        ([0.5, 0.3, 0.1], [0.04, 0.05, 0.9], 1000.0, 10.0),
        pytest.param(0.3, 0.05, 100.0, 100.0, marks=pytest.mark.slow),
        pytest.param(0.0, 1.0, 1e5, 1e5, marks=pytest.mark.slow),
        pytest.param(1.0, 0.0, 0.0, 0.0, marks=pytest.mark.slow),
    ],
)
def test_matches_reference_and_properties(rd, rs, nu, nv):
    m = models.AshikhminShirley(rho_d=rd, rho_s=rs, nu=nu, nv=nv)
    wi, wo = mc.random_upper(3000, 11), mc.random_upper(3000, 12)
    np.testing.assert_allclose(
        np.asarray(m.f(wi, wo)), reference_f(rd, rs, nu, nv, wi, wo), rtol=1e-7, atol=1e-300
    )
    j = zc.Jitted(m)
    mc.check_reciprocity(j)
    mc.check_nonnegative_and_masked(j)
    mc.check_stress(j)
    zc.check_param_gradients_jit(m)
    mc.check_sample_weight_consistent(j)


def test_isotropy():
    mc.check_isotropy(models.AshikhminShirley(rho_d=0.2, rho_s=0.1, nu=300.0))


@pytest.mark.slow
def test_energy_below_one():
    for nu, nv in ((10.0, 10.0), (1000.0, 50.0)):
        mc.check_albedo_at_most_one(
            models.AshikhminShirley(rho_d=1.0, rho_s=1.0, nu=nu, nv=nv), theta_o_deg=(0, 45, 80)
        )


def test_half_vector_density_integrates_to_one():
    m = models.AshikhminShirley(nu=800.0, nv=20.0)
    # pdf over wi with the diffuse mixture weight removed integrates to 1 when wo is the normal
    # (every reflected direction stays above the horizon).
    th, ph = np.meshgrid(
        np.linspace(0, np.pi / 2, 1200), np.linspace(0, 2 * np.pi, 1200), indexing="ij"
    )
    h = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    ph_ = np.asarray(m._half_pdf(h.reshape(-1, 3))).reshape(th.shape)
    integral = np.trapezoid(np.trapezoid(ph_ * np.sin(th), ph[0], axis=1), th[:, 0])
    assert abs(integral - 1) < 2e-3


@pytest.mark.parametrize(
    ("nu", "nv", "thetas"),
    [
        (2000.0, 20.0, (30, 85)),
        pytest.param(100.0, 100.0, (0, 60), marks=pytest.mark.slow),
        pytest.param(5.0, 50.0, (45, 75), marks=pytest.mark.slow),
    ],
)
def test_chi2(nu, nv, thetas):
    m = models.AshikhminShirley(rho_d=0.3, rho_s=0.2, nu=nu, nv=nv)
    zc.check_chi2_jit(m, theta_o_deg=thetas, n_tests=N_CHI2)


@pytest.mark.parametrize("kw", [dict(rho_s=1.5), dict(nu=-1.0), dict(nv=float("nan"))])
def test_bad_parameters_raise(kw):
    with pytest.raises(ParameterError):
        models.AshikhminShirley(**kw)
