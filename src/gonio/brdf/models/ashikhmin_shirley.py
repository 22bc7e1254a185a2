"""Ashikhmin & Shirley (2000): anisotropic Phong lobe, Schlick Fresnel, coupled diffuse term.

Ashikhmin, Shirley, "An anisotropic Phong BRDF model", Journal of Graphics Tools 5(2), 2000.
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf import frames
from gonio.brdf.models._base import BRDFModel, Param, channel_mean, mixture_sample
from gonio.brdf.models.fresnel import Schlick
from gonio.brdf.sampling import warps

Array = jnp.ndarray


def _log_half_power(h: Array, nu: Array, nv: Array) -> Array:
    """``log((n.h) ^ e(h))`` with ``e = (nu h_x^2 + nv h_y^2) / (1 - h_z^2)``, shape ``(...)``.

    Written as ``0.5 (nu h_x^2 + nv h_y^2) log1p(-s) / s`` with ``s = h_x^2 + h_y^2``, which is
    smooth through the pole (where ``log1p(-s) / s -> -1``) instead of the paper's 0/0 there.
    """
    s = h[..., 0] ** 2 + h[..., 1] ** 2
    eps = jnp.finfo(h.dtype).eps
    s_c = jnp.clip(s, 0.0, 1.0 - eps)
    small = s_c < 1e-6
    s_safe = jnp.where(small, 1.0, s_c)
    ratio = jnp.where(small, -1.0 - 0.5 * s_c, jnp.log1p(-s_safe) / s_safe)
    return 0.5 * (nu * h[..., 0] ** 2 + nv * h[..., 1] ** 2) * ratio


class AshikhminShirley(BRDFModel):
    """The Ashikhmin-Shirley BRDF as published (2000).

    Specular, with ``h`` the half vector and ``k`` either direction (``k.h`` is the same for both):
    ``f_s = sqrt((nu + 1)(nv + 1)) / (8 pi) (n.h)^(nu cos^2 phi_h + nv sin^2 phi_h)
    / (k.h max(cos_i, cos_o)) F(k.h)`` with ``F = rho_s + (1 - rho_s)(1 - k.h)^5`` (Schlick).
    Diffuse: ``f_d = 28 rho_d / (23 pi) (1 - rho_s) (1 - (1 - cos_i / 2)^5)
    (1 - (1 - cos_o / 2)^5)``.

    Sampling (as published): the half vector with ``phi = atan(sqrt((nu + 1)/(nv + 1)) tan(pi
    xi / 2))`` per quadrant and ``cos theta_h = (1 - xi')^(1 / (nu cos^2 phi + nv sin^2 phi + 1))``,
    whose density is ``p_h = sqrt((nu + 1)(nv + 1)) / (2 pi) (n.h)^(...)``, so ``p(wi) = p_h /
    (4 k.h)``; mixed with cosine-weighted sampling of the diffuse term by an albedo estimate.

    Parameters
    ----------
    rho_d : diffuse reflectance ``R_d``, scalar or per channel.
    rho_s : specular reflectance at normal incidence ``R_s`` (Schlick's ``F0``), scalar or per
        channel.
    nu, nv : Phong exponents along the tangent (x) and bitangent (y); equal for isotropy.
    """

    PARAMS = (
        Param("rho_d", 0.3, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="diffuse reflectance R_d"),
        Param("rho_s", 0.05, 0.0, 1.0, "1", per_channel=True, scale="logit",
              doc="specular reflectance at normal incidence R_s (Schlick F0)"),
        Param("nu", 100.0, 0.0, 1e5, "1", scale="log", doc="exponent along the tangent (x)"),
        Param("nv", 100.0, 0.0, 1e5, "1", scale="log", doc="exponent along the bitangent (y)"),
    )  # fmt: skip

    def __init__(
        self,
        rho_d: Array | float = 0.3,
        rho_s: Array | float = 0.05,
        nu: Array | float = 100.0,
        nv: Array | float | None = None,
    ) -> None:
        self._set_params(rho_d=rho_d, rho_s=rho_s, nu=nu, nv=nu if nv is None else nv)

    def _exps(self, dtype) -> tuple[Array, Array]:
        return self.nu.astype(dtype), self.nv.astype(dtype)

    def _half_pdf(self, h: Array) -> Array:
        """Density of the sampled half vector per unit solid angle, ``(...)``."""
        nu, nv = self._exps(h.dtype)
        norm = jnp.sqrt((nu + 1.0) * (nv + 1.0)) / (2.0 * jnp.pi)
        return norm * jnp.exp(_log_half_power(h, nu, nv))

    def _f(self, wi: Array, wo: Array) -> Array:
        dtype = wi.dtype
        rs = jnp.atleast_1d(self.rho_s).astype(dtype)
        rd = jnp.atleast_1d(self.rho_d).astype(dtype)
        h = frames.half_vector(wi, wo)
        kh = jnp.maximum(frames.dot(wi, h), 1e-12)
        ci, co = wi[..., 2], wo[..., 2]
        spec = (
            self._half_pdf(h) / 4.0 / (kh * jnp.maximum(ci, co))
        )  # sqrt(..)/(8 pi) (n.h)^e / (k.h max(cos))
        # Schlick's term with F0 = rho_s (built without re-validating a possibly traced rho_s)
        fres = Schlick._tree_unflatten((), [self.rho_s]).eval(kh).astype(dtype)
        diff = (
            28.0 / (23.0 * jnp.pi) * rd * (1.0 - rs)
            * (1.0 - (1.0 - ci / 2.0) ** 5)[..., None]
            * (1.0 - (1.0 - co / 2.0) ** 5)[..., None]
        )  # fmt: skip
        return spec[..., None] * fres + diff

    def _spec_pdf(self, wi: Array, wo: Array) -> Array:
        h = frames.half_vector(wi, wo)
        kh = frames.dot(wo, h)
        return jnp.where(kh > 0, frames.safe_div(self._half_pdf(h), 4.0 * kh), 0.0)

    def _sample_spec(self, wo: Array, u: Array) -> Array:
        nu, nv = self._exps(wo.dtype)
        q = jnp.floor(4.0 * u[..., 0])
        uq = 4.0 * u[..., 0] - q  # in [0, 1) within the quadrant
        half = 0.5 * jnp.pi * uq
        phi = jnp.arctan2(jnp.sqrt(nu + 1.0) * jnp.sin(half), jnp.sqrt(nv + 1.0) * jnp.cos(half))
        phi = jnp.select(
            [q == 1, q == 2, q >= 3], [jnp.pi - phi, jnp.pi + phi, 2 * jnp.pi - phi], phi
        )
        c, s = jnp.cos(phi), jnp.sin(phi)
        e = nu * c * c + nv * s * s
        cos_t = jnp.exp(jnp.log1p(-jnp.minimum(u[..., 1], 1.0 - 1e-7)) / (e + 1.0))
        sin_t = frames.safe_sqrt(1.0 - cos_t * cos_t)
        h = jnp.stack([sin_t * c, sin_t * s, cos_t], -1)
        return frames.reflect(wo, h)

    def _weights(self, wo: Array) -> list[Array]:
        co = jnp.clip(wo[..., 2], 0.0, 1.0)
        rs = channel_mean(self.rho_s).astype(wo.dtype)
        rd = channel_mean(self.rho_d).astype(wo.dtype)
        spec = rs + (1.0 - rs) * (1.0 - co) ** 5
        # Exact diffuse albedo: int (1 - (1 - cos_i / 2)^5) cos_i dwi / pi = 23 / 28.
        diff = rd * (1.0 - rs) * (1.0 - (1.0 - co / 2.0) ** 5)
        return [spec, diff]

    def _pdf(self, wi: Array, wo: Array) -> Array:
        ws = self._weights(wo)
        total = ws[0] + ws[1]
        p_s = jnp.where(total > 0, frames.safe_div(ws[0], total), 0.5)
        return p_s * self._spec_pdf(wi, wo) + (1.0 - p_s) * warps.cosine_hemisphere_pdf(wi)

    def _sample(self, wo: Array, u: Array) -> Array:
        samplers = [self._sample_spec, lambda w, uu: warps.square_to_cosine_hemisphere(uu)]
        wi, _ = mixture_sample(wo, u, self._weights(wo), samplers)
        return wi

    def sampling_weight(self, wo: Array) -> Array:
        ws = self._weights(wo)
        return ws[0] + ws[1]
