"""A small specular lobe used to develop and test the fitter independently of the model workers.

It is a normalized modified-Phong lobe ``rho_s (n + 2) / (2 pi) max(0, r.wi)^n`` with
``r = reflect(wo)``; only ``_f`` matters for fitting (sampling is the cosine hemisphere).
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.models import BRDFModel, Param
from gonio.brdf.models._base import channel_mean
from gonio.brdf.sampling import warps


class TestLobe(BRDFModel):
    PARAMS = (
        Param("rho_s", 0.3, 0.0, 1.0, "1", per_channel=True, scale="logit", doc="specular"),
        Param("n", 20.0, 1.0, 1e4, "1", scale="log", doc="exponent"),
    )
    __test__ = False

    def __init__(self, rho_s=0.3, n=20.0):
        self._set_params(rho_s=rho_s, n=n)

    def _f(self, wi, wo):
        r = wo * jnp.array([-1.0, -1.0, 1.0], wo.dtype)
        c = jnp.clip(jnp.sum(r * wi, -1, keepdims=True), 0.0, 1.0)
        n = jnp.asarray(self.n, wi.dtype)
        rho = jnp.atleast_1d(self.rho_s).astype(wi.dtype)
        # c**n with c = 0 has an infinite derivative in n; exp(n log c) with a floor is finite.
        lobe = jnp.exp(n * jnp.log(jnp.maximum(c, 1e-30)))
        return rho * (n + 2) / (2 * jnp.pi) * lobe

    def _pdf(self, wi, wo):
        return warps.cosine_hemisphere_pdf(wi)

    def _sample(self, wo, u):
        return warps.square_to_cosine_hemisphere(u)

    def sampling_weight(self, wo):
        return jnp.broadcast_to(channel_mean(self.rho_s).astype(wo.dtype), wo.shape[:-1])
