"""Warps from the unit square ``u in [0, 1)^2`` to directions, with their densities.

Each ``square_to_X`` maps ``u`` of shape ``(..., 2)`` to unit vectors ``(..., 3)`` in the local
frame; the matching ``X_pdf`` gives the density per unit solid angle. They stay finite for ``u``
at 0 and at ``1 - eps``.
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf.frames import safe_sqrt

Array = jnp.ndarray


def square_to_disk_concentric(u: Array) -> Array:
    """Shirley-Chiu concentric map of the square onto the unit disk -> ``(..., 2)``."""
    a = 2.0 * u[..., 0] - 1.0
    b = 2.0 * u[..., 1] - 1.0
    first = jnp.abs(a) > jnp.abs(b)
    big = jnp.where(first, a, b)
    small = jnp.where(first, b, a)
    safe_big = jnp.where(big == 0, 1.0, big)
    ang = (jnp.pi / 4.0) * small / safe_big
    ang = jnp.where(first, ang, jnp.pi / 2.0 - ang)
    r = jnp.where(big == 0, 0.0, big)
    return jnp.stack([r * jnp.cos(ang), r * jnp.sin(ang)], -1)


def square_to_cosine_hemisphere(u: Array) -> Array:
    """Cosine-weighted hemisphere around +z (Malley's method) -> ``(..., 3)``."""
    d = square_to_disk_concentric(u)
    z = safe_sqrt(1.0 - d[..., 0] ** 2 - d[..., 1] ** 2)
    return jnp.concatenate([d, z[..., None]], -1)


def cosine_hemisphere_pdf(w: Array) -> Array:
    """Density of :func:`square_to_cosine_hemisphere`: ``max(cos theta, 0) / pi``."""
    return jnp.maximum(w[..., 2], 0.0) / jnp.pi


def square_to_uniform_hemisphere(u: Array) -> Array:
    """Uniform over the upper hemisphere -> ``(..., 3)``; density ``1 / (2 pi)``."""
    z = u[..., 0]
    r = safe_sqrt(1.0 - z * z)
    phi = 2.0 * jnp.pi * u[..., 1]
    return jnp.stack([r * jnp.cos(phi), r * jnp.sin(phi), z], -1)


def square_to_cosine_power_lobe(u: Array, n: Array) -> Array:
    """Directions about +z with density ``(n + 1) / (2 pi) cos^n theta`` -> ``(..., 3)``.

    ``cos theta = (1 - u0)^(1 / (n + 1))``, evaluated through ``exp(log1p(-u0) / (n + 1))`` so
    that exponents up to 1e5 and ``u0`` near 1 stay accurate.
    """
    cos_t = jnp.exp(jnp.log1p(-jnp.minimum(u[..., 0], 1.0 - 1e-7)) / (n + 1.0))
    sin_t = safe_sqrt(1.0 - cos_t * cos_t)
    phi = 2.0 * jnp.pi * u[..., 1]
    return jnp.stack([sin_t * jnp.cos(phi), sin_t * jnp.sin(phi), cos_t], -1)


def cosine_power_lobe_pdf(cos_t: Array, n: Array) -> Array:
    """Density of :func:`square_to_cosine_power_lobe` given the cosine to the lobe axis."""
    c = jnp.maximum(cos_t, 0.0)
    # exp(n log c) rather than c**n: finite gradients in n at c = 0.
    pos = c > 0
    cn = jnp.where(pos, jnp.exp(n * jnp.log(jnp.where(pos, c, 1.0))), 0.0)
    return (n + 1.0) / (2.0 * jnp.pi) * cn
