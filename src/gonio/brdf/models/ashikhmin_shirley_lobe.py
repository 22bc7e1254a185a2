"""The specular lobe of Ashikhmin & Shirley (2000), isotropic, with any Fresnel term.

Ashikhmin, Shirley, "An anisotropic Phong BRDF model", Journal of Graphics Tools 5(2), 2000,
as the published fits use it: Ngan et al. (2005) with Schlick's Fresnel term and Löw et al.
(2012) with the exact dielectric Fresnel reflectance (bbm's ``NganAshikhminShirley`` and
``LowAshikhminShirley``: a scale times the specular lobe, no coupled diffuse term).
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf import frames
from gonio.brdf.models._base import BRDFModel, Param
from gonio.brdf.models._lobes import HalfVectorPowerProposal, pow_one_minus
from gonio.brdf.models.fresnel import Fresnel, Schlick
from gonio.errors import ParameterError

Array = jnp.ndarray


class AshikhminShirleyLobe(HalfVectorPowerProposal, BRDFModel):
    """``f = rho_s (n + 1) / (8 pi) cos^n theta_h F(wi.h) / (wi.h max(cos_i, cos_o))`` (sr^-1).

    Parameters
    ----------
    rho_s : scale per channel in [0, 1e3] (dimensionless; bbm's ``albedo``).
    n : exponent in [0, 1e7] (dimensionless; bbm's ``sharpness``).
    fresnel : a :mod:`.fresnel` term at ``wi.h``, e.g. ``Schlick(f0)`` (Ngan) or
        ``Dielectric(eta)`` (Löw); default ``Schlick(1)`` (no Fresnel variation).

    Sampling: half vectors from ``(n + 1) / (2 pi) cos^n theta_h`` (the lobe's own
    distribution, as Ashikhmin and Shirley sample it), reflected about ``h``.
    """

    PARAMS = (
        Param("rho_s", 1.0, 0.0, 1e3, "1", per_channel=True, scale="log", doc="scale"),
        Param("n", 100.0, 0.0, 1e7, "1", scale="log", doc="exponent of cos theta_h"),
    )  # fmt: skip
    CHILDREN = ("fresnel",)

    def __init__(
        self,
        rho_s: Array | float = 1.0,
        n: Array | float = 100.0,
        fresnel: Fresnel | None = None,
    ) -> None:
        fresnel = Schlick(1.0) if fresnel is None else fresnel
        if not isinstance(fresnel, Fresnel):
            raise ParameterError(
                f"AshikhminShirleyLobe: fresnel must be a Fresnel term, got {fresnel!r}"
            )
        object.__setattr__(self, "fresnel", fresnel)
        self._set_params(rho_s=rho_s, n=n)
        _ = self.channels  # validates channel agreement

    def _f(self, wi: Array, wo: Array) -> Array:
        dt = wi.dtype
        n = jnp.asarray(self.n).astype(dt)
        h = wi + wo
        norm = frames.safe_sqrt(jnp.sum(h * h, -1))
        hxy2 = h[..., 0] ** 2 + h[..., 1] ** 2
        one_minus = hxy2 / jnp.maximum(norm * (norm + jnp.abs(h[..., 2])), 1e-30)
        kh = jnp.maximum(0.5 * norm, 1e-12)  # wi.h = |wi + wo| / 2
        lobe = (n + 1.0) / (8.0 * jnp.pi) * pow_one_minus(one_minus, n)
        lobe = lobe / (kh * jnp.maximum(wi[..., 2], wo[..., 2]))
        fres = self.fresnel.eval(kh).astype(dt)
        return jnp.atleast_1d(self.rho_s).astype(dt) * lobe[..., None] * fres

    def _exponent(self, dt: object) -> Array:
        return jnp.asarray(self.n).astype(dt)

    def _amplitude(self) -> Array:
        return self.rho_s
