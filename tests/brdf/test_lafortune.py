import jax
import numpy as np
import pytest

from gonio.brdf import frames, models
from gonio.errors import ParameterError
from tests.brdf import model_checks as mc
from tests.brdf import zoo_checks as zc

# Chi-square tests in this file (Sidak correction over all of them).
N_CHI2 = 7

CASES = {
    "phong-like": dict(cx=-1.0, cy=-1.0, cz=1.0, n=40.0, rho_s=0.6),
    "three lobes": dict(
        cx=[-1.0, 0.6, -0.9],
        cy=[-1.0, 0.6, -0.3],
        cz=[1.0, 0.7, 1.1],
        n=[200.0, 4.0, 15.0],
        rho_s=[[0.3, 0.2, 0.1], [0.1, 0.12, 0.14], [0.2, 0.2, 0.2]],
        rho_d=[0.1, 0.2, 0.3],
    ),
    "sharp": dict(cx=-1.0, cy=-1.0, cz=1.0, n=1e5, rho_s=0.5, rho_d=0.05),
    "unnormalized": dict(
        cx=[-1.01, -0.3],
        cy=[-1.01, -0.3],
        cz=[1.0, 0.9],
        n=[30.0, 2.0],
        rho_s=[1.0, 0.4],
        normalization="none",
    ),
}


def reference_f(p, wi, wo):
    """Independent NumPy evaluation of the Lafortune sum (one lobe at a time)."""
    cx, cy, cz, n = (
        np.atleast_1d(np.asarray(p.get(k, d), float))
        for k, d in (("cx", -1.0), ("cy", -1.0), ("cz", 1.0), ("n", 20.0))
    )
    rho_s = np.asarray(p.get("rho_s", 0.5), float)
    rho_s = np.broadcast_to(rho_s, cx.shape) if rho_s.ndim == 0 else rho_s
    out = np.zeros((wi.shape[0], 1 if rho_s.ndim == 1 else rho_s.shape[1]))
    for k in range(cx.size):
        x = cx[k] * wi[:, 0] * wo[:, 0] + cy[k] * wi[:, 1] * wo[:, 1] + cz[k] * wi[:, 2] * wo[:, 2]
        val = np.maximum(x, 0) ** n[k]
        if p.get("normalization", "normalized") == "normalized":
            val *= (n[k] + 2) / (2 * np.pi) / max(abs(cx[k]), abs(cy[k]), abs(cz[k])) ** n[k]
        out += val[:, None] * np.atleast_1d(rho_s[k])[None, :]
    return out + np.atleast_1d(np.asarray(p.get("rho_d", 0.0)))[None, :] / np.pi


@pytest.mark.parametrize(
    "name", [n if n == "three lobes" else pytest.param(n, marks=pytest.mark.slow) for n in CASES]
)
def test_matches_reference_and_properties(name):
    p = CASES[name]
    m = models.Lafortune(**p)
    wi, wo = mc.random_upper(3000, 5), mc.random_upper(3000, 6)
    np.testing.assert_allclose(
        np.asarray(m.f(wi, wo)), reference_f(p, wi, wo), rtol=1e-9, atol=1e-12
    )
    j = zc.Jitted(m)
    mc.check_reciprocity(j)
    mc.check_nonnegative_and_masked(j)
    mc.check_stress(j)
    zc.check_param_gradients_jit(m)
    mc.check_sample_weight_consistent(j)


def test_phong_special_case_is_modified_phong():
    m = models.Lafortune(cx=-1.0, cy=-1.0, cz=1.0, n=25.0, rho_s=0.7)
    wi, wo = mc.random_upper(500, 7), mc.random_upper(500, 8)
    cos_a = np.clip(np.sum(np.asarray(frames.reflect(wi)) * wo, -1), 0, None)
    np.testing.assert_allclose(
        np.asarray(m.f(wi, wo))[:, 0], 0.7 * 27 / (2 * np.pi) * cos_a**25, rtol=1e-9, atol=1e-14
    )


def test_isotropic_when_cx_equals_cy():
    mc.check_isotropy(
        models.Lafortune(
            cx=[-1.0, 0.5],
            cy=[-1.0, 0.5],
            cz=[0.9, 0.7],
            n=[30.0, 3.0],
            rho_s=[0.5, 0.2],
            rho_d=0.1,
        )
    )


@pytest.mark.slow
def test_energy():
    a = mc.check_albedo_at_most_one(
        models.Lafortune(cx=-1, cy=-1, cz=1, n=50, rho_s=0.9, rho_d=0.05)
    )
    assert a[0, 0] > 0.85  # near the normal almost all of the lobe is above the horizon


@pytest.mark.parametrize(
    ("name", "thetas"),
    [
        ("three lobes", (0, 40, 85)),
        pytest.param("phong-like", (20, 70), marks=pytest.mark.slow),
        pytest.param("unnormalized", (10, 60), marks=pytest.mark.slow),
    ],
)
def test_chi2(name, thetas):
    zc.check_chi2_jit(models.Lafortune(**CASES[name]), theta_o_deg=thetas, n_tests=N_CHI2)


def test_parameter_layout_and_serialization():
    m = models.Lafortune(**CASES["three lobes"])
    assert m.lobe_count == 3 and m.channels == 3
    specs = m.param_specs()
    assert specs["cx"].per_lobe and specs["rho_s"].per_lobe and specs["rho_s"].per_channel
    assert not specs["rho_d"].per_lobe
    again = models.Node.from_dict(m.to_dict())
    assert repr(again) == repr(m)
    # replace works under jit with traced per-lobe arrays
    f = jax.jit(lambda n: m.replace(n=n).f(np.array([0, 0, 1.0]), np.array([0.6, 0, 0.8])))
    assert np.all(np.isfinite(np.asarray(f(np.array([10.0, 3.0, 7.0])))))


@pytest.mark.parametrize(
    "kw",
    [
        dict(cx=[1.0, 2.0], cy=[1.0, 2.0, 3.0]),
        dict(n=-1.0),
        dict(rho_s=[[[0.1]]]),
        dict(normalization="bogus"),
        dict(cx=[]),
        dict(cz="x"),
    ],
)
def test_bad_parameters_raise(kw):
    with pytest.raises(ParameterError):
        models.Lafortune(**kw)


def test_single_lobe_layout_for_generic_fitters():
    """Scalar lobe parameters and a (C,) rho_s (what a fitter without per-lobe support passes)
    describe one lobe; a sum of single-lobe models equals the multi-lobe model."""
    two = models.Lafortune(
        cx=[-1.0, 0.5], cy=[-1.0, 0.5], cz=[1.0, 0.8], n=[30.0, 4.0],
        rho_s=[[0.3, 0.2, 0.1], [0.1, 0.2, 0.3]], rho_d=[0.1, 0.1, 0.1],
    )  # fmt: skip
    a = models.Lafortune(n=[1.0], rho_s=[[1.0, 1.0, 1.0]]).replace(
        cx=-1.0, cy=-1.0, cz=1.0, n=30.0, rho_s=[0.3, 0.2, 0.1], rho_d=[0.1, 0.1, 0.1]
    )
    b = models.Lafortune(n=[1.0], rho_s=[[1.0, 1.0, 1.0]]).replace(
        cx=0.5, cy=0.5, cz=0.8, n=4.0, rho_s=[0.1, 0.2, 0.3], rho_d=0.0
    )
    assert a.lobe_count == 1 and a.channels == 3
    wi, wo = mc.random_upper(500, 31), mc.random_upper(500, 32)
    np.testing.assert_allclose(
        np.asarray((a + b).f(wi, wo)), np.asarray(two.f(wi, wo)), rtol=1e-12, atol=1e-15
    )
    mc.check_sample_weight_consistent(a + b)
