"""Cook-Torrance as fitted by Ngan, Durand & Matusik (2005): a scaled Beckmann V-cavity lobe.

Cook, Torrance, "A reflectance model for computer graphics", ACM Trans. Graph. 1(1), 1982;
parameterized as in Ngan, Durand, Matusik, "Experimental analysis of BRDF models", EGSR 2005
(the BSDF benchmark library's ``NganCookTorrance``: ``albedo`` = ``rho_s``, ``eta`` = ``f0``,
``roughness`` = ``alpha``).
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import dot, normalize, reflect, safe_div
from gonio.brdf.models import microfacet as mf
from gonio.brdf.models._base import BRDFModel, Param, channel_mean

Array = jnp.ndarray


class CookTorrance(BRDFModel):
    """``f = rho_s D(h) G(wi, wo) F(wi.h) / (pi cos_i cos_o)``, specular only (add a Lambert).

    ``D(h) = exp(-tan^2 theta_h / alpha^2) / (pi alpha^2 cos^4 theta_h)`` (normalized Beckmann),
    ``G = min(1, 2 cos_h cos_o / (wo.h), 2 cos_h cos_i / (wo.h))`` (Torrance-Sparrow V-cavity),
    ``F = f0 + (1 - f0)(1 - wi.h)^5`` (Schlick) with **one** ``f0`` for every channel; the colour
    of the highlight is the per-channel factor ``rho_s``. Unlike
    :class:`~gonio.brdf.models.TorranceSparrow` (``D G F / (4 cos_i cos_o)``), the lobe's height is
    free of ``f0``: a weak highlight does not force a small ``f0`` and an exaggerated grazing rise.

    Parameters
    ----------
    rho_s : specular factor per channel in [0, 10] (dimensionless; the published ``albedo``).
    alpha : Beckmann roughness (RMS slope) in [1e-4, 1].
    f0 : Schlick reflectance at normal incidence in [0, 1], shared by the channels.

    Sampling: half vectors with density ``D(h) cos theta_h``, reflected about ``h``
    (``p(wi) = D cos theta_h / (4 wo.h)``).
    """

    PARAMS = (
        Param("rho_s", 0.1, 0.0, 10.0, "1", per_channel=True, scale="log",
              doc="specular factor (Ngan's albedo)"),
        Param("alpha", 0.1, 1e-4, 1.0, "1", scale="log", doc="Beckmann roughness (RMS slope)"),
        Param("f0", 0.5, 0.0, 1.0, "1", scale="logit",
              doc="Schlick reflectance at normal incidence, shared by the channels"),
    )  # fmt: skip

    def __init__(
        self, rho_s: Array | float = 0.1, alpha: Array | float = 0.1, f0: Array | float = 0.5
    ) -> None:
        self._set_params(rho_s=rho_s, alpha=alpha, f0=f0)

    def _f(self, wi: Array, wo: Array) -> Array:
        dt = wi.dtype
        h = normalize(wi + wo)
        alpha = jnp.asarray(self.alpha).astype(dt)
        d = mf.ndf(h, alpha, "beckmann")
        v = mf.visibility(wi, wo, h, alpha, "beckmann", "vcavity")  # G / (4 cos_i cos_o)
        c = jnp.clip(dot(wi, h), 0.0, 1.0)
        f0 = jnp.asarray(self.f0).astype(dt)
        fr = f0 + (1.0 - f0) * (1.0 - c) ** 5
        spec = (4.0 / jnp.pi) * d * v * fr
        return jnp.atleast_1d(self.rho_s).astype(dt) * spec[..., None]

    def _pdf(self, wi: Array, wo: Array) -> Array:
        h = normalize(wi + wo)
        oh = jnp.maximum(dot(wo, h), 0.0)
        return safe_div(mf.ndf_pdf(h, jnp.asarray(self.alpha).astype(wi.dtype), "beckmann"),
                        4.0 * oh)  # fmt: skip

    def _sample(self, wo: Array, u: Array) -> Array:
        h = mf.sample_ndf(u, jnp.asarray(self.alpha).astype(wo.dtype), "beckmann")
        return reflect(wo, h)

    def sampling_weight(self, wo: Array) -> Array:
        dt = wo.dtype
        f0 = jnp.asarray(self.f0).astype(dt)
        fr = f0 + (1.0 - f0) * (1.0 - jnp.clip(wo[..., 2], 0.0, 1.0)) ** 5
        return (4.0 / jnp.pi) * channel_mean(self.rho_s).astype(dt) * fr
