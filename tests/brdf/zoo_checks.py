"""Helpers shared by the zoo model tests (Lafortune, Ashikhmin-Shirley, HTSG, Ngan)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf import frames
from gonio.brdf.chi2 import chi2_test


def jit_sampler(model, wo, drop_delta: bool = False):
    """``model_sampler`` with jitted sample and pdf (the eager path is slow for 1e6 samples).

    With ``drop_delta`` delta samples are reported as failed (pdf 0): the chi-square test then
    expects exactly the missing mass ``1 - integral of pdf`` to be lost, which checks the delta
    lobe's selection probability too.
    """
    wo = jnp.asarray(wo, jnp.float64)

    @jax.jit
    def _sample(m, u):
        s = m.sample(wo, u)
        pdf = jnp.where(s.delta, 0.0, s.pdf) if drop_delta else s.pdf
        return s.wi, pdf

    @jax.jit
    def _pdf(m, wi):
        return m.pdf(wi, wo)

    def sample(u):
        wi, pdf = _sample(model, jnp.asarray(u))
        return np.asarray(wi), np.asarray(pdf)

    def pdf(wi):
        return np.asarray(_pdf(model, jnp.asarray(wi)))

    return sample, pdf


def check_chi2_jit(model, theta_o_deg, n_tests: int, drop_delta: bool = False, **kw) -> None:
    """Like ``model_checks.check_chi2`` (phi_o = 0.3, >= 1e6 samples) with jitted sampling."""
    for t in theta_o_deg:
        wo = np.asarray(frames.spherical_to_direction(np.radians(t), 0.3))
        sample, pdf = jit_sampler(model, wo, drop_delta)
        r = chi2_test(sample, pdf, n_samples=kw.pop("n_samples", 1_000_000), n_tests=n_tests, **kw)
        assert r.passed, f"{model!r} at theta_o={t} deg: {r.message}"


def albedo_jit(model, wo, n: int = 128) -> np.ndarray:
    """``model.directional_albedo(wo, n)`` evaluated under ``jax.jit``."""
    return np.asarray(jax.jit(lambda m, w: m.directional_albedo(w, n=n))(model, jnp.asarray(wo)))


def check_param_gradients_jit(model) -> None:
    """``model_checks.check_param_gradients`` with the loss and its gradient jitted."""
    from tests.brdf.model_checks import stress_directions

    d = stress_directions()
    wi = jnp.asarray(np.repeat(d, len(d), axis=0))
    wo = jnp.asarray(np.tile(d, (len(d), 1)))
    u = jnp.asarray(np.random.default_rng(0).random((wi.shape[0], 2)))

    @jax.jit
    def grads(params):
        def loss(p):
            m = model.replace(**p)
            s = m.sample(wo, u)
            return (
                jnp.sum(m.f(wi, wo)) + jnp.sum(m.pdf(wi, wo)) + jnp.sum(s.weight) + jnp.sum(s.pdf)
            )

        return jax.grad(loss)(params)

    for name, g in grads(model.params()).items():
        assert np.all(np.isfinite(np.asarray(g))), f"{model!r}: non-finite gradient w.r.t. {name}"


class Jitted:
    """A model whose ``f``, ``pdf`` and ``sample`` run under ``jax.jit`` (one compile per input
    shape instead of op-by-op dispatch), for the ``model_checks`` property checks."""

    def __init__(self, model) -> None:
        self.model = model
        self.channels = model.channels
        self._f = jax.jit(lambda m, wi, wo: m.f(wi, wo))
        self._pdf = jax.jit(lambda m, wi, wo: m.pdf(wi, wo))
        self._sample = jax.jit(lambda m, wo, u: m.sample(wo, u))

    def f(self, wi, wo):
        return self._f(self.model, jnp.asarray(wi), jnp.asarray(wo))

    def pdf(self, wi, wo):
        return self._pdf(self.model, jnp.asarray(wi), jnp.asarray(wo))

    def sample(self, wo, u):
        return self._sample(self.model, jnp.asarray(wo), jnp.asarray(u))

    def __repr__(self) -> str:
        return repr(self.model)
