"""The Shifted Gamma Distribution microfacet model of Bagher, Soler & Holzschuch (2012).

Bagher, Soler, Holzschuch, "Accurate fitting of measured reflectances using a Shifted Gamma
micro-facet distribution", Computer Graphics Forum 31(4), 2012, in the form of the BSDF
benchmark library (bbm, ``include/bsdfmodel/bagher.h`` with ``ndf/sgd.h`` and
``maskingshadowing/uncorrelated.h``), which the published fits (``bagher_sgd.fit``) follow.
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import dot, normalize
from gonio.brdf.models._base import BRDFModel, Param
from gonio.brdf.models._lobes import HalfVectorPowerProposal

Array = jnp.ndarray


class BagherSGD(HalfVectorPowerProposal, BRDFModel):
    """``f = rho_s D(h) G(wi, wo) F(wi.h) / (pi cos_i cos_o)`` in sr^-1 (specular), per channel.

    * ``D(h) = K P22(tan^2 theta_h) / (pi cos^4 theta_h)`` with the shifted gamma distribution
      of slopes ``P22(t) = exp(-(alpha + t / alpha)) / (alpha + t / alpha)^p``;
    * ``G = G1(wi) G1(wo)`` (uncorrelated), the paper's fitted shadowing
      ``G1(v) = 1 + Lambda (1 - exp(c (theta_v - theta0)^k))`` for ``theta_v > theta0``, else 1;
    * ``F(x) = F0 + (1 - F0)(1 - x)^5 - F1 x``, Bagher et al.'s modified Schlick term.

    Every parameter is per channel (the published fits give one value per RGB channel).

    Parameters
    ----------
    rho_s : scale in [0, 1e3] (dimensionless; bbm's ``albedo``).
    alpha : distribution width in [1e-7, 10] (dimensionless).
    p : distribution shape in [0, 10] (dimensionless).
    f0, f1 : the Fresnel term's coefficients in [-100, 100] (dimensionless; bbm's
        ``eta[0]``, ``eta[1]``).
    K : the distribution's normalization in [0, 1e7] (dimensionless).
    Lambda, c, k : the shadowing fit's amplitude in [-1e12, 1e12], scale in [0, 1e300] and
        exponent in [0, 1e4] (dimensionless; the published fits reach ``c = 1e109`` with
        ``k = 258``, so ``c (theta - theta0)^k`` is formed as ``exp(log c + k log(theta -
        theta0))`` from the parameters' own precision, finite in float32 too).
    theta0 : the shadowing fit's onset angle in [-pi/2, pi/2], radians.

    Sampling: half vectors from ``cos^m theta_h`` with ``m = 2 / mean(alpha)`` (near its peak
    the distribution is ``exp(-tan^2 theta_h / alpha)``, a Beckmann lobe of slope
    ``sqrt(alpha)``), reflected about ``h``.
    """

    PARAMS = (
        Param("rho_s", 1.0, 0.0, 1e3, "1", per_channel=True, scale="log", doc="scale"),
        Param("alpha", 0.01, 1e-7, 10.0, "1", per_channel=True, scale="log", doc="width"),
        Param("p", 0.64, 0.0, 10.0, "1", per_channel=True, doc="shape of the distribution"),
        Param("f0", 1.0, -100.0, 100.0, "1", per_channel=True, doc="Fresnel F0"),
        Param("f1", 0.0, -100.0, 100.0, "1", per_channel=True, doc="Fresnel F1"),
        Param("K", 7.5, 0.0, 1e7, "1", per_channel=True, scale="log", doc="normalization"),
        Param("Lambda", 0.0, -1e12, 1e12, "1", per_channel=True, doc="shadowing amplitude"),
        Param("c", 0.0, 0.0, 1e300, "1", per_channel=True, doc="shadowing scale"),
        Param("k", 1.0, 0.0, 1e4, "1", per_channel=True, doc="shadowing exponent"),
        Param("theta0", 1.5707963267948966, -1.5707963267948966, 1.5707963267948966, "rad",
              per_channel=True, doc="shadowing onset angle"),
    )  # fmt: skip

    def __init__(
        self,
        rho_s: Array | float = 1.0,
        alpha: Array | float = 0.01,
        p: Array | float = 0.64,
        f0: Array | float = 1.0,
        f1: Array | float = 0.0,
        K: Array | float = 7.5,
        Lambda: Array | float = 0.0,
        c: Array | float = 0.0,
        k: Array | float = 1.0,
        theta0: Array | float = 1.5707963267948966,
    ) -> None:
        self._set_params(rho_s=rho_s, alpha=alpha, p=p, f0=f0, f1=f1, K=K, Lambda=Lambda,
                         c=c, k=k, theta0=theta0)  # fmt: skip
        _ = self.channels  # validates channel agreement

    def _v(self, name: str, dt: object) -> Array:
        return jnp.atleast_1d(getattr(self, name)).astype(dt)

    def _g1(self, cos_v: Array, dt: object) -> Array:
        theta = jnp.arccos(jnp.clip(cos_v, -1.0, 1.0))[..., None]
        t0 = self._v("theta0", dt)
        above = theta > t0
        d = jnp.where(above, theta - t0, 1.0)
        log_c = jnp.log(jnp.atleast_1d(self.c)).astype(dt)  # before the cast: c may be 1e109
        g = 1.0 + self._v("Lambda", dt) * (
            1.0 - jnp.exp(jnp.exp(log_c + self._v("k", dt) * jnp.log(d)))
        )
        return jnp.where(above, g, 1.0)

    def _f(self, wi: Array, wo: Array) -> Array:
        dt = wi.dtype
        h = normalize(wi + wo)
        ch = jnp.maximum(h[..., 2], 1e-12)
        tan2 = ((1.0 - ch * ch) / (ch * ch))[..., None]
        alpha = self._v("alpha", dt)
        t = alpha + tan2 / alpha
        p22 = jnp.exp(-t - self._v("p", dt) * jnp.log(t))
        d = self._v("K", dt) * p22 / (jnp.pi * (ch**4)[..., None])
        g = self._g1(wi[..., 2], dt) * self._g1(wo[..., 2], dt)
        x = dot(wi, h)[..., None]
        f0 = self._v("f0", dt)
        fres = f0 + (1.0 - f0) * (1.0 - x) ** 5 - self._v("f1", dt) * x
        denom = (jnp.pi * wi[..., 2] * wo[..., 2])[..., None]
        return self._v("rho_s", dt) * d * g * fres / denom

    def _exponent(self, dt: object) -> Array:
        return 2.0 / jnp.mean(jnp.atleast_1d(self.alpha).astype(dt))

    def _amplitude(self) -> Array:
        return self.rho_s
