"""Oren-Nayar rough diffuse reflection (the qualitative model of Oren & Nayar 1994)."""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import safe_sqrt
from gonio.brdf.models._base import BRDFModel, Param, channel_mean
from gonio.brdf.sampling import warps

Array = jnp.ndarray


class OrenNayar(BRDFModel):
    """Qualitative Oren-Nayar model; sampled cosine-weighted (pdf ``cos(theta_i) / pi``).

    ``f = albedo/pi (A + B max(0, cos(phi_i - phi_o)) sin(alpha) tan(beta))`` with
    ``A = 1 - 0.5 s^2/(s^2 + 0.33)``, ``B = 0.45 s^2/(s^2 + 0.09)``, ``s = sigma``,
    ``alpha = max(theta_i, theta_o)``, ``beta = min(theta_i, theta_o)``.

    The angular factor is evaluated without angles: since
    ``cos(phi_i - phi_o) sin(theta_i) sin(theta_o) = wi_x wo_x + wi_y wo_y`` and the larger polar
    angle has the smaller cosine,
    ``cos(dphi) sin(alpha) tan(beta) = (wi_xy . wo_xy) / max(cos theta_i, cos theta_o)``.
    That is exact, symmetric in ``wi``/``wo`` (reciprocal), and defined at the pole where ``phi``
    is not; it grows like ``1/cos`` only when both directions graze (where ``f cos`` stays
    bounded by ``albedo (A + B) / pi``). At ``sigma = 0`` (``A = 1``, ``B = 0``) it is exactly
    Lambert.

    Energy: with ``albedo = 1`` the directional albedo is exactly ``A + B g(theta_o)`` with
    ``g = (2 sin t / pi) [(1 - sin^3 t)/(3 cos t) + t/2 - sin(2t)/4]``, ``t = theta_o`` (the
    integral of the angular factor against ``cos(theta_i)/pi``); ``g`` rises from 0 at normal
    incidence to 1/2 at grazing. Hence albedo <= 1 everywhere for ``sigma >= 0.326`` rad
    (``sigma^2 >= 0.1064``), while for ``0 < sigma < 0.326`` it exceeds 1 at grazing outgoing
    angles, by at most about 1.5 % (``sigma ~ 0.2``, ``theta_o -> 90 deg``; at ``sigma = 0.2``
    from ``theta_o ~ 76 deg`` on). This is a property of the qualitative approximation, not of
    rough diffuse surfaces; ``tests/brdf/test_oren_nayar.py`` checks both statements by
    quadrature.

    Parameters
    ----------
    albedo : diffuse reflectance in [0, 1], scalar or one value per channel (dimensionless).
    sigma : surface roughness, the standard deviation of the facet slope angle, in radians,
        in [0, pi/2].
    """

    PARAMS = (
        Param("albedo", 0.5, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="diffuse reflectance"),
        Param("sigma", 0.3, 0.0, float(jnp.pi / 2), "rad", scale="log",
              doc="standard deviation of the facet slope angle"),
    )  # fmt: skip

    def __init__(self, albedo: Array | float = 0.5, sigma: Array | float = 0.3) -> None:
        self._set_params(albedo=albedo, sigma=sigma)

    def _ab(self, dtype) -> tuple[Array, Array]:
        s2 = jnp.square(jnp.asarray(self.sigma).astype(dtype))
        a = 1.0 - 0.5 * s2 / (s2 + 0.33)
        b = 0.45 * s2 / (s2 + 0.09)
        return a, b

    def _f(self, wi: Array, wo: Array) -> Array:
        alb = jnp.atleast_1d(self.albedo).astype(wi.dtype)
        a, b = self._ab(wi.dtype)
        dot_xy = wi[..., 0] * wo[..., 0] + wi[..., 1] * wo[..., 1]
        # Both cosines are > 0 here (the caller replaced masked directions by the normal).
        g = jnp.maximum(dot_xy, 0.0) / jnp.maximum(wi[..., 2], wo[..., 2])
        return (alb / jnp.pi) * (a + b * g)[..., None]

    def _pdf(self, wi: Array, wo: Array) -> Array:
        return warps.cosine_hemisphere_pdf(wi)

    def _sample(self, wo: Array, u: Array) -> Array:
        return warps.square_to_cosine_hemisphere(u)

    def sampling_weight(self, wo: Array) -> Array:
        # The exact directional albedo (class docstring), with (1 - s^3)/(3c) rewritten as
        # c (1 + s + s^2) / (3 (1 + s)) so that it stays finite at grazing.
        a, b = self._ab(wo.dtype)
        c = jnp.clip(wo[..., 2], 0.0, 1.0)
        s = safe_sqrt(1.0 - c * c)
        t = jnp.arctan2(s, c)
        g = (2.0 * s / jnp.pi) * (c * (1.0 + s + s * s) / (3.0 * (1.0 + s)) + 0.5 * t - 0.5 * s * c)
        return channel_mean(self.albedo).astype(wo.dtype) * (a + b * g)
