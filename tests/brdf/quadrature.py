"""Deterministic hemisphere quadrature for energy checks that must not rely on a model's sampler.

The directional albedo from ``model.directional_albedo`` uses the model's own importance
sampler; these helpers integrate ``f cos`` with Gauss-Legendre cells instead (the cell rule of
:func:`gonio.brdf.chi2.integrate_pdf_cells`), so a wrong sampler cannot hide a wrong albedo.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf import frames
from gonio.brdf.chi2 import integrate_pdf_cells


def direction(theta_deg: float, phi: float = 0.0) -> np.ndarray:
    """Unit vector for a polar angle in degrees and an azimuth in radians, ``(3,)``."""
    return np.asarray(frames.spherical_to_direction(np.radians(theta_deg), phi))


def albedo_quadrature(
    model, wo: np.ndarray, res_theta: int = 90, res_phi: int = 180, order: int = 8
) -> np.ndarray:
    """``int f(wi, wo) cos(theta_i) dwi`` per channel, ``(C,)``, by cell-wise Gauss-Legendre.

    Cell edges lie on multiples of ``90/res_theta`` degrees in theta and ``360/res_phi`` in phi;
    put kinks of the integrand (``theta_i = theta_o``, the horizon) on edges for full accuracy.
    """
    wo = np.asarray(wo, dtype=np.float64)
    model = model if isinstance(model, jitted) else jitted(model)
    out = []
    for c in range(model.channels):

        def integrand(wi, c=c):
            return np.asarray(model.f(wi, wo))[:, c] * wi[:, 2]

        out.append(integrate_pdf_cells(integrand, res_theta, res_phi, order=order).sum())
    return np.asarray(out)


def pdf_integral(model, wo: np.ndarray, res_theta: int = 90, res_phi: int = 180, order: int = 8):
    """``int pdf(wi, wo) dwi`` over the upper hemisphere by the same quadrature."""
    wo = np.asarray(wo, dtype=np.float64)
    model = model if isinstance(model, jitted) else jitted(model)
    return float(
        integrate_pdf_cells(
            lambda wi: np.asarray(model.pdf(wi, wo)), res_theta, res_phi, order=order
        ).sum()
    )


class jitted:
    """A model whose ``sample``/``pdf``/``f`` run through ``jax.jit`` (the model is a pytree
    argument, so one compilation serves every parameter value). Chi-square tests draw 1e6
    samples; eager dispatch makes them several times slower."""

    _sample = staticmethod(jax.jit(lambda m, wo, u: m.sample(wo, u)))
    _pdf = staticmethod(jax.jit(lambda m, wi, wo: m.pdf(wi, wo)))
    _f = staticmethod(jax.jit(lambda m, wi, wo: m.f(wi, wo)))
    _albedo = staticmethod(jax.jit(lambda m, wo, n: m.directional_albedo(wo, n), static_argnums=2))

    def __init__(self, model) -> None:
        self.model = model
        self.channels = model.channels

    def sample(self, wo, u):
        return self._sample(self.model, jnp.asarray(wo), jnp.asarray(u))

    def pdf(self, wi, wo):
        return self._pdf(self.model, jnp.asarray(wi), jnp.asarray(wo))

    def f(self, wi, wo):
        return self._f(self.model, jnp.asarray(wi), jnp.asarray(wo))

    def directional_albedo(self, wo, n: int = 128):
        return self._albedo(self.model, jnp.asarray(wo), n)

    def __repr__(self) -> str:
        return repr(self.model)


#: Histogram for sharp half-vector lobes at grazing ``wo``: reflecting about a half vector near
#: the normal compresses the lobe sideways by ``2 cos(theta_o)`` (0.17 at 85 deg), to a fraction
#: of a default 2-degree azimuth cell, where the cell quadrature would lose accuracy.
SHARP_CHI2 = {"res_theta": 180, "res_phi": 2880, "order": 4}
