"""Numerics shared by the cosine-power lobes (Phong, Blinn-Phong) and two-lobe mixtures.

Exponents reach 1e5, where ``c**n`` of a float32 cosine loses every digit: a cosine within one
ulp of 1 already moves ``n log c`` by 6e-3. These helpers therefore work with ``1 - cos``
computed from differences of vectors (no cancellation) and evaluate powers as
``exp(n log1p(-(1 - cos)))``.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp

from gonio.brdf.frames import safe_sqrt
from gonio.brdf.models._base import choose_lobe, mixture_sample
from gonio.brdf.sampling import warps

Array = jnp.ndarray


def pow_one_minus(x: Array, n: Array) -> Array:
    """``(1 - x)**n`` for ``x = 1 - cos``; 0 where the cosine is not positive (``x >= 1``).

    Finite with finite gradients in ``x`` and ``n`` everywhere, including ``n = 0``.
    """
    pos = x < 1.0
    xs = jnp.where(pos, x, 0.0)
    return jnp.where(pos, jnp.exp(n * jnp.log1p(-xs)), 0.0)


def power_lobe_local(u: Array, n: Array) -> Array:
    """Directions about +z with density ``(n + 1)/(2 pi) cos^n theta`` -> ``(..., 3)``.

    Inversion of the marginal CDF: ``cos theta = (1 - u0)^(1/(n+1))``. ``1 - cos theta`` is
    taken from ``expm1`` so that ``sin theta`` keeps full relative precision for ``n`` up to
    1e5 in float32 (``warps.square_to_cosine_power_lobe`` forms ``1 - cos**2`` directly, which
    cancels there).
    """
    lg = jnp.log1p(-u[..., 0]) / (n + 1.0)
    one_minus = -jnp.expm1(lg)
    cos_t = jnp.exp(lg)
    sin_t = safe_sqrt(one_minus * (1.0 + cos_t))
    phi = 2.0 * jnp.pi * u[..., 1]
    return jnp.stack([sin_t * jnp.cos(phi), sin_t * jnp.sin(phi), cos_t], -1)


def frame_about(axis: Array) -> tuple[Array, Array]:
    """Two unit vectors ``(t, b)`` completing the unit ``axis`` (``(..., 3)``, ``axis_z > -1``)
    to a right-handed orthonormal frame (Duff et al. 2017, branch for ``axis_z >= 0``; our axes
    are mirror directions and half vectors, always in the upper hemisphere)."""
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    a = -1.0 / (1.0 + z)
    b = x * y * a
    t = jnp.stack([1.0 + x * x * a, b, -x], -1)
    bt = jnp.stack([b, 1.0 + y * y * a, -y], -1)
    return t, bt


def lobe_probabilities(shape: tuple[int, ...], dtype, weights: Sequence[Array]) -> list[Array]:
    """Selection probabilities exactly as :func:`mixture_sample` computes them."""
    return choose_lobe(jnp.zeros(shape, dtype), weights)[2]


def _cosine(wo: Array, u: Array) -> Array:
    return warps.square_to_cosine_hemisphere(u)


class DiffusePlusLobe:
    """Sampling shared by the models ``rho_d / pi + one specular lobe`` (Phong, Blinn-Phong, Ward).

    A model mixes this in before :class:`~gonio.brdf.models._base.BRDFModel` and provides
    ``_weights(wo) -> (w_diffuse, w_lobe)`` (albedo estimates of the two parts) and
    ``_sample_lobe(wo, u) -> wi``; cosine sampling and the lobe's sampler are then mixed in
    proportion to the weights, and the model's ``_pdf`` must be the matching mixture.
    """

    def _sample(self, wo: Array, u: Array) -> Array:
        wi, _ = mixture_sample(wo, u, self._weights(wo), [_cosine, self._sample_lobe])
        return wi

    def sampling_weight(self, wo: Array) -> Array:
        w = self._weights(wo)
        return jnp.broadcast_to(w[0] + w[1], wo.shape[:-1])


class HalfVectorPowerProposal:
    """Sampling of a specular lobe by half vectors from ``(m + 1) / (2 pi) cos^m theta_h``
    about the normal, reflected about ``h``: ``p(wi) = p_h / (4 wo.h)``.

    A model mixes this in before :class:`~gonio.brdf.models._base.BRDFModel` and provides
    ``_exponent(dtype) -> m`` (the proposal's exponent, matched to the lobe's curvature at its
    peak) and ``_amplitude() -> (C,)`` or scalar (for :meth:`sampling_weight`). The proposal is
    exact for the density it reports, whatever the lobe's shape.
    """

    def _m(self, dt: object) -> Array:
        return jnp.clip(self._exponent(dt), 0.0, 1e6)

    def _pdf(self, wi: Array, wo: Array) -> Array:
        m = self._m(wi.dtype)
        h = wi + wo
        hxy2 = h[..., 0] ** 2 + h[..., 1] ** 2
        norm = safe_sqrt(jnp.sum(h * h, -1))
        one_minus = jnp.where(
            h[..., 2] > 0, hxy2 / jnp.maximum(norm * (norm + jnp.abs(h[..., 2])), 1e-30), 1.0
        )
        p_h = (m + 1.0) / (2.0 * jnp.pi) * pow_one_minus(one_minus, m)
        return p_h / jnp.maximum(2.0 * norm, 1e-30)  # 4 wo.h = 2 |wi + wo|

    def _sample(self, wo: Array, u: Array) -> Array:
        h = power_lobe_local(u, self._m(wo.dtype))
        return 2.0 * jnp.sum(wo * h, -1, keepdims=True) * h - wo

    def sampling_weight(self, wo: Array) -> Array:
        # A scale for lobe selection only: the amplitude times the peak-normalized lobe area.
        m = self._m(wo.dtype)
        area = jnp.minimum(2.0 * jnp.pi / (m + 1.0), 2.0 * jnp.pi) / jnp.pi
        amp = jnp.mean(jnp.abs(jnp.atleast_1d(self._amplitude()))).astype(wo.dtype)
        return jnp.broadcast_to(amp * area, wo.shape[:-1])
