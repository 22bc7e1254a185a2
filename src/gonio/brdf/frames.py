"""Local shading frame, spherical coordinates, reflection/refraction and the half/diff transform.

Conventions (DESIGN.md): directions are unit vectors of shape ``(..., 3)`` in the local frame,
z is the surface normal, x the tangent. ``wi`` points toward the light and ``wo`` toward the
viewer, both away from the surface. Angles are radians; ``theta`` is measured from +z and
``phi`` counter-clockwise from +x, returned in ``[0, 2*pi)``.

All functions are written with :mod:`jax.numpy`, accept NumPy or JAX arrays, keep the input
dtype and are safe to differentiate (no NaN gradients at the pole or at the horizon).
"""

from __future__ import annotations

import jax.numpy as jnp

Array = jnp.ndarray

TWO_PI = 2.0 * jnp.pi


def safe_sqrt(x: Array) -> Array:
    """``sqrt(max(x, 0))`` whose gradient is 0 (not inf/NaN) where ``x <= 0``."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def safe_div(a: Array, b: Array) -> Array:
    """``a / b`` where ``b != 0``, else 0; gradients stay finite."""
    nz = b != 0
    return jnp.where(nz, a / jnp.where(nz, b, 1.0), 0.0)


def dot(a: Array, b: Array) -> Array:
    """Dot product over the last axis: ``(..., 3), (..., 3) -> (...)``."""
    # Written out per component rather than jnp.sum(a * b, -1): XLA fuses elementwise code
    # into one loop, while a reduction over the size-3 axis starts a separate pass over memory.
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def normalize(v: Array) -> Array:
    """Unit vector along ``v`` (``(..., 3)``); a zero vector maps to +z."""
    # Per component and stacked, rather than v * inv[..., None] with a scattered +z fallback:
    # the same values bit for bit, and XLA:CPU fuses it into its consumers (e.g. ndf(normalize(.))
    # becomes one loop), where the scatter would be a separate pass over memory.
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    n2 = x * x + y * y + z * z
    ok = n2 > 0
    inv = jnp.where(ok, 1.0 / jnp.sqrt(jnp.where(ok, n2, 1.0)), 0.0)
    return jnp.stack(
        [jnp.where(ok, x * inv, 0.0), jnp.where(ok, y * inv, 0.0), jnp.where(ok, z * inv, 1.0)], -1
    )


def cos_theta(w: Array) -> Array:
    """Cosine of the polar angle of ``w`` (its z component), shape ``(...)``."""
    return w[..., 2]


def spherical_to_direction(theta: Array, phi: Array) -> Array:
    """Unit vector(s) for polar angle ``theta`` and azimuth ``phi`` (radians) -> ``(..., 3)``."""
    theta = jnp.asarray(theta)
    phi = jnp.asarray(phi)
    st = jnp.sin(theta)
    x, y, z = jnp.broadcast_arrays(st * jnp.cos(phi), st * jnp.sin(phi), jnp.cos(theta))
    return jnp.stack([x, y, z], -1)


def direction_to_spherical(w: Array) -> tuple[Array, Array]:
    """``(theta, phi)`` of direction(s) ``w`` (..., 3): theta in [0, pi], phi in [0, 2pi).

    ``theta`` uses ``atan2(|xy|, z)`` rather than ``acos(z)`` so that it stays accurate near the
    pole. At the pole itself ``phi`` is 0.
    """
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    r2 = x * x + y * y
    theta = jnp.arctan2(safe_sqrt(r2), z)
    # arctan2(0, 0) has a NaN gradient: feed it a harmless point at the pole.
    pole = r2 == 0
    phi = jnp.where(pole, 0.0, jnp.arctan2(jnp.where(pole, 0.0, y), jnp.where(pole, 1.0, x)))
    phi = jnp.where(phi < 0, phi + TWO_PI, phi)
    # arctan2 of a tiny negative y can round to exactly 2*pi after the shift.
    phi = jnp.where(phi >= TWO_PI, 0.0, phi)
    return theta, phi


def frame_from_normal(n: Array, t: Array | None = None) -> Array:
    """Orthonormal frame whose rows are (tangent, bitangent, normal): ``(..., 3, 3)``.

    Parameters
    ----------
    n : (..., 3) unit normal.
    t : optional (..., 3) tangent hint; it is made orthogonal to ``n`` (Gram-Schmidt). Without it
        the branchless construction of Duff et al. (2017) picks a tangent continuous except at
        ``n_z = -1``.
    """
    n = normalize(jnp.asarray(n))
    if t is None:
        s = jnp.where(n[..., 2] >= 0, 1.0, -1.0)
        a = -1.0 / (s + n[..., 2])
        b = n[..., 0] * n[..., 1] * a
        t = jnp.stack([1.0 + s * n[..., 0] ** 2 * a, s * b, -s * n[..., 0]], -1)
    else:
        t = jnp.asarray(t)
        t = normalize(t - dot(t, n)[..., None] * n)
    bt = jnp.cross(n, t)
    return jnp.stack(jnp.broadcast_arrays(t, bt, n), axis=-2)


def to_local(frame: Array, v: Array) -> Array:
    """Express world vector(s) ``v`` in ``frame`` (rows t, b, n) -> ``(..., 3)``."""
    return jnp.einsum("...ij,...j->...i", frame, v)


def to_world(frame: Array, v: Array) -> Array:
    """Inverse of :func:`to_local`."""
    return jnp.einsum("...ji,...j->...i", frame, v)


def reflect(w: Array, n: Array | None = None) -> Array:
    """Mirror direction of ``w`` about normal ``n`` (default +z): ``2 (w.n) n - w``."""
    if n is None:
        return w * jnp.array([-1.0, -1.0, 1.0], dtype=jnp.result_type(w))
    return 2.0 * dot(w, n)[..., None] * n - w


def refract(w: Array, eta: Array, n: Array | None = None) -> tuple[Array, Array]:
    """Refracted direction through an interface with relative index ``eta = eta_t / eta_i``.

    ``w`` points away from the surface on the incident side (the side ``n`` points to; default
    normal +z). Returns ``(wt, ok)``: ``wt`` (..., 3) points away from the surface on the other
    side; ``ok`` is False under total internal reflection, where ``wt`` is the zero vector.
    """
    if n is None:
        n = jnp.zeros_like(w).at[..., 2].set(1.0)
    eta = jnp.asarray(eta)
    cos_i = dot(w, n)
    sin2_t = jnp.maximum(0.0, 1.0 - cos_i**2) / (eta * eta)
    ok = sin2_t <= 1.0
    cos_t = safe_sqrt(1.0 - sin2_t)
    wt = -w / eta[..., None] + (cos_i / eta - cos_t)[..., None] * n
    return jnp.where(ok[..., None], wt, 0.0), ok


def _rot_z(v: Array, ang: Array) -> Array:
    c, s = jnp.cos(ang), jnp.sin(ang)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return jnp.stack([c * x - s * y, s * x + c * y, z], -1)


def _rot_y(v: Array, ang: Array) -> Array:
    c, s = jnp.cos(ang), jnp.sin(ang)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return jnp.stack([c * x + s * z, y, -s * x + c * z], -1)


def half_vector(wi: Array, wo: Array) -> Array:
    """Normalized half vector ``(wi + wo) / |wi + wo|``; +z where ``wi = -wo``."""
    return normalize(wi + wo)


def half_diff(wi: Array, wo: Array) -> tuple[Array, Array, Array, Array]:
    """Rusinkiewicz (1998) half/difference angles ``(theta_h, phi_h, theta_d, phi_d)``.

    The difference vector is ``wi`` expressed in the frame where the half vector is the pole:
    rotate by ``-phi_h`` about z, then by ``-theta_h`` about y. ``phi_h`` and ``phi_d`` are in
    [0, 2pi); isotropic tables may fold ``phi_d`` to [0, pi) by reciprocity.
    """
    h = half_vector(wi, wo)
    theta_h, phi_h = direction_to_spherical(h)
    d = _rot_y(_rot_z(wi, -phi_h), -theta_h)
    theta_d, phi_d = direction_to_spherical(d)
    return theta_h, phi_h, theta_d, phi_d


def half_diff_to_directions(
    theta_h: Array, phi_h: Array, theta_d: Array, phi_d: Array
) -> tuple[Array, Array]:
    """Inverse of :func:`half_diff`: ``(wi, wo)`` each ``(..., 3)``."""
    theta_h, phi_h, theta_d, phi_d = jnp.broadcast_arrays(
        *(jnp.asarray(a) for a in (theta_h, phi_h, theta_d, phi_d))
    )
    d = spherical_to_direction(theta_d, phi_d)
    d_o = d * jnp.array([-1.0, -1.0, 1.0], dtype=d.dtype)
    wi = _rot_z(_rot_y(d, theta_h), phi_h)
    wo = _rot_z(_rot_y(d_o, theta_h), phi_h)
    return wi, wo


def upper(w: Array) -> Array:
    """True where ``w`` is strictly above the horizon (``w_z > 0``)."""
    return w[..., 2] > 0
