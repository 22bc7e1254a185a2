"""Lambertian (ideal diffuse) reflection."""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.models._base import BRDFModel, Param, channel_mean
from gonio.brdf.sampling import warps

Array = jnp.ndarray


class Lambert(BRDFModel):
    """``f = albedo / pi``; sampled cosine-weighted (pdf ``cos(theta_i) / pi``).

    Parameters
    ----------
    albedo : reflectance in [0, 1], scalar or one value per channel (dimensionless).
    """

    PARAMS = (
        Param("albedo", 0.5, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="diffuse reflectance (hemispherical-directional)"),
    )  # fmt: skip

    def __init__(self, albedo: Array | float = 0.5) -> None:
        self._set_params(albedo=albedo)

    def _f(self, wi: Array, wo: Array) -> Array:
        a = jnp.atleast_1d(self.albedo).astype(wi.dtype)
        return jnp.broadcast_to(a / jnp.pi, (*wi.shape[:-1], a.shape[-1]))

    def _pdf(self, wi: Array, wo: Array) -> Array:
        return warps.cosine_hemisphere_pdf(wi)

    def _sample(self, wo: Array, u: Array) -> Array:
        return warps.square_to_cosine_hemisphere(u)

    def sampling_weight(self, wo: Array) -> Array:
        return jnp.broadcast_to(channel_mean(self.albedo).astype(wo.dtype), wo.shape[:-1])
