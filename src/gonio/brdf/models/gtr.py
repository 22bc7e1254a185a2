"""A microfacet lobe with the long-tailed GTR distribution of normals (Burley 2012)."""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import dot, normalize, reflect, safe_sqrt
from gonio.brdf.models import microfacet as mf
from gonio.brdf.models._base import BRDFModel, Param, channel_mean

Array = jnp.ndarray


def _log_norm(a: Array, gamma: Array) -> Array:
    """``log c`` of ``D = c / (a cos^2 + sin^2)^gamma`` normalized as ``int D cos dh = 1``:
    ``c = (gamma - 1)(1 - a) / (pi (a^(1 - gamma) - 1))`` written with ``z = (gamma - 1)(-ln a)``
    as ``ln(gamma - 1) + ln(1 - a) - ln pi - z - ln(1 - e^-z)`` (no overflow for small ``a``)."""
    z = (gamma - 1.0) * (-jnp.log(a))
    return jnp.log(gamma - 1.0) + jnp.log1p(-a) - jnp.log(jnp.pi) - z - jnp.log(-jnp.expm1(-z))


def gtr_ndf(h: Array, alpha: Array, gamma: Array) -> Array:
    """GTR normal density ``D(h)`` in sr^-1, shape ``(...)``; 0 where ``h_z <= 0``.

    ``D = c / (alpha^2 cos^2 theta_h + sin^2 theta_h)^gamma`` with ``c`` such that
    ``int D(h) cos(theta_h) dh = 1``; ``gamma = 2`` is GGX, smaller ``gamma`` a longer tail.
    """
    a = jnp.square(jnp.asarray(alpha).astype(h.dtype))
    g = jnp.asarray(gamma).astype(h.dtype)
    t = h[..., 0] ** 2 + h[..., 1] ** 2 + a * h[..., 2] ** 2
    d = jnp.exp(_log_norm(a, g) - g * jnp.log(jnp.maximum(t, 1e-30)))
    return jnp.where(h[..., 2] > 0, d, 0.0)


def sample_gtr(u: Array, alpha: Array, gamma: Array) -> Array:
    """Half vectors with density ``D(h) cos(theta_h)`` (Burley 2012, appendix B), ``(..., 3)``.

    With ``t = a cos^2 + sin^2`` (``a = alpha^2``) the CDF inverts to
    ``t^(1 - gamma) = a^(1 - gamma) (1 - u0) + u0``, evaluated in logarithms.
    """
    a = jnp.square(jnp.asarray(alpha).astype(u.dtype))
    g = jnp.asarray(gamma).astype(u.dtype)
    u0 = jnp.clip(u[..., 0], 1e-12, 1.0 - 1e-7)
    z = (g - 1.0) * (-jnp.log(a))
    log_t = jnp.logaddexp(z + jnp.log1p(-u0), jnp.log(u0)) / (1.0 - g)
    # sin^2 = (t - a) / (1 - a), computed as a (t / a - 1) without cancellation near the peak
    s2 = jnp.clip(a * jnp.expm1(log_t - jnp.log(a)) / (1.0 - a), 0.0, 1.0)
    s = safe_sqrt(s2)
    phi = 2.0 * jnp.pi * u[..., 1]
    return jnp.stack([s * jnp.cos(phi), s * jnp.sin(phi), safe_sqrt(1.0 - s2)], -1)


class GTR(BRDFModel):
    """Microfacet lobe ``f = rho_s D_GTR(h) G(wi, wo) F(wi.h) / (4 cos_i cos_o)`` (no diffuse).

    ``D_GTR`` is Burley's (2012) generalized Trowbridge-Reitz distribution
    ``c / (alpha^2 cos^2 theta_h + sin^2 theta_h)^gamma``, normalized so that
    ``int D cos theta_h dh = 1`` (see :func:`gtr_ndf`): the tail exponent ``gamma`` is free, so
    the lobe can hold the slowly falling, long tails of real highlights (metals, metallic paints)
    that a Beckmann or Ward lobe, whose tail falls like a Gaussian, puts into a diffuse floor.
    ``gamma = 2`` is GGX. ``G`` is the V-cavity shadowing of Torrance-Sparrow (independent of
    ``alpha`` and ``gamma``, see :mod:`.microfacet`); ``F = f0 + (1 - f0)(1 - wi.h)^5``
    (Schlick) with one ``f0`` for every channel; the colour of the lobe is the per-channel
    ``rho_s``, which can take the lobe to 0 (a Schlick term alone cannot: its grazing rise
    stays), so a family with this lobe nests the family without it.

    Energy: ``D`` is normalized, ``G <= 1`` and ``F <= 1``, so the directional albedo is at most
    ``rho_s <= 1`` (the shadowed part and the part below the horizon are lost).

    Sampling: half vectors from ``D cos theta_h`` (closed-form inversion, :func:`sample_gtr`),
    reflected about; ``pdf = D cos theta_h / (4 wo.h)`` over ``wi``. Samples below the horizon
    fail.

    Parameters
    ----------
    rho_s : specular albedo factor per channel in [0, 1] (dimensionless).
    alpha : width in [1e-3, 0.95] (dimensionless; the GGX roughness at ``gamma = 2``). Fitted on
        a log scale.
    gamma : tail exponent in [1.001, 10] (dimensionless): near 1 the heaviest tail, 2 GGX,
        larger values a faster fall-off (and a narrower lobe at the same ``alpha``).
    f0 : Schlick reflectance at normal incidence in [0, 1], shared by the channels
        (dimensionless; 1: no Fresnel rise, as for a metal).
    """

    PARAMS = (
        Param("rho_s", 0.5, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="specular albedo factor (the lobe's colour)"),
        Param("alpha", 0.2, 1e-3, 0.95, "1", scale="log", doc="GTR width (GGX alpha at gamma=2)"),
        Param("gamma", 2.0, 1.001, 10.0, "1", scale="log", doc="GTR tail exponent, 2: GGX"),
        Param("f0", 0.5, 0.0, 1.0, "1", scale="logit", doc="Schlick reflectance at normal "
              "incidence"),
    )  # fmt: skip

    def __init__(
        self,
        rho_s: Array | float = 0.5,
        alpha: Array | float = 0.2,
        gamma: Array | float = 2.0,
        f0: Array | float = 0.5,
    ) -> None:
        self._set_params(rho_s=rho_s, alpha=alpha, gamma=gamma, f0=f0)

    def _fresnel(self, c: Array) -> Array:
        f0 = jnp.asarray(self.f0).astype(c.dtype)
        m = 1.0 - jnp.clip(c, 0.0, 1.0)
        m2 = m * m
        return f0 + (1.0 - f0) * (m2 * m2 * m)

    def _f(self, wi: Array, wo: Array) -> Array:
        h = normalize(wi + wo)
        d = gtr_ndf(h, self.alpha, self.gamma)
        v = mf.visibility(wi, wo, h, self.alpha, "ggx", "vcavity")
        rho = jnp.atleast_1d(self.rho_s).astype(wi.dtype)
        return rho * (d * v * self._fresnel(dot(wi, h)))[..., None]

    def _pdf(self, wi: Array, wo: Array) -> Array:
        h = normalize(wi + wo)
        oh = jnp.maximum(dot(wo, h), 1e-30)
        return gtr_ndf(h, self.alpha, self.gamma) * jnp.maximum(h[..., 2], 0.0) / (4.0 * oh)

    def _sample(self, wo: Array, u: Array) -> Array:
        return reflect(wo, sample_gtr(u, self.alpha, self.gamma))

    def sampling_weight(self, wo: Array) -> Array:
        rho = channel_mean(self.rho_s).astype(wo.dtype)
        return rho * self._fresnel(wo[..., 2])
