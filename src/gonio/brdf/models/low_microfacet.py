"""The microfacet model of Löw, Kronander, Ynnerman & Unger (2012) with its ABC distribution.

Löw, Kronander, Ynnerman, Unger, "BRDF models for accurate and efficient rendering of glossy
surfaces", ACM Trans. Graph. 31(1), 2012, section 5 (the microfacet variant; the ABC form
``S(f) = A / (1 + B f^2)^C`` replaces the distribution of normals, with ``f^2 = 1 - cos theta_h``).
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import dot, normalize, safe_div
from gonio.brdf.models import microfacet as mf
from gonio.brdf.models._base import BRDFModel, Param, channel_mean
from gonio.brdf.models._lobes import pow_one_minus, power_lobe_local
from gonio.brdf.models.blinn_phong import BlinnPhong
from gonio.brdf.models.fresnel import dielectric_reflectance

Array = jnp.ndarray


class LowMicrofacet(BRDFModel):
    """``f = A F(wi.h) G(wi, wo) / (pi (1 + B (1 - cos theta_h))^C cos_i cos_o)`` (specular).

    ``F`` is the exact unpolarized Fresnel reflectance of a dielectric of index ``eta`` (one for
    every channel), ``G`` the Torrance-Sparrow V-cavity term, ``A`` the per-channel amplitude (it
    absorbs the distribution's normalization, as in the paper), ``B`` the sharpness and ``C`` the
    fall-off of the ABC distribution (a power law for large ``B (1 - cos theta_h)``, which is
    what fits the long tails of real glossy highlights better than a Beckmann or Gaussian lobe).

    Parameters
    ----------
    A : amplitude per channel in [0, 1e4] (dimensionless).
    B : sharpness in [1e-3, 1e8] (dimensionless).
    C : fall-off exponent in [1e-3, 10] (dimensionless).
    eta : index of refraction in [1.01, 100] (dimensionless; Löw et al.'s published fits of
        metals reach 100, a Fresnel term near 1 at every angle).

    Sampling: half vectors from the power lobe ``cos^m theta_h`` with ``m = B C`` (the ABC
    distribution's curvature at the peak), reflected about ``h``; the pdf is that proposal's.
    """

    PARAMS = (
        Param("A", 1.0, 0.0, 1e4, "1", per_channel=True, scale="log", doc="amplitude"),
        Param("B", 100.0, 1e-3, 1e8, "1", scale="log", doc="sharpness of the ABC distribution"),
        Param("C", 1.0, 1e-3, 10.0, "1", scale="log", doc="fall-off of the ABC distribution"),
        Param("eta", 1.5, 1.01, 100.0, "1", scale="log", doc="index of refraction (Fresnel)"),
    )  # fmt: skip

    def __init__(
        self,
        A: Array | float = 1.0,
        B: Array | float = 100.0,
        C: Array | float = 1.0,
        eta: Array | float = 1.5,
    ) -> None:
        self._set_params(A=A, B=B, C=C, eta=eta)

    def _f(self, wi: Array, wo: Array) -> Array:
        dt = wi.dtype
        h = normalize(wi + wo)
        one_minus, _ = BlinnPhong._half(wi, wo)
        b, c = jnp.asarray(self.B).astype(dt), jnp.asarray(self.C).astype(dt)
        s = jnp.exp(-c * jnp.log1p(b * one_minus))
        v = mf.visibility(wi, wo, h, 1.0, "beckmann", "vcavity")  # G / (4 cos_i cos_o)
        fr = dielectric_reflectance(dot(wi, h), jnp.asarray(self.eta).astype(dt))
        spec = (4.0 / jnp.pi) * s * v * fr
        return jnp.atleast_1d(self.A).astype(dt) * spec[..., None]

    def _m(self, dt: object) -> Array:
        return jnp.clip(jnp.asarray(self.B).astype(dt) * jnp.asarray(self.C).astype(dt), 0.0, 1e6)

    def _pdf(self, wi: Array, wo: Array) -> Array:
        m = self._m(wi.dtype)
        one_minus, norm = BlinnPhong._half(wi, wo)
        p_h = (m + 1.0) / (2.0 * jnp.pi) * pow_one_minus(one_minus, m)
        return safe_div(p_h, 2.0 * norm)

    def _sample(self, wo: Array, u: Array) -> Array:
        h = power_lobe_local(u, self._m(wo.dtype))
        return 2.0 * dot(wo, h)[..., None] * h - wo

    def sampling_weight(self, wo: Array) -> Array:
        # A scale for lobe selection only: the amplitude times the peak-normalized lobe area.
        dt = wo.dtype
        m = self._m(dt)
        area = 2.0 * jnp.pi / (m + 1.0)
        return channel_mean(self.A).astype(dt) * jnp.minimum(area, 2.0 * jnp.pi) / jnp.pi
