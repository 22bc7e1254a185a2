"""Normalized Blinn-Phong reflection (Blinn 1977): a cosine-power lobe of the half vector."""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import dot, safe_div, safe_sqrt
from gonio.brdf.models._base import BRDFModel, Param, channel_mean
from gonio.brdf.models._lobes import (
    DiffusePlusLobe,
    lobe_probabilities,
    pow_one_minus,
    power_lobe_local,
)
from gonio.brdf.sampling import warps

Array = jnp.ndarray


def blinn_phong_norm(n: Array) -> Array:
    """``K(n) = (n + 2)(n + 4) / (8 pi (2^(-n/2) + n))``: the factor that makes
    ``int K cos^n(theta_h) cos(theta_i) dwi = 1`` for ``wo`` on the normal (exact, for every
    ``n >= 0``; Giesen 2009, "Derivation of Phong and Blinn-Phong BRDF normalization factors").
    ``K(0) = 1/pi`` (Lambert); ``K(n) ~ (n + 6)/(8 pi)`` for large ``n``."""
    return (n + 2.0) * (n + 4.0) / (8.0 * jnp.pi * (jnp.exp(-0.5 * jnp.log(2.0) * n) + n))


class BlinnPhong(DiffusePlusLobe, BRDFModel):
    """``f = rho_d/pi + rho_s K(n) cos^n(theta_h)``, ``theta_h`` the polar angle of the half
    vector ``h = (wi + wo)/|wi + wo|``, with the normalization
    ``K(n) = (n + 2)(n + 4) / (8 pi (2^(-n/2) + n))`` (see :func:`blinn_phong_norm`), chosen so
    that the specular lobe reflects exactly ``rho_s`` of the light arriving along the normal.

    Sampling: a mixture chosen with probabilities proportional to ``mean(rho_d)`` and
    ``mean(rho_s)``; cosine-weighted for the diffuse part; for the lobe, ``h`` is drawn with
    density ``p_h = (n + 1)/(2 pi) cos^n(theta_h)`` about the normal and ``wi`` is the reflection
    of ``wo`` about ``h``, so ``p(wi) = p_h / (4 wo.h)`` (``wo.h = |wi + wo|/2``). Half vectors
    with ``wo.h <= 0`` reflect below the horizon and are failed samples.

    Numerics: ``1 - cos(theta_h) = (H_x^2 + H_y^2) / (|H| (|H| + H_z))`` with ``H = wi + wo``
    (no cancellation) and ``cos^n = exp(n log1p(-(1 - cos)))``: exponents up to 1e5 stay
    accurate in float32 and ``K(1e5) = 4e3`` is far from overflow.

    Energy (``tests/brdf/test_blinn_phong.py``): the specular albedo is ``rho_s`` at normal
    incidence and decreases towards grazing (about ``rho_s cos^2(theta_o)`` for sharp lobes,
    since ``cos(theta_i)`` and ``4 wo.h`` both shrink); the total stays <= ``rho_d + rho_s``,
    so energy is conserved whenever ``rho_d + rho_s <= 1`` (the bounds do not impose the sum).

    Parameters
    ----------
    rho_d : diffuse reflectance in [0, 1], scalar or per channel (dimensionless).
    rho_s : specular reflectance in [0, 1] (albedo of the lobe at normal incidence), scalar or
        per channel (dimensionless).
    n : exponent of the half-vector cosine in [0, 1e5] (dimensionless); roughly
        ``2/alpha^2 - 2`` for a Beckmann roughness ``alpha``.
    """

    PARAMS = (
        Param("rho_d", 0.2, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="diffuse reflectance"),
        Param("rho_s", 0.5, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="specular reflectance (albedo of the lobe at normal incidence)"),
        Param("n", 50.0, 0.0, 1e5, "1", scale="log", doc="half-vector cosine exponent"),
    )  # fmt: skip

    def __init__(
        self,
        rho_d: Array | float = 0.2,
        rho_s: Array | float = 0.5,
        n: Array | float = 50.0,
    ) -> None:
        self._set_params(rho_d=rho_d, rho_s=rho_s, n=n)

    @staticmethod
    def _half(wi: Array, wo: Array) -> tuple[Array, Array]:
        """``(1 - cos theta_h, |wi + wo|)``."""
        h = wi + wo
        hxy2 = h[..., 0] ** 2 + h[..., 1] ** 2
        norm = safe_sqrt(dot(h, h))
        one_minus = safe_div(hxy2, norm * (norm + jnp.abs(h[..., 2])))
        # A half vector below the horizon (only for wi below, which the caller masks) is out.
        one_minus = jnp.where(h[..., 2] > 0, one_minus, 1.0)
        return one_minus, norm

    def _f(self, wi: Array, wo: Array) -> Array:
        dt = wi.dtype
        rd = jnp.atleast_1d(self.rho_d).astype(dt)
        rs = jnp.atleast_1d(self.rho_s).astype(dt)
        n = jnp.asarray(self.n).astype(dt)
        one_minus, _ = self._half(wi, wo)
        spec = blinn_phong_norm(n) * pow_one_minus(one_minus, n)
        return rd / jnp.pi + rs * spec[..., None]

    def _weights(self, wo: Array) -> list[Array]:
        dt = wo.dtype
        return [channel_mean(self.rho_d).astype(dt), channel_mean(self.rho_s).astype(dt)]

    def _pdf(self, wi: Array, wo: Array) -> Array:
        n = jnp.asarray(self.n).astype(wi.dtype)
        p_d, p_s = lobe_probabilities(wi.shape[:-1], wi.dtype, self._weights(wo))
        one_minus, norm = self._half(wi, wo)
        p_h = (n + 1.0) / (2.0 * jnp.pi) * pow_one_minus(one_minus, n)
        return p_d * warps.cosine_hemisphere_pdf(wi) + p_s * safe_div(p_h, 2.0 * norm)

    def _sample_lobe(self, wo: Array, u: Array) -> Array:
        n = jnp.asarray(self.n).astype(wo.dtype)
        h = power_lobe_local(u, n)
        return 2.0 * dot(wo, h)[..., None] * h - wo
