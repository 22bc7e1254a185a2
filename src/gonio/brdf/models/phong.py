"""Modified, normalized Phong reflection (Lewis 1994; Lafortune & Willems 1994)."""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import dot, reflect
from gonio.brdf.models._base import BRDFModel, Param, channel_mean
from gonio.brdf.models._lobes import (
    DiffusePlusLobe,
    frame_about,
    lobe_probabilities,
    pow_one_minus,
    power_lobe_local,
)
from gonio.brdf.sampling import warps

Array = jnp.ndarray


class Phong(DiffusePlusLobe, BRDFModel):
    """``f = rho_d/pi + rho_s (n + 2)/(2 pi) cos^n(a)``, ``a`` = angle between ``wi`` and the
    mirror direction of ``wo``. The lobe ends where ``a`` reaches 90 degrees (``cos^n`` is 0
    beyond, also for ``n = 0``, where the lobe is a hemisphere about the mirror direction).

    Sampling: a two-lobe mixture chosen with probabilities proportional to ``mean(rho_d)`` and
    ``mean(rho_s)``: cosine-weighted for the diffuse part, and for the specular part directions
    about the mirror direction with density ``(n + 1)/(2 pi) cos^n(a)`` (the part of that lobe
    below the horizon is a failed sample). ``pdf`` is the matching mixture.

    Numerics: ``1 - cos(a) = |wi - r|^2 / 2`` with ``r`` the mirror direction, and
    ``cos^n = exp(n log1p(-(1 - cos)))``, so exponents up to 1e5 keep their precision in
    float32 and nothing overflows (the peak value is ``rho_s (n + 2)/(2 pi)``, 1.6e4 at 1e5).

    Energy: the specular directional albedo is exactly ``rho_s`` at normal incidence and smaller
    elsewhere (part of the lobe falls below the horizon and is weighted by a smaller cosine), so
    the albedo stays <= ``rho_d + rho_s``; energy is conserved whenever ``rho_d + rho_s <= 1``.
    The parameter bounds ([0, 1] each) do not impose that sum; ``tests/brdf/test_phong.py``
    checks both the bound and its tightness at normal incidence.

    Parameters
    ----------
    rho_d : diffuse reflectance in [0, 1], scalar or per channel (dimensionless).
    rho_s : specular reflectance in [0, 1], scalar or per channel (dimensionless).
    n : Phong exponent in [0, 1e5] (dimensionless); roughly ``2/alpha^2 - 2`` for a microfacet
        roughness ``alpha``.
    """

    PARAMS = (
        Param("rho_d", 0.2, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="diffuse reflectance"),
        Param("rho_s", 0.5, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="specular reflectance (albedo of the lobe at normal incidence)"),
        Param("n", 50.0, 0.0, 1e5, "1", scale="log", doc="Phong exponent (lobe sharpness)"),
    )  # fmt: skip

    def __init__(
        self,
        rho_d: Array | float = 0.2,
        rho_s: Array | float = 0.5,
        n: Array | float = 50.0,
    ) -> None:
        self._set_params(rho_d=rho_d, rho_s=rho_s, n=n)

    def _lobe(self, wi: Array, wo: Array, n: Array) -> Array:
        d = wi - reflect(wo)
        return pow_one_minus(0.5 * dot(d, d), n)

    def _f(self, wi: Array, wo: Array) -> Array:
        dt = wi.dtype
        rd = jnp.atleast_1d(self.rho_d).astype(dt)
        rs = jnp.atleast_1d(self.rho_s).astype(dt)
        n = jnp.asarray(self.n).astype(dt)
        spec = (n + 2.0) / (2.0 * jnp.pi) * self._lobe(wi, wo, n)
        return rd / jnp.pi + rs * spec[..., None]

    def _weights(self, wo: Array) -> list[Array]:
        return [
            channel_mean(self.rho_d).astype(wo.dtype),
            channel_mean(self.rho_s).astype(wo.dtype),
        ]

    def _pdf(self, wi: Array, wo: Array) -> Array:
        n = jnp.asarray(self.n).astype(wi.dtype)
        p_d, p_s = lobe_probabilities(wi.shape[:-1], wi.dtype, self._weights(wo))
        spec = (n + 1.0) / (2.0 * jnp.pi) * self._lobe(wi, wo, n)
        return p_d * warps.cosine_hemisphere_pdf(wi) + p_s * spec

    def _sample_lobe(self, wo: Array, u: Array) -> Array:
        n = jnp.asarray(self.n).astype(wo.dtype)
        r = reflect(wo)
        t, b = frame_about(r)
        loc = power_lobe_local(u, n)
        return loc[..., 0:1] * t + loc[..., 1:2] * b + loc[..., 2:3] * r
