"""Helpers shared by the zoo model tests (Lafortune, Ashikhmin-Shirley, HTSG, Ngan)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf import frames
from gonio.brdf.chi2 import chi2_test
from tests.brdf import model_checks
from tests.brdf.model_checks import check_param_gradients


def jit_sampler(model, wo, drop_delta: bool = False):
    """``model_sampler`` with jitted sample and pdf (the eager path is slow for 1e6 samples).

    With ``drop_delta`` delta samples are reported as failed (pdf 0): the chi-square test then
    expects exactly the missing mass ``1 - integral of pdf`` to be lost, which checks the delta
    lobe's selection probability too. The model and ``wo`` are arguments of the jitted functions,
    so every ``theta_o`` of a model (and models of one class and shape) share their compiles.
    """
    wo = jnp.asarray(wo, jnp.float64)

    def sample(u):
        wi, pdf = _jit_sampler_sample(model, wo, jnp.asarray(u), drop_delta)
        return np.asarray(wi), np.asarray(pdf)

    def pdf(wi):
        return np.asarray(_jit_sampler_pdf(model, jnp.asarray(wi), wo))

    return sample, pdf


@functools.partial(jax.jit, static_argnums=3)
def _jit_sampler_sample(m, wo, u, drop_delta):
    s = m.sample(wo, u)
    pdf = jnp.where(s.delta, 0.0, s.pdf) if drop_delta else s.pdf
    return s.wi, pdf


_jit_sampler_pdf = jax.jit(lambda m, wi, wo: m.pdf(wi, wo))


def check_chi2_jit(model, theta_o_deg, n_tests: int, drop_delta: bool = False, **kw) -> None:
    """Like ``model_checks.check_chi2`` (phi_o = 0.3, the same grid) with jitted sampling."""
    kw = model_checks.chi2_kwargs(kw)
    for t in theta_o_deg:
        wo = np.asarray(frames.spherical_to_direction(np.radians(t), 0.3))
        sample, pdf = jit_sampler(model, wo, drop_delta)
        r = chi2_test(sample, pdf, n_tests=n_tests, **kw)
        assert r.passed, f"{model!r} at theta_o={t} deg: {r.message}"


def albedo_jit(model, wo, n: int = 128) -> np.ndarray:
    """``model.directional_albedo(wo, n)`` evaluated under ``jax.jit``."""
    return np.asarray(_jit_albedo(model, jnp.asarray(wo), n))


_jit_albedo = jax.jit(lambda m, w, n: m.directional_albedo(w, n=n), static_argnums=2)


def check_param_gradients_jit(model) -> None:
    """``model_checks.check_param_gradients`` (the loss and its gradient jitted, the model an
    argument: models of one class and shape share the compile)."""
    check_param_gradients(model)


#: ``f``, ``pdf`` and ``sample`` under ``jax.jit`` with the model an argument and the rows padded
#: to a few fixed counts, so that one compile per class and shape serves every check and test.
Jitted = model_checks.Jitted
