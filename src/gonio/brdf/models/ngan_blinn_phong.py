"""Blinn-Phong with the half vector, normalized as in Ngan, Durand & Matusik (2005).

Blinn, "Models of light reflection for computer synthesized pictures", SIGGRAPH 1977; the
``(n + 2) / (2 pi)`` normalization and the parameter names (``albedo`` = ``rho_s``,
``sharpness`` = ``n``) of Ngan, Durand, Matusik, "Experimental analysis of BRDF models", EGSR
2005. (:class:`~gonio.brdf.models.BlinnPhong` is the same lobe with Giesen's exact
normalization; :class:`~gonio.brdf.models.Phong` is the mirror-direction lobe.)
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import dot, safe_div
from gonio.brdf.models._base import BRDFModel, Param, channel_mean
from gonio.brdf.models._lobes import pow_one_minus, power_lobe_local
from gonio.brdf.models.blinn_phong import BlinnPhong

Array = jnp.ndarray


class NganBlinnPhong(BRDFModel):
    """``f = rho_s (n + 2) / (2 pi) cos^n(theta_h)``, specular only (add a Lambert).

    ``theta_h`` is the polar angle of the half vector ``h = (wi + wo) / |wi + wo|``.

    Parameters
    ----------
    rho_s : specular factor per channel in [0, 10] (dimensionless; the published ``albedo``).
    n : exponent in [0, 1e6] (the published ``sharpness``, up to 1.21e5 in Ngan's fits).

    Sampling: half vectors with density ``(n + 1) / (2 pi) cos^n theta_h`` reflected about ``h``,
    ``p(wi) = p_h / (4 wo.h)``. Numerics as in :class:`~gonio.brdf.models.BlinnPhong`.
    """

    PARAMS = (
        Param("rho_s", 0.1, 0.0, 10.0, "1", per_channel=True, scale="log",
              doc="specular factor (Ngan's albedo)"),
        Param("n", 100.0, 0.0, 1e6, "1", scale="log", doc="half-vector cosine exponent"),
    )  # fmt: skip

    def __init__(self, rho_s: Array | float = 0.1, n: Array | float = 100.0) -> None:
        self._set_params(rho_s=rho_s, n=n)

    def _f(self, wi: Array, wo: Array) -> Array:
        dt = wi.dtype
        n = jnp.asarray(self.n).astype(dt)
        one_minus, _ = BlinnPhong._half(wi, wo)
        spec = (n + 2.0) / (2.0 * jnp.pi) * pow_one_minus(one_minus, n)
        return jnp.atleast_1d(self.rho_s).astype(dt) * spec[..., None]

    def _pdf(self, wi: Array, wo: Array) -> Array:
        n = jnp.asarray(self.n).astype(wi.dtype)
        one_minus, norm = BlinnPhong._half(wi, wo)
        p_h = (n + 1.0) / (2.0 * jnp.pi) * pow_one_minus(one_minus, n)
        return safe_div(p_h, 2.0 * norm)  # 4 wo.h = 2 |wi + wo|

    def _sample(self, wo: Array, u: Array) -> Array:
        h = power_lobe_local(u, jnp.asarray(self.n).astype(wo.dtype))
        return 2.0 * dot(wo, h)[..., None] * h - wo

    def sampling_weight(self, wo: Array) -> Array:
        return jnp.broadcast_to(channel_mean(self.rho_s).astype(wo.dtype), wo.shape[:-1])
