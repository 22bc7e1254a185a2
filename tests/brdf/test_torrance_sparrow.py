"""TorranceSparrow: values against a plain NumPy reference, properties, energy, sampler."""

import numpy as np
import pytest
from scipy import special

from gonio.brdf import frames, models
from gonio.errors import ParameterError
from tests.brdf import model_checks as mc

GOLD = dict(eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 1.9])
COMBOS = [(d, g) for d in ("blinn", "beckmann", "ggx") for g in ("vcavity", "smith")]
# Chi-square tests run by default in this file (Sidak correction): 3 distributions x 3 theta_o.
N_CHI2 = 9


def reference_f(wi, wo, alpha, dist, shadowing, eta, k, rho_d):
    """Textbook Torrance-Sparrow in NumPy: tan/cos^4 forms, complex Fresnel, erf Lambda."""
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    th = np.arccos(np.clip(h[:, 2], -1, 1))
    c, t2 = np.cos(th), np.tan(th) ** 2
    if dist == "beckmann":
        d = np.exp(-t2 / alpha**2) / (np.pi * alpha**2 * c**4)
    elif dist == "ggx":
        d = alpha**2 / (np.pi * c**4 * (alpha**2 + t2) ** 2)
    else:
        e = 2 / alpha**2 - 2
        d = (e + 2) / (2 * np.pi) * c**e
    ci, co = wi[:, 2], wo[:, 2]
    oh = np.sum(wo * h, -1)
    if shadowing == "vcavity":
        g = np.minimum(1, np.minimum(2 * c * co / oh, 2 * c * ci / oh))
    else:

        def lam(w):
            tan = np.hypot(w[:, 0], w[:, 1]) / w[:, 2]
            if dist == "ggx":
                return (np.sqrt(1 + alpha**2 * tan**2) - 1) / 2
            a = 1 / (alpha * tan)
            return (special.erf(a) - 1) / 2 + np.exp(-(a**2)) / (2 * a * np.sqrt(np.pi))

        g = 1 / (1 + lam(wi) + lam(wo))
    n = np.asarray(eta) + 1j * np.asarray(k)
    cd = np.sum(wi * h, -1)[:, None]
    root = np.sqrt(n**2 - (1 - cd**2))
    rs = np.abs((cd - root) / (cd + root)) ** 2
    rp = np.abs((n**2 * cd - root) / (n**2 * cd + root)) ** 2
    f = 0.5 * (rs + rp)
    return np.asarray(rho_d) / np.pi + (d * g / (4 * ci * co))[:, None] * f


@pytest.mark.parametrize("dist,shadowing", COMBOS)
def test_matches_reference(dist, shadowing):
    wi, wo = mc.random_upper(3000, 11, max_theta=1.5), mc.random_upper(3000, 12, max_theta=1.5)
    for alpha in (0.05, 0.3, 1.0):
        m = models.TorranceSparrow(
            alpha, dist, shadowing, fresnel=models.Conductor(**GOLD), rho_d=[0.1, 0.0, 0.3]
        )
        expect = reference_f(wi, wo, alpha, dist, shadowing, GOLD["eta"], GOLD["k"], [0.1, 0, 0.3])
        np.testing.assert_allclose(np.asarray(m.f(wi, wo)), expect, rtol=1e-8, atol=1e-300)


def test_design_example_and_params():
    m = models.TorranceSparrow(
        alpha=0.2,
        distribution="beckmann",
        shadowing="vcavity",
        fresnel=models.Conductor(eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 1.9]),
        rho_d=0.0,
    )
    assert m.channels == 3
    assert set(m.params()) == {"alpha", "rho_d", "fresnel.eta", "fresnel.k"}
    assert m.param_specs()["alpha"].scale == "log"
    m2 = m.replace(**{"fresnel.eta": [0.3, 0.9, 1.1], "alpha": 0.1})
    np.testing.assert_allclose(np.asarray(m2.fresnel.eta), [0.3, 0.9, 1.1])
    assert float(m2.alpha) == 0.1 and m2.distribution == "beckmann"
    again = models.Node.from_dict(m.to_dict())
    assert repr(again) == repr(m)
    s = (models.Lambert(0.2) + m).sample(np.array([0.3, 0.0, np.sqrt(0.91)]), np.full((8, 2), 0.3))
    assert s.weight.shape == (8, 3)
    default = models.TorranceSparrow()
    assert isinstance(default.fresnel, models.Schlick) and float(default.fresnel.f0) == 0.04


def test_bad_arguments():
    with pytest.raises(ParameterError, match="distribution"):
        models.TorranceSparrow(distribution="phong")
    with pytest.raises(ParameterError, match="shadowing"):
        models.TorranceSparrow(shadowing="walter")
    with pytest.raises(ParameterError, match="alpha"):
        models.TorranceSparrow(alpha=0.0)
    with pytest.raises(ParameterError, match="alpha"):
        models.TorranceSparrow(alpha=4.5)  # above ALPHA_MAX (up to it: a valid, rough lobe)
    with pytest.raises(ParameterError, match="fresnel"):
        models.TorranceSparrow(fresnel=0.04)
    with pytest.raises(ParameterError, match="visible"):
        models.TorranceSparrow(distribution="blinn", sampling="visible")
    with pytest.raises(ParameterError, match="channel"):
        models.TorranceSparrow(rho_d=[0.1, 0.2], fresnel=models.Conductor(**GOLD))


def _property_checks(m, full=True):
    m = mc.Jitted(m)
    mc.check_stress(m)
    mc.check_sample_weight_consistent(m)
    mc.check_reciprocity(m)
    if full:
        mc.check_nonnegative_and_masked(m)
        mc.check_isotropy(m)


@pytest.mark.parametrize("dist,shadowing", COMBOS)
def test_properties_sharpest(dist, shadowing):
    m = models.TorranceSparrow(1e-4, dist, shadowing, fresnel=models.Dielectric(1.5), rho_d=0.2)
    _property_checks(m, full=False)
    mc.check_param_gradients(m, names=["alpha"])


@pytest.mark.parametrize(
    "dist,shadowing,fresnel",
    [("beckmann", "vcavity", models.Conductor(**GOLD)), ("ggx", "smith", models.Schlick(0.9)),
     ("blinn", "smith", models.Dielectric([1.3, 1.5, 1.7]))],
)  # fmt: skip
def test_properties_and_gradients(dist, shadowing, fresnel):
    m = models.TorranceSparrow(0.3, dist, shadowing, fresnel=fresnel, rho_d=[0.1, 0.2, 0.0])
    _property_checks(m)
    mc.check_param_gradients(m)


@pytest.mark.slow
@pytest.mark.parametrize("dist,shadowing", COMBOS)
@pytest.mark.parametrize("alpha", [1e-4, 0.02, 0.3, 1.0])
def test_properties_sweep(dist, shadowing, alpha):
    for fresnel in (models.Conductor(**GOLD), models.Dielectric(1.5), models.Schlick(0.9)):
        m = models.TorranceSparrow(alpha, dist, shadowing, fresnel=fresnel, rho_d=0.1)
        _property_checks(m)
        mc.check_param_gradients(m)
    mc.check_stress(models.TorranceSparrow(alpha, dist, shadowing, fresnel=models.Schlick(0.0)))


@pytest.mark.parametrize("dist,shadowing", [c for c in COMBOS if c != ("blinn", "smith")])
def test_energy_at_most_one(dist, shadowing):
    """With F = 1, exact Smith and the V-cavity term both keep single scattering <= 1."""
    for alpha in (0.02, 0.3, 1.0):
        m = models.TorranceSparrow(alpha, dist, shadowing, fresnel=models.NoFresnel())
        a = mc.check_albedo_at_most_one(mc.Jitted(m), theta_o_deg=(0, 30, 60, 85, 89))
        if alpha == 0.02:  # a sharp lobe loses almost nothing away from grazing
            assert np.all(a[:3] > 0.99)


def test_blinn_smith_approximation_breaks_energy():
    """Blinn has no exact Smith term; the Beckmann-equivalent one (documented in microfacet.py)
    creates energy for very rough surfaces at grazing angles, and is fine otherwise."""
    wo = np.asarray(frames.spherical_to_direction(np.radians([30.0, 85.0]), 0.0))
    blinn = models.TorranceSparrow(1.0, "blinn", "smith", fresnel=models.NoFresnel())
    a = np.asarray(mc.Jitted(blinn).directional_albedo(wo, 256))[:, 0]
    assert a[0] < 1.0 and a[1] > 1.2, a
    blinn = models.TorranceSparrow(0.3, "blinn", "smith", fresnel=models.NoFresnel())
    mc.check_albedo_at_most_one(mc.Jitted(blinn), theta_o_deg=(0, 30, 60, 85))


@pytest.mark.parametrize("dist", ["blinn", "beckmann", "ggx"])
def test_chi2(dist):
    m = models.TorranceSparrow(0.02, dist, "smith", fresnel=models.Schlick(0.3), rho_d=0.1)
    mc.check_chi2(mc.Jitted(m), theta_o_deg=(0, 60, 85), n_tests=N_CHI2, res_theta=60, res_phi=120,
                  mirror_cap=0.2)  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("dist", ["blinn", "beckmann", "ggx"])
@pytest.mark.parametrize("alpha", [0.02, 0.1, 0.5, 1.0])
@pytest.mark.parametrize("sampling", ["auto", "distribution"])
def test_chi2_sweep(dist, alpha, sampling):
    m = models.TorranceSparrow(
        alpha, dist, "vcavity", fresnel=models.Conductor(**GOLD), rho_d=0.05, sampling=sampling
    )
    n_tests = 3 * 4 * 2 * 4
    kw = {"mirror_cap": 10 * alpha, "res_theta": 60, "res_phi": 120} if alpha < 0.2 else {}
    mc.check_chi2(mc.Jitted(m), theta_o_deg=(0, 30, 70, 85), n_tests=n_tests, **kw)


def test_chi2_detects_a_wrong_jacobian():
    class Wrong(models.TorranceSparrow):
        def specular_pdf(self, wi, wo):  # forgets the 1/(4 wo.h) Jacobian's wo.h dependence
            h = frames.normalize(wi + wo)
            return super().specular_pdf(wi, wo) * 4.0 * frames.dot(wo, h)

    m = Wrong(0.3, "beckmann", "smith", fresnel=models.Schlick(0.5))
    with pytest.raises(AssertionError, match=r"differs|p =|integrates"):
        mc.check_chi2(mc.Jitted(m), theta_o_deg=(60,), n_tests=1, n_samples=200_000)


@pytest.mark.parametrize("dist", ["beckmann", "ggx"])
def test_known_zero_diffuse_skips_the_mixture_exactly(dist):
    """A concrete rho_d = 0 samples the specular lobe alone; a traced rho_d = 0 goes through the
    two-lobe mixture. Both must give the same pdf and the same samples (F > 0 everywhere)."""
    import jax

    rng = np.random.default_rng(5)
    wo = frames.spherical_to_direction(rng.uniform(0, 1.4, 500), rng.uniform(0, 6.2, 500))
    wi = frames.spherical_to_direction(rng.uniform(0, 1.4, 500), rng.uniform(0, 6.2, 500))
    u = rng.random((500, 2))
    m = models.TorranceSparrow(0.3, dist, "smith", models.Conductor(**GOLD))
    assert m._diffuse_free()

    def traced(rho, fn, *args):
        return fn(m.replace(rho_d=rho), *args)

    rho = np.zeros(3)
    p_mix = jax.jit(traced, static_argnums=1)(rho, models.TorranceSparrow.pdf, wi, wo)
    s_mix = jax.jit(traced, static_argnums=1)(rho, models.TorranceSparrow.sample, wo, u)
    np.testing.assert_allclose(m.pdf(wi, wo), p_mix, rtol=1e-12)
    s = m.sample(wo, u)
    np.testing.assert_allclose(s.wi, s_mix.wi, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(s.pdf, s_mix.pdf, rtol=1e-12)
    np.testing.assert_allclose(s.weight, s_mix.weight, rtol=1e-12)


@pytest.mark.parametrize(("dist", "sampling"), [("beckmann", "distribution"), ("ggx", "visible")])
def test_closed_form_sample_weight_is_f_cos_over_pdf(dist, sampling):
    """The specular-only sample weight (D cancelled) equals f cos_i / pdf of the same wi."""
    rng = np.random.default_rng(8)
    wo = frames.spherical_to_direction(rng.uniform(0, 1.55, 4000), rng.uniform(0, 6.2, 4000))
    u = rng.random((4000, 2))
    m = models.TorranceSparrow(0.3, dist, "smith", models.Conductor(**GOLD), sampling=sampling)
    s = m.sample(wo, u)
    ok = np.asarray(s.pdf) > 0
    assert ok.mean() > 0.8  # most samples above the horizon (0.89 for Beckmann here)
    wi = np.asarray(s.wi)[ok]
    expect = np.asarray(m.f(wi, wo[ok])) * wi[:, 2:3] / np.asarray(m.pdf(wi, wo[ok]))[:, None]
    np.testing.assert_allclose(np.asarray(s.weight)[ok], expect, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(s.pdf)[ok], np.asarray(m.pdf(wi, wo[ok])), rtol=1e-12)
