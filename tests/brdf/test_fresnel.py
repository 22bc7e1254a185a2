"""Fresnel terms against independent closed forms (complex-index formulas written here)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gonio.brdf import models
from gonio.errors import ParameterError

COS = np.concatenate([[0.0, 1e-12, 1e-6], np.linspace(0.01, 0.99, 60), [1 - 1e-9, 1.0]])


def complex_fresnel(cos_i, eta):
    """Unpolarized reflectance for relative complex index ``eta`` via complex amplitudes."""
    cos_i = np.asarray(cos_i, dtype=np.complex128)
    eta = np.asarray(eta, dtype=np.complex128)
    sin2 = 1.0 - cos_i**2
    root = np.sqrt(eta**2 - sin2)  # eta * cos_t, principal branch
    with np.errstate(invalid="ignore", divide="ignore"):  # 0/0 only for eta = 1 at grazing
        rs = (cos_i - root) / (cos_i + root)
        rp = (eta**2 * cos_i - root) / (eta**2 * cos_i + root)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2), np.abs(rs) ** 2, np.abs(rp) ** 2


@pytest.mark.parametrize("eta,k", [(0.2, 3.9), (1.1, 1.9), (0.05, 0.0), (2.5, 0.3), (1.0, 0.0)])
def test_conductor_matches_complex_amplitudes(eta, k):
    f = np.asarray(models.Conductor(eta=eta, k=k).eval(COS))[:, 0]
    expect, _, _ = complex_fresnel(COS, eta + 1j * k)
    if eta == 1.0 and k == 0.0:  # index-matched: no reflection (the formula is 0/0 at grazing)
        expect[0] = 0.0
    np.testing.assert_allclose(f, expect, rtol=1e-10, atol=1e-12)


def test_conductor_normal_incidence_per_channel():
    eta, k = np.array([0.2, 0.9, 1.1]), np.array([3.9, 2.4, 1.9])
    f = np.asarray(models.Conductor(eta=eta, k=k).eval(1.0))
    np.testing.assert_allclose(f, ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2), rtol=1e-12)
    assert f.shape == (3,)
    # Grazing incidence reflects everything.
    np.testing.assert_allclose(np.asarray(models.Conductor(eta=eta, k=k).eval(0.0)), 1.0)


def test_dielectric_brewster_and_normal():
    eta = 1.5
    m = models.Dielectric(eta)
    np.testing.assert_allclose(np.asarray(m.eval(1.0)), ((eta - 1) / (eta + 1)) ** 2, rtol=1e-12)
    brewster = np.arctan(eta)
    # At Brewster's angle R_p = 0, so F = R_s / 2 with R_s from Snell's law.
    ci = np.cos(brewster)
    ct = np.sqrt(1 - np.sin(brewster) ** 2 / eta**2)
    rs = ((ci - eta * ct) / (ci + eta * ct)) ** 2
    np.testing.assert_allclose(np.asarray(m.eval(ci))[0], rs / 2, rtol=1e-12)
    _, _, rp = complex_fresnel(ci, eta)
    assert rp < 1e-25
    # And F over angles equals the complex-amplitude result.
    np.testing.assert_allclose(
        np.asarray(m.eval(COS))[:, 0], complex_fresnel(COS, eta)[0], rtol=1e-10, atol=1e-14
    )


def test_dielectric_total_internal_reflection_and_inside():
    eta = 1.5
    m = models.Dielectric(eta)
    crit = np.sqrt(1 - 1 / eta**2)  # cosine of the critical angle, inside
    inside_tir = -np.linspace(0.0, crit * (1 - 1e-9), 20)
    np.testing.assert_array_equal(np.asarray(m.eval(inside_tir))[:, 0], 1.0)
    # Below the critical angle, light from inside reflects like the outside at the Snell pair.
    ci = np.linspace(0.02, 1.0, 30)
    ct = np.sqrt(1 - (1 - ci**2) / eta**2)
    np.testing.assert_allclose(
        np.asarray(m.eval(-ct))[:, 0], np.asarray(m.eval(ci))[:, 0], rtol=1e-10, atol=1e-14
    )
    # A conductor with k = 0 and eta < 1 is the same interface seen from inside.
    np.testing.assert_allclose(
        np.asarray(models.Conductor(eta=1 / eta, k=0.0).eval(COS)),
        np.asarray(m.eval(-COS)),
        rtol=1e-9,
        atol=1e-12,
    )


def test_schlick_endpoints_and_no_fresnel():
    m = models.Schlick([0.04, 0.5, 1.0])
    np.testing.assert_allclose(np.asarray(m.eval(1.0)), [0.04, 0.5, 1.0])
    np.testing.assert_allclose(np.asarray(m.eval(0.0)), [1.0, 1.0, 1.0])
    np.testing.assert_allclose(np.asarray(m.eval(0.5))[0], 0.04 + 0.96 * 0.5**5)
    np.testing.assert_allclose(np.asarray(m.mean(0.3)), np.mean(np.asarray(m.eval(0.3))))
    assert np.asarray(models.NoFresnel().eval(np.zeros((4, 2)))).shape == (4, 2, 1)


TERMS = [
    models.Conductor(eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 1.9]),
    models.Conductor(eta=1.0, k=0.0),
    models.Conductor(eta=0.5, k=0.0),
    models.Dielectric(1.5),
    models.Dielectric([1.0, 1.33, 2.4]),
    models.Schlick(0.04),
]


@pytest.mark.parametrize("term", TERMS, ids=repr)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_range_dtype_and_gradients(term, dtype):
    c = np.concatenate([COS, -COS]).astype(dtype)
    f = np.asarray(term.eval(c))
    assert f.dtype == dtype
    assert np.all(np.isfinite(f)) and np.all(f >= 0) and np.all(f <= 1)
    for name, v0 in term.params().items():

        def loss(v, name=name):
            return jnp.sum(term.replace(**{name: v}).eval(jnp.asarray(c)))

        g = np.asarray(jax.grad(loss)(v0))
        assert np.all(np.isfinite(g)), f"{term!r}: gradient w.r.t. {name}"


@pytest.mark.parametrize("term", TERMS, ids=repr)
def test_channels_first_is_eval_with_the_axis_moved(term):
    from gonio.brdf.models._base import channels_last

    c = jnp.asarray(np.concatenate([COS, -COS]).astype(np.float32))
    first = jax.jit(term.eval_channels_first)(c)
    assert first.shape[0] == np.asarray(term.eval(c)).shape[-1]
    # the same formula, compiled in another loop order: equal to within float32 rounding
    want = np.asarray(jax.jit(term.eval)(c))
    np.testing.assert_allclose(np.moveaxis(np.asarray(first), 0, -1), want, rtol=2e-6, atol=0)
    # the identity product moves the axis exactly, the smallest normal and huge values included
    # (XLA:CPU flushes subnormals to zero in any computation)
    x = np.array([[1.2e-38, 3.0e38, -2.5], [7.0, -1.2e-38, 0.0], [1.0, -3.0e38, 1e-7]], np.float32)
    np.testing.assert_array_equal(np.asarray(jax.jit(channels_last)(x)), x.T)


def test_bad_parameters():
    with pytest.raises(ParameterError, match="k"):
        models.Conductor(eta=0.2, k=-1.0)
    with pytest.raises(ParameterError, match="eta"):
        models.Dielectric(eta=0.0)
    with pytest.raises(ParameterError, match="f0"):
        models.Schlick(1.5)
    with pytest.raises(ParameterError, match="channel"):
        models.Conductor(eta=[0.2, 0.9], k=[3.9, 2.4, 1.9])


def test_serialization_round_trip():
    for term in TERMS:
        again = models.Node.from_dict(term.to_dict())
        assert repr(again) == repr(term)
