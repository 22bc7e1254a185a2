import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gonio.fit  # noqa: F401
from gonio.brdf import models
from gonio.errors import FitError
from gonio.fit.data import from_arrays, prepare
from gonio.fit.losses import LOSSES, evaluate, get_loss
from tests.fit.synth import cosine_directions, synthetic


def _dirs(n, seed=1):
    rng = np.random.default_rng(seed)
    return cosine_directions(n, rng), cosine_directions(n, rng)


def test_prepare_masks_nan_sigma_and_cutoff():
    wi, wo = _dirs(500)
    y = np.full((500, 3), 0.2)
    y[:10, 1] = np.nan
    sigma = np.full((500, 3), 0.01)
    sigma[10:15, 0] = 0.0
    d = from_arrays(wi, wo, y, sigma=sigma)
    theta_i = np.degrees(np.arccos(wi[:, 2]))
    theta_o = np.degrees(np.arccos(wo[:, 2]))
    beyond = (theta_i > 80) | (theta_o > 80)
    expect = (~beyond).copy()
    expect[:15] = False
    assert d.n == expect.sum()
    assert d.source["n_invalid"] == 15
    assert d.source["n_beyond_cutoff"] == int(beyond[15:].sum())
    assert np.all(np.isfinite(d.values)) and np.all(d.sigma > 0)
    assert d.channel_names == ("R", "G", "B")
    # the cutoff is applied to both directions
    assert np.all(d.wi[:, 2] >= np.cos(np.radians(80)) - 1e-12)
    assert np.all(d.wo[:, 2] >= np.cos(np.radians(80)) - 1e-12)


def test_prepare_rejects_unusable_input():
    wi, wo = _dirs(50)
    with pytest.raises(FitError, match="no usable samples"):
        from_arrays(wi, wo, np.full(50, np.nan))
    graze = np.array([[np.sin(1.5), 0.0, np.cos(1.5)]] * 20)  # 86 degrees
    with pytest.raises(FitError, match="beyond theta_max"):
        from_arrays(graze, graze, np.ones(20))
    assert from_arrays(graze, graze, np.ones(20), theta_max_deg=89).n == 20
    with pytest.raises(FitError, match="theta_max"):
        from_arrays(wi, wo, np.ones(50), theta_max_deg=0)
    with pytest.raises(FitError, match="inconsistent"):
        from_arrays(wi[:10], wo, np.ones(50))
    with pytest.raises(FitError, match="cannot fit"):
        prepare(object())


def test_duck_typed_samples_object():
    class Samples:
        pass

    s = Samples()
    s.wi, s.wo = _dirs(100)
    s.values = np.ones((100, 1))
    s.sigma = None
    s.weights = np.full(100, 2.0)
    s.meta = {"name": "felt"}
    d = prepare(s)
    assert d.source["name"] == "felt" and d.channels == 1 and np.all(d.weights == 2.0)


def _manual(name, f, d):
    y, w, c = d.values, d.weights[:, None], d.values.shape[1]
    cos = d.wi[:, 2:3]
    sig = 1.0 if d.sigma is None else d.sigma
    W = d.weights.sum() * c
    if name == "wls":
        return np.sum(((f - y) / sig) ** 2)
    if name == "ngan":
        return np.sqrt(np.sum(w * ((f - y) * cos) ** 2) / W)
    if name == "low-e1":
        return np.sqrt(np.sum(w * (np.log1p(f * cos) - np.log1p(y * cos)) ** 2) / W)
    if name == "low-e2":
        return np.sqrt(np.sum(w * (np.log1p(f) - np.log1p(y)) ** 2) / W)
    if name == "sqrt-cos":
        return np.sqrt(np.sum(w * (np.sqrt(f * cos + 1e-4) - np.sqrt(y * cos + 1e-4)) ** 2) / W)
    if name == "cube-root":
        return np.sqrt(np.sum(w * (np.cbrt(f + 1e-6) - np.cbrt(y + 1e-6)) ** 2) / W)
    raise AssertionError(name)


@pytest.mark.parametrize("name", sorted(LOSSES))
def test_loss_formulas(name):
    truth = models.Lambert(albedo=[0.5, 0.4, 0.3])
    d, _f = synthetic(truth, n=300, seed=3)
    rng = np.random.default_rng(0)
    d = d.__class__(
        d.wi, d.wo, np.abs(d.values), d.sigma, rng.uniform(0.5, 2, d.n), d.channel_names, d.source
    )
    f_model = np.asarray(truth.f(d.wi, d.wo)) * 1.1
    assert evaluate(name, f_model, d) == pytest.approx(_manual(name, f_model, d), rel=1e-10)
    assert evaluate(name, d.values, d) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("name", sorted(LOSSES))
def test_loss_gradient_finite_at_zero_model(name):
    d, _ = synthetic(models.Lambert(albedo=0.5), n=50, seed=2)
    lo = get_loss(name)
    k = {a: jnp.asarray(b) for a, b in lo.constants(d).items()}
    g = jax.grad(lambda s: jnp.sum(lo.residual(jnp.full(d.values.shape, s), k) ** 2))(0.0)
    assert np.isfinite(g)


def test_unknown_loss():
    with pytest.raises(FitError, match="valid: wls"):
        get_loss("l3")
