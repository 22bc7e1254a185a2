"""A retro-reflective cosine-power lobe about the direction of the light."""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import dot
from gonio.brdf.models._base import BRDFModel, Param, channel_mean
from gonio.brdf.models._lobes import frame_about, pow_one_minus, power_lobe_local

Array = jnp.ndarray


class Retroreflection(BRDFModel):
    """``f = rho_r (n + 2)/(2 pi) cos^n(b)``, ``b`` = angle between ``wi`` and ``wo``.

    The modified Phong lobe (Lafortune & Willems 1994) turned back toward the light: its peak
    is where the viewer looks along the light (``wi = wo``), the back-scattering of retro-
    reflective tapes and paints (glass beads, corner cubes) and, broad, of rough and porous
    surfaces. It is a Lafortune lobe with ``C_x = C_y = C_z = 1`` (Lafortune et al. 1997).

    Energy: at normal ``wo`` the directional albedo is exactly ``rho_r``; elsewhere part of the
    lobe lies below the horizon and the rest is weighted by smaller cosines, so it stays
    ``<= rho_r`` (``tests/brdf/test_retro.py`` checks both).

    Sampling: directions about ``wo`` with density ``(n + 1)/(2 pi) cos^n(b)``; the part of the
    lobe below the horizon is a failed sample.

    Numerics: ``1 - cos(b) = |wi - wo|^2 / 2`` (no cancellation near the peak), as in
    :class:`~.phong.Phong`.

    Parameters
    ----------
    rho_r : albedo of the lobe at normal incidence, in [0, 1], scalar or per channel
        (dimensionless).
    n : exponent in [0, 1e4] (dimensionless): 0 a hemisphere about ``wo``, large a narrow peak
        (half width about ``sqrt(2 ln 2 / n)`` radians).
    """

    PARAMS = (
        Param("rho_r", 0.1, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="retro-reflective albedo at normal incidence"),
        Param("n", 10.0, 0.0, 1e4, "1", scale="log", doc="exponent (lobe sharpness)"),
    )  # fmt: skip

    def __init__(self, rho_r: Array | float = 0.1, n: Array | float = 10.0) -> None:
        self._set_params(rho_r=rho_r, n=n)

    def _lobe(self, wi: Array, wo: Array, n: Array) -> Array:
        d = wi - wo
        return pow_one_minus(0.5 * dot(d, d), n)

    def _f(self, wi: Array, wo: Array) -> Array:
        dt = wi.dtype
        rho = jnp.atleast_1d(self.rho_r).astype(dt)
        n = jnp.asarray(self.n).astype(dt)
        return rho * ((n + 2.0) / (2.0 * jnp.pi) * self._lobe(wi, wo, n))[..., None]

    def _pdf(self, wi: Array, wo: Array) -> Array:
        n = jnp.asarray(self.n).astype(wi.dtype)
        return (n + 1.0) / (2.0 * jnp.pi) * self._lobe(wi, wo, n)

    def _sample(self, wo: Array, u: Array) -> Array:
        n = jnp.asarray(self.n).astype(wo.dtype)
        t, b = frame_about(wo)
        loc = power_lobe_local(u, n)
        return loc[..., 0:1] * t + loc[..., 1:2] * b + loc[..., 2:3] * wo

    def sampling_weight(self, wo: Array) -> Array:
        return jnp.broadcast_to(channel_mean(self.rho_r).astype(wo.dtype), wo.shape[:-1])
