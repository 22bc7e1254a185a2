"""Delta lobes: exact mirror/refraction directions, event probabilities and weights."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gonio.brdf import frames, models
from gonio.errors import ParameterError
from tests.brdf import model_checks as mc

GOLD = models.Conductor(eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 1.9])


def snell_fresnel(cos_o, eta):
    """Reflectance and refracted cosine from Snell's law, written out for one side."""
    sin_t = np.sqrt(1 - cos_o**2) / eta
    with np.errstate(invalid="ignore"):  # NaN beyond the critical angle; the caller masks it
        cos_t = np.sqrt(1 - sin_t**2)
    rs = (cos_o - eta * cos_t) / (cos_o + eta * cos_t)
    rp = (eta * cos_o - cos_t) / (eta * cos_o + cos_t)
    return 0.5 * (rs**2 + rp**2), cos_t


def test_mirror_direction_and_weight():
    m = models.SpecularReflection(GOLD)
    wo = mc.random_upper(500, 7)
    s = m.sample(wo, np.random.default_rng(0).random((500, 2)))
    np.testing.assert_array_equal(np.asarray(s.wi), wo * [-1, -1, 1])
    np.testing.assert_array_equal(np.asarray(s.pdf), 1.0)
    assert np.all(np.asarray(s.delta))
    n = np.asarray(GOLD.eta) + 1j * np.asarray(GOLD.k)
    c = wo[:, 2:3]
    root = np.sqrt(n**2 - (1 - c**2))
    rs = np.abs((c - root) / (c + root)) ** 2
    rp = np.abs((n**2 * c - root) / (n**2 * c + root)) ** 2
    np.testing.assert_allclose(np.asarray(s.weight), (rs + rp) / 2, rtol=1e-10)
    # Delta lobes never report a density or a BRDF value, not even for the mirror pair.
    assert np.all(np.asarray(m.f(s.wi, wo)) == 0) and np.all(np.asarray(m.pdf(s.wi, wo)) == 0)
    below = m.sample(wo * [1, 1, -1], np.full((500, 2), 0.5))
    assert np.all(np.asarray(below.pdf) == 0) and np.all(np.asarray(below.weight) == 0)
    assert not np.any(np.asarray(below.delta))
    np.testing.assert_allclose(np.asarray(models.SpecularReflection().sample(wo, 0.5).weight), 1)


def test_mirror_in_a_sum():
    m = models.Lambert(0.3) + models.SpecularReflection(GOLD)
    assert m.has_delta
    wo = np.asarray(frames.spherical_to_direction(0.6, 0.2))
    u = np.random.default_rng(1).random((20000, 2))
    s = m.sample(wo, u)
    delta = np.asarray(s.delta)
    f_mirror = np.asarray(GOLD.eval(wo[2]))
    p_mirror = np.mean(f_mirror) / (0.3 + np.mean(f_mirror))
    assert abs(delta.mean() - p_mirror) < 0.01
    np.testing.assert_allclose(np.asarray(s.pdf)[delta], p_mirror, rtol=1e-12)
    w_delta = np.asarray(s.weight)[delta]
    np.testing.assert_allclose(w_delta, np.broadcast_to(f_mirror / p_mirror, w_delta.shape))
    # Smooth samples are evaluated against the Lambert part only.
    wi = np.asarray(s.wi)[~delta]
    np.testing.assert_allclose(np.asarray(s.pdf)[~delta], (1 - p_mirror) * wi[:, 2] / np.pi)
    albedo = np.asarray(m.directional_albedo(wo))
    # The 128 x 128 stratified estimate picks lobes on rows of u0: exact to within 1/128.
    np.testing.assert_allclose(albedo, 0.3 + f_mirror, atol=1.5 / 128)


@pytest.mark.parametrize("eta", [1.5, 1.0, 2.4, 0.7])
def test_glass_from_outside(eta):
    m = models.SpecularTransmission(eta)
    cos_o = np.array([1.0, 0.9, 0.5, 0.1, 1e-3])
    wo = np.stack(
        [np.sqrt(1 - cos_o**2) * np.cos(0.4), np.sqrt(1 - cos_o**2) * np.sin(0.4), cos_o], -1
    )
    f, cos_t = snell_fresnel(cos_o, eta)
    f = np.where(np.isnan(f), 1.0, f)  # eta < 1 has a critical angle outside too
    refl = m.sample(wo, np.stack([np.maximum(f - 1e-9, 0), np.full(5, 0.5)], -1))
    tran = m.sample(wo, np.stack([np.minimum(f + 1e-9, mc.EPS1), np.full(5, 0.5)], -1))
    can = f < 1
    # Reflection: exact mirror, probability F, weight 1 (so pdf * weight = F).
    r = f > 1e-9
    np.testing.assert_allclose(np.asarray(refl.wi)[r], (wo * [-1, -1, 1])[r], atol=1e-15)
    np.testing.assert_allclose(np.asarray(refl.pdf)[r], f[r], rtol=1e-9)
    np.testing.assert_allclose(np.asarray(refl.weight)[r, 0], 1.0)
    # Refraction: Snell's law, the other side, probability 1 - F, weight 1/eta^2.
    wt = np.asarray(tran.wi)[can]
    np.testing.assert_allclose(wt[:, 2], -cos_t[can], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(wt[:, :2], -wo[can, :2] / eta, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(np.asarray(tran.pdf)[can], 1 - f[can], rtol=1e-9)
    np.testing.assert_allclose(np.asarray(tran.weight)[can, 0], 1 / eta**2, rtol=1e-12)
    assert np.all(np.asarray(tran.delta)[can])
    # Energy: the two events' probabilities times their (importance) throughputs sum to 1.
    imp = models.SpecularTransmission(eta, transport="importance")
    ri = imp.sample(wo, np.stack([np.maximum(f - 1e-9, 0), np.full(5, 0.5)], -1))
    ti = imp.sample(wo, np.stack([np.minimum(f + 1e-9, mc.EPS1), np.full(5, 0.5)], -1))
    e_r = np.where(f > 1e-9, np.asarray(ri.pdf) * np.asarray(ri.weight)[:, 0], 0.0)
    e_t = np.where(can, np.asarray(ti.pdf) * np.asarray(ti.weight)[:, 0], 0.0)
    np.testing.assert_allclose(e_r + e_t, 1.0, rtol=1e-12)


def test_glass_from_inside_and_round_trip():
    eta = 1.5
    m = models.SpecularTransmission(eta)
    crit = np.sqrt(1 - 1 / eta**2)  # cosine of the critical angle inside
    # Beyond the critical angle: total internal reflection, always.
    wo = np.asarray(frames.spherical_to_direction(np.pi - np.arccos(crit * 0.9), 0.3))
    s = m.sample(np.tile(wo, (50, 1)), np.random.default_rng(2).random((50, 2)))
    np.testing.assert_allclose(np.asarray(s.wi), np.tile(wo * [-1, -1, 1], (50, 1)))
    np.testing.assert_array_equal(np.asarray(s.pdf), 1.0)
    # Light refracted in from outside at theta retraces its path out (radiance gains eta^2).
    wo_out = np.asarray(frames.spherical_to_direction(0.7, 1.1))
    t_in = m.sample(wo_out, np.array([mc.EPS1, 0.5]))
    assert float(t_in.wi[2]) < 0
    back = m.sample(np.asarray(t_in.wi), np.array([mc.EPS1, 0.5]))
    np.testing.assert_allclose(np.asarray(back.wi), wo_out, atol=1e-12)
    np.testing.assert_allclose(np.asarray(back.weight), eta**2)
    # Reflectance is the same on both sides of the Snell pair (Stokes relation).
    np.testing.assert_allclose(np.asarray(back.pdf), np.asarray(t_in.pdf), rtol=1e-10)


def test_horizon_stress_and_gradients():
    d = mc.stress_directions()
    us = np.array([[0, 0], [0, mc.EPS1], [mc.EPS1, 0], [mc.EPS1, mc.EPS1], [0.5, 0.5]])
    ww = np.repeat(d, len(us), axis=0)
    uu = np.tile(us, (len(d), 1))
    lobes = [
        models.SpecularReflection(GOLD),
        models.SpecularTransmission(1.5),
        models.SpecularTransmission(0.5),
        models.Lambert(0.2) + models.SpecularTransmission(),
    ]
    for m in lobes:
        for dtype in (np.float32, np.float64):
            s = m.sample(ww.astype(dtype), uu.astype(dtype))
            for name in ("wi", "pdf", "weight"):
                arr = np.asarray(getattr(s, name))
                assert np.all(np.isfinite(arr)), (m, name, dtype)
                assert arr.dtype == dtype
            horizon = ww[:, 2].astype(dtype) == 0
            assert np.all(np.asarray(s.pdf)[horizon] == 0)
        wi = np.repeat(d, len(d), axis=0)
        wo = np.tile(d, (len(d), 1))
        if m.is_delta:
            assert np.all(np.asarray(m.f(wi, wo)) == 0) and np.all(np.asarray(m.pdf(wi, wo)) == 0)
        for name, v0 in m.params().items():

            def loss(v, m=m, name=name):
                s = m.replace(**{name: v}).sample(jnp.asarray(ww), jnp.asarray(uu))
                return jnp.sum(s.pdf) + jnp.sum(s.weight)

            # one compiled program per gradient: op by op, every primitive of the backward
            # pass compiles on its own (most of this test's time); the values are the same
            grad = np.asarray(jax.jit(jax.grad(loss))(v0))
            assert np.all(np.isfinite(grad)), (m, name)


def test_flags_and_errors():
    assert models.SpecularReflection.is_delta and models.SpecularTransmission.is_delta
    assert set(models.SpecularReflection(GOLD).params()) == {"fresnel.eta", "fresnel.k"}
    for m in (models.SpecularReflection(GOLD), models.SpecularTransmission(1.33, "importance")):
        assert repr(models.Node.from_dict(m.to_dict())) == repr(m)
    with pytest.raises(ParameterError, match="eta"):
        models.SpecularTransmission([1.5, 1.6])
    with pytest.raises(ParameterError, match="transport"):
        models.SpecularTransmission(1.5, transport="light")
    with pytest.raises(ParameterError, match="fresnel"):
        models.SpecularReflection(0.9)
