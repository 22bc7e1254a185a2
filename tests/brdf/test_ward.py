import numpy as np
import pytest

from gonio.brdf import models
from gonio.errors import ParameterError
from tests.brdf import model_checks as mc
from tests.brdf.quadrature import SHARP_CHI2, albedo_quadrature, direction, jitted, pdf_integral

VARIANTS = ("original", "duer", "balanced")

# Chi-square tests in this file, default and slow together (Sidak correction over all of them).
# The sampler and pdf do not depend on the variant (only f does); both are exercised anyway.
# (rho_d, alpha_x, alpha_y, variant, theta_o list, histogram options)
FAST_CHI2 = [
    (0.3, 0.1, 0.1, "original", (0, 45, 85), {}),
    (0.0, 0.02, 0.02, "balanced", (0, 45), {}),
    (0.0, 0.02, 0.02, "balanced", (85,), SHARP_CHI2),
    (0.0, 0.05, 0.3, "duer", (0, 45), {}),
    (0.0, 0.05, 0.3, "duer", (85,), SHARP_CHI2),
]
SLOW_CHI2 = [
    (0.0, 0.5, 0.5, "original", (0, 30, 60, 85), {}),
    (0.0, 1.0, 0.2, "balanced", (10, 50, 80), {}),
    (0.3, 0.02, 0.02, "original", (0, 30, 60), {}),
    (0.3, 0.02, 0.08, "balanced", (75, 85), SHARP_CHI2),
]
N_CHI2 = sum(len(c[4]) for c in FAST_CHI2 + SLOW_CHI2)


def reference_f(rho_d, rho_s, ax, ay, variant, wi, wo):
    """Ward's formula in half-vector angles; the balanced variant in its D / (4 (wi.h)^2) form."""
    h = wi + wo
    h = h / np.linalg.norm(h, axis=1, keepdims=True)
    th, ph = np.arccos(h[:, 2]), np.arctan2(h[:, 1], h[:, 0])
    e = np.exp(-(np.tan(th) ** 2) * (np.cos(ph) ** 2 / ax**2 + np.sin(ph) ** 2 / ay**2))
    ci, co = wi[:, 2], wo[:, 2]
    if variant == "original":
        spec = e / (4 * np.pi * ax * ay * np.sqrt(ci * co))
    elif variant == "duer":
        spec = e / (4 * np.pi * ax * ay * ci * co)
    else:
        beckmann = e / (np.pi * ax * ay * np.cos(th) ** 4)
        spec = beckmann / (4 * np.einsum("ij,ij->i", wi, h) ** 2)
    return rho_d / np.pi + rho_s * spec


@pytest.mark.parametrize("variant", VARIANTS)
def test_value_against_formula(variant):
    wi, wo = mc.random_upper(500, 40), mc.random_upper(500, 41)
    for ax, ay in ((0.3, 0.3), (0.2, 0.6), (1.0, 0.05)):
        m = models.Ward(0.2, 0.7, ax, ay, variant=variant)
        np.testing.assert_allclose(
            np.asarray(m.f(wi, wo))[:, 0],
            reference_f(0.2, 0.7, ax, ay, variant, wi, wo),
            rtol=1e-9,
            atol=1e-300,
        )


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_peak_value(variant, dtype):
    n = np.array([0.0, 0.0, 1.0], dtype)
    for ax, ay in ((0.1, 0.1), (1e-4, 1e-4), (1e-4, 0.5)):
        m = models.Ward(0.1, 0.6, ax, ay, variant=variant)
        got = np.asarray(m.f(n, n))[0]
        assert got.dtype == dtype and np.isfinite(got)
        np.testing.assert_allclose(got, 0.1 / np.pi + 0.6 / (4 * np.pi * ax * ay), rtol=1e-6)


def test_anisotropy_axes():
    """Rotating both directions by 90 degrees about the normal swaps alpha_x and alpha_y."""
    wi, wo = mc.random_upper(300, 42), mc.random_upper(300, 43)

    def rot(w):
        return np.stack([-w[:, 1], w[:, 0], w[:, 2]], 1)

    for variant in VARIANTS:
        a = models.Ward(0.0, 1.0, 0.1, 0.4, variant=variant)
        b = models.Ward(0.0, 1.0, 0.4, 0.1, variant=variant)
        np.testing.assert_allclose(
            np.asarray(a.f(rot(wi), rot(wo))), np.asarray(b.f(wi, wo)), rtol=1e-9
        )
        np.testing.assert_allclose(
            np.asarray(a.pdf(rot(wi), rot(wo))), np.asarray(b.pdf(wi, wo)), rtol=1e-9
        )


# Every variant at the stress corner alpha = 1e-4 (isotropic, and anisotropic against 1.0);
# the variants share everything except the normalization, so the other sets run once.
PROPERTY_SETS = [
    (v, *p)
    for v in VARIANTS
    for p in ((0.0, 1.0, 1e-4, 1e-4), ([0.1, 0.2, 0.3], [0.5, 0.4, 0.3], 1e-4, 1.0))
] + [("original", 0.1, 0.5, 0.2, 0.2), ("balanced", 0.5, 0.0, 1.0, 1.0)]


@pytest.mark.parametrize("variant, rho_d, rho_s, ax, ay", PROPERTY_SETS)
def test_properties(variant, rho_d, rho_s, ax, ay):
    m = models.Ward(rho_d, rho_s, ax, ay, variant=variant)
    mc.check_properties(m, isotropic=ax == ay)


@pytest.mark.parametrize("rho_d, ax, ay, variant, thetas, kw", FAST_CHI2)
def test_chi2(rho_d, ax, ay, variant, thetas, kw):
    m = jitted(models.Ward(rho_d, 0.6, ax, ay, variant=variant))
    mc.check_chi2(m, thetas, n_tests=N_CHI2, **kw)


@pytest.mark.slow
@pytest.mark.parametrize("rho_d, ax, ay, variant, thetas, kw", SLOW_CHI2)
def test_chi2_sweep(rho_d, ax, ay, variant, thetas, kw):
    m = jitted(models.Ward(rho_d, 0.6, ax, ay, variant=variant))
    mc.check_chi2(m, thetas, n_tests=N_CHI2, **kw)


def test_chi2_detects_swapped_axes():
    class Wrong(models.Ward):
        def sample_half_vector(self, u, dtype=None):  # alpha_x and alpha_y swapped
            return models.Ward(0.0, 1.0, self.alpha_y, self.alpha_x).sample_half_vector(u, dtype)

    with pytest.raises(AssertionError, match=r"p ="):
        mc.check_chi2(
            jitted(Wrong(0.0, 0.6, 0.1, 0.3)), theta_o_deg=(30,), n_tests=1, n_samples=200_000
        )


def test_pdf_integrates_to_at_most_one():
    for ax, ay in ((0.05, 0.05), (0.3, 0.1), (1.0, 1.0)):
        m = models.Ward(0.0, 1.0, ax, ay)
        for t in (0, 45, 85):
            total = pdf_integral(m, direction(t, 0.3), res_phi=720)
            assert total <= 1.0 + 1e-6, (ax, ay, t, total)
    # A narrow lobe about the normal loses (almost) nothing below the horizon.
    assert abs(pdf_integral(models.Ward(0.0, 1.0, 0.05, 0.05), direction(0.0)) - 1.0) < 1e-5


@pytest.mark.parametrize("variant", VARIANTS)
def test_specular_albedo_tends_to_rho_s_for_smooth_lobes(variant):
    a = models.Ward(0.0, 0.8, 0.01, 0.01, variant=variant).directional_albedo(direction(0.0))
    np.testing.assert_allclose(np.asarray(a), [0.8], rtol=1e-3)


ALPHAS = (1e-3, 0.01, 0.1, 0.3, 0.5, 1.0)


def _albedos(variant, alpha, thetas):
    m = jitted(models.Ward(0.0, 1.0, alpha, alpha, variant=variant))
    wo = np.stack([direction(t) for t in thetas])
    return np.asarray(m.directional_albedo(wo, n=256))[:, 0]


@pytest.mark.parametrize("alpha", ALPHAS)
def test_energy_balanced_is_bounded(alpha):
    a = _albedos("balanced", alpha, (0, 30, 60, 80, 85, 89, 89.9, 89.99))
    assert np.all(a <= 1.0 + 1e-3), a


@pytest.mark.parametrize("alpha", ALPHAS)
def test_energy_original_conserves_up_to_89_degrees(alpha):
    a = _albedos("original", alpha, (0, 30, 60, 80, 85, 89))
    assert np.all(a <= 1.0 + 1e-3), a


def test_energy_original_violation_at_extreme_grazing():
    """Documented: original Ward with alpha = 0.5 reflects ~1.5x the light at theta_o = 89.9."""
    m = models.Ward(0.0, 1.0, 0.5, 0.5, variant="original")
    wo = direction(89.9)
    q = albedo_quadrature(m, wo, res_theta=900, res_phi=720, order=4)[0]  # 0.1-degree rows
    s = float(np.asarray(m.directional_albedo(wo, n=256))[0])
    assert q > 1.3 and s > 1.3, (q, s)
    np.testing.assert_allclose(s, q, rtol=1e-2)


@pytest.mark.parametrize("alpha", (1e-3, 0.01, 0.05, 0.1))
def test_energy_duer_conserves_for_smooth_lobes_up_to_85_degrees(alpha):
    a = _albedos("duer", alpha, (0, 30, 60, 80, 85))
    assert np.all(a <= 1.0 + 1e-3), a


def test_energy_duer_violation_at_grazing():
    """Documented: Duer's 1/(cos_i cos_o) exceeds 1 at grazing (alpha = 0.3: ~1.25 at 85 deg)."""
    m = models.Ward(0.0, 1.0, 0.3, 0.3, variant="duer")
    q = albedo_quadrature(m, direction(85.0), res_phi=720)[0]
    assert q > 1.2, q
    a = _albedos("duer", 0.1, (89.0,))
    assert a[0] > 1.5, a


@pytest.mark.parametrize(
    "kw, name",
    [({"alpha_x": 0.0}, "alpha_x"), ({"alpha_y": 2.0}, "alpha_y"), ({"rho_s": 1.5}, "rho_s"),
     ({"alpha_x": [0.1, 0.2]}, "alpha_x"), ({"variant": "blinn"}, "variant")],
)  # fmt: skip
def test_bad_parameters_raise(kw, name):
    with pytest.raises(ParameterError, match=name):
        models.Ward(**kw)


def test_metadata_and_serialization():
    m = models.Ward([0.1, 0.2, 0.3], 0.4, 0.05, 0.2, variant="balanced")
    specs = m.param_specs()
    assert specs["alpha_x"].scale == "log" and specs["alpha_x"].lower == 1e-4
    assert "variant" not in m.params()
    again = models.Node.from_dict(m.to_dict())
    assert repr(again) == repr(m) and again.variant == "balanced"
    assert models.Ward(alpha_x=0.3).alpha_y == 0.3  # isotropic by default
    mc.check_sample_weight_consistent(m + models.Lambert(0.1))
