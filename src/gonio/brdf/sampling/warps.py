"""Warps from the unit square ``u in [0, 1)^2`` to directions, with their densities.

Each ``square_to_X`` maps ``u`` of shape ``(..., 2)`` to unit vectors ``(..., 3)`` in the local
frame; the matching ``X_pdf`` gives the density per unit solid angle. They stay finite for ``u``
at 0 and at ``1 - eps``.
"""

from __future__ import annotations

import jax.numpy as jnp

from gonio.brdf._trig import cos_sin_turns
from gonio.brdf.frames import safe_sqrt

Array = jnp.ndarray


def square_to_disk_concentric(u: Array) -> Array:
    """Shirley-Chiu concentric map of the square onto the unit disk -> ``(..., 2)``."""
    return jnp.stack(_concentric_xy(u), -1)


def _concentric_xy(u: Array) -> tuple[Array, Array]:
    a = 2.0 * u[..., 0] - 1.0
    b = 2.0 * u[..., 1] - 1.0
    first = jnp.abs(a) > jnp.abs(b)
    big = jnp.where(first, a, b)
    small = jnp.where(first, b, a)
    safe_big = jnp.where(big == 0, 1.0, big)
    turns = 0.125 * small / safe_big  # the angle pi/4 small/big, in turns
    turns = jnp.where(first, turns, 0.25 - turns)
    r = jnp.where(big == 0, 0.0, big)
    c, s = cos_sin_turns(turns)
    return r * c, r * s


def square_to_cosine_hemisphere(u: Array) -> Array:
    """Cosine-weighted hemisphere around +z (Malley's method) -> ``(..., 3)``."""
    # Components stacked once at the end: slicing a stacked disk point back apart kept XLA:CPU
    # from fusing the map into one loop (same values either way).
    x, y = _concentric_xy(u)
    z = safe_sqrt(1.0 - x**2 - y**2)
    return jnp.stack([x, y, z], -1)


def cosine_hemisphere_pdf(w: Array) -> Array:
    """Density of :func:`square_to_cosine_hemisphere`: ``max(cos theta, 0) / pi``."""
    return jnp.maximum(w[..., 2], 0.0) / jnp.pi


def square_to_uniform_hemisphere(u: Array) -> Array:
    """Uniform over the upper hemisphere -> ``(..., 3)``; density ``1 / (2 pi)``."""
    z = u[..., 0]
    r = safe_sqrt(1.0 - z * z)
    c, s = cos_sin_turns(u[..., 1])
    return jnp.stack([r * c, r * s, z], -1)


def square_to_cosine_power_lobe(u: Array, n: Array) -> Array:
    """Directions about +z with density ``(n + 1) / (2 pi) cos^n theta`` -> ``(..., 3)``.

    ``cos theta = (1 - u0)^(1 / (n + 1))``, evaluated through ``exp(log1p(-u0) / (n + 1))`` so
    that exponents up to 1e5 and ``u0`` near 1 stay accurate.
    """
    cos_t = jnp.exp(jnp.log1p(-jnp.minimum(u[..., 0], 1.0 - 1e-7)) / (n + 1.0))
    sin_t = safe_sqrt(1.0 - cos_t * cos_t)
    c, s = cos_sin_turns(u[..., 1])
    return jnp.stack([sin_t * c, sin_t * s, cos_t], -1)


def cosine_power_lobe_pdf(cos_t: Array, n: Array) -> Array:
    """Density of :func:`square_to_cosine_power_lobe` given the cosine to the lobe axis."""
    c = jnp.maximum(cos_t, 0.0)
    # exp(n log c) rather than c**n: finite gradients in n at c = 0.
    pos = c > 0
    cn = jnp.where(pos, jnp.exp(n * jnp.log(jnp.where(pos, c, 1.0))), 0.0)
    return (n + 1.0) / (2.0 * jnp.pi) * cn
