"""Microfacet building blocks: normal distributions D, shadowing G, and half-vector sampling.

Everything works in the local frame (z = macro normal) on unit vectors ``(..., 3)`` and a scalar
roughness ``alpha`` (cast to the directions' dtype). Distributions (``dist``):

``"beckmann"``
    ``D = exp(-tan^2 theta_h / alpha^2) / (pi alpha^2 cos^4 theta_h)``.
``"ggx"``
    ``D = alpha^2 / (pi cos^4 theta_h (alpha^2 + tan^2 theta_h)^2)`` (Trowbridge-Reitz; Walter
    et al. 2007).
``"blinn"``
    the classic normalized Blinn-Phong ``D = (e + 2) / (2 pi) cos^e theta_h`` with
    ``e = 2 / alpha^2 - 2``, the exponent whose Beckmann distribution has the same roughness
    (Walter et al. 2007, eq. 30).

All three are normalized as ``int D(h) cos(theta_h) dh = 1`` over the hemisphere.

Shadowing (``shadowing``):

``"vcavity"``
    Torrance-Sparrow / Cook-Torrance ``G = min(1, 2 n.h n.o / o.h, 2 n.h n.i / o.h)``.
``"smith"``
    height-correlated Smith ``G = 1 / (1 + Lambda(wi) + Lambda(wo))`` (Heitz 2014, eq. 99) with
    the exact ``Lambda`` of the distribution: ``(erf(a) - 1) / 2 + exp(-a^2) / (2 a sqrt(pi))``,
    ``a = 1 / (alpha tan theta)`` for Beckmann and ``(sqrt(1 + alpha^2 tan^2 theta) - 1) / 2``
    for GGX. Blinn has no closed-form Smith term; it uses the Beckmann ``Lambda`` at the same
    alpha, the standard approximation (Walter et al. 2007, section 5.2).

Sampling: :func:`sample_ndf` draws half vectors with density ``D(h) cos(theta_h)`` for every
distribution (closed-form inversion). :func:`sample_visible` draws visible normals with density
``G1(wo) max(0, wo.h) D(h) / cos(theta_o)`` and is exact for GGX (Heitz 2018). Beckmann's
visible-normal distribution has no closed-form inverse (Heitz & d'Eon 2014 invert it
numerically); it is not offered here, so Beckmann and Blinn use ``sample_ndf``. A BRDF using
either sampler turns the half-vector density into a density of ``wi`` with the Jacobian
``1 / (4 wo.h)``.

Models never need ``G`` alone: they need ``G / (4 cos_i cos_o)``, which :func:`visibility`
computes without dividing by the cosines (finite at grazing angles). The Smith form works with
``mu = cos theta * Lambda``, which stays finite where ``Lambda`` itself diverges.

Numerics: the formulas are written in log space or in rearranged forms so that alpha down to
1e-4 (Blinn exponents up to 2e8) gives no overflow and finite gradients in float32 and float64.
Squared sines are computed from the x and y components (``x^2 + y^2``) instead of ``1 - z^2``,
which would lose everything below float32's epsilon.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.scipy.special import erfc

from gonio.brdf._trig import cos_sin_turns
from gonio.brdf.frames import dot, normalize, safe_sqrt
from gonio.errors import ParameterError

Array = jnp.ndarray

DISTRIBUTIONS = ("blinn", "beckmann", "ggx")
SHADOWINGS = ("vcavity", "smith")
#: Distributions with exact visible-normal sampling.
VISIBLE_SAMPLING = ("ggx",)

_TINY = 1e-30  # smallest squared cosine used in log/divisions (representable in float32)
_SQRT_PI = 1.7724538509055159
_COS_FLOOR = 1e-9


def check_distribution(dist: str) -> str:
    """Return ``dist`` if it names a distribution, else raise ParameterError."""
    if dist not in DISTRIBUTIONS:
        raise ParameterError(
            f"unknown microfacet distribution {dist!r}; use one of {DISTRIBUTIONS}"
        )
    return dist


def check_shadowing(shadowing: str) -> str:
    """Return ``shadowing`` if it names a shadowing term, else raise ParameterError."""
    if shadowing not in SHADOWINGS:
        raise ParameterError(f"unknown shadowing term {shadowing!r}; use one of {SHADOWINGS}")
    return shadowing


def _sin2_cos2(w: Array) -> tuple[Array, Array]:
    return w[..., 0] ** 2 + w[..., 1] ** 2, w[..., 2] ** 2


def _log_cos2(s2: Array, c2: Array) -> Array:
    """``log(cos^2 theta)``, accurate near the pole (via log1p of -sin^2) and finite at 90 deg."""
    near = s2 < 0.5
    return jnp.where(
        near,
        jnp.log1p(-jnp.where(near, s2, 0.0)),
        jnp.log(jnp.where(near, 1.0, jnp.maximum(c2, _TINY))),
    )


# -- normal distributions -----------------------------------------------------------------------
def ndf(h: Array, alpha: Array, dist: str) -> Array:
    """Microfacet normal density ``D(h)`` in sr^-1, shape ``(...)``; 0 where ``h_z <= 0``.

    Parameters
    ----------
    h : (..., 3) unit microfacet normal in the local frame.
    alpha : scalar roughness > 0 (each distribution is normalized for any; fits search (0, 1]).
    dist : ``"blinn"``, ``"beckmann"`` or ``"ggx"``.
    """
    alpha = jnp.asarray(alpha).astype(h.dtype)
    s2, c2 = _sin2_cos2(h)
    up = h[..., 2] > 0
    a2 = alpha * alpha
    if dist == "ggx":
        den = s2 + a2 * c2
        d = a2 / (jnp.pi * den * den)
    elif dist == "beckmann":
        c2s = jnp.maximum(c2, _TINY)
        t = jnp.minimum(s2 / c2s, 1e20)  # tan^2; beyond 1e20 D underflows to 0 anyway
        log_d = -t / a2 - jnp.log(jnp.pi * a2) - 2.0 * jnp.log(c2s)
        d = jnp.exp(log_d)
    elif dist == "blinn":
        log_d = (1.0 / a2 - 1.0) * _log_cos2(s2, c2) - jnp.log(jnp.pi * a2)
        d = jnp.exp(log_d)
    else:
        check_distribution(dist)
    return jnp.where(up, d, 0.0)


def blinn_exponent(alpha: Array) -> Array:
    """Blinn-Phong exponent ``e = 2 / alpha^2 - 2`` of roughness ``alpha``."""
    return 2.0 / (alpha * alpha) - 2.0


# -- Smith shadowing -----------------------------------------------------------------------------
def smith_mu(w: Array, alpha: Array, dist: str) -> Array:
    """``mu = cos(theta) * Lambda(w)`` for ``w`` (..., 3) above the horizon, shape ``(...)``.

    ``Lambda`` diverges at grazing angles; ``mu`` tends to ``alpha sin(theta) / (2 sqrt(pi))``
    (Beckmann) or ``alpha sin(theta) / 2`` (GGX) there and is 0 at normal incidence.
    """
    alpha = jnp.asarray(alpha).astype(w.dtype)
    s2, c2 = _sin2_cos2(w)
    c = jnp.maximum(w[..., 2], 0.0)
    if dist == "ggx":
        # (sqrt(c^2 + alpha^2 s^2) - c) / 2 without cancellation for small alpha.
        r = jnp.sqrt(c2 + alpha * alpha * s2)
        return alpha * alpha * s2 / (2.0 * (r + c))
    if dist in ("beckmann", "blinn"):
        s = safe_sqrt(s2)
        as_ = alpha * s
        # a = 1 / (alpha tan theta), capped at 40 (Lambda < 1e-690 beyond) without ever
        # dividing by a tiny number (keeps forward values and gradients finite; the 1e-12
        # floor only matters for c = 0, where a = 0 anyway).
        a = c / jnp.maximum(jnp.maximum(as_, c / 40.0), 1e-12)
        mu = as_ * jnp.exp(-a * a) / (2.0 * _SQRT_PI) - 0.5 * c * erfc(a)
        return jnp.maximum(mu, 0.0)
    check_distribution(dist)
    raise AssertionError  # unreachable


def smith_lambda(w: Array, alpha: Array, dist: str) -> Array:
    """Smith's ``Lambda(w)`` (inf at grazing incidence), for tests and analysis."""
    return smith_mu(w, alpha, dist) / w[..., 2]


def smith_g1(w: Array, alpha: Array, dist: str) -> Array:
    """Smith masking ``G1(w) = 1 / (1 + Lambda(w))`` (for ``w`` above the horizon; else 0)."""
    c = jnp.maximum(w[..., 2], 0.0)
    ok = c > 0
    den = c + smith_mu(w, alpha, dist)
    return jnp.where(ok, c / jnp.where(ok, den, 1.0), 0.0)


# -- G / (4 cos_i cos_o) -------------------------------------------------------------------------
def visibility(wi: Array, wo: Array, h: Array, alpha: Array, dist: str, shadowing: str) -> Array:
    """``G(wi, wo, h) / (4 cos_i cos_o)`` for directions above the horizon, shape ``(...)``.

    ``h`` is the half vector of ``wi`` and ``wo``.
    """
    ci = wi[..., 2]
    co = wo[..., 2]
    if shadowing == "vcavity":
        nh = h[..., 2]
        oh = jnp.maximum(dot(wo, h), _TINY)
        # min(1, 2 nh co / oh, 2 nh ci / oh) / (4 ci co)
        #   = min(1 / (4 ci co), nh / (2 oh max(ci, co))): finite as either cosine -> 0.
        cmax = jnp.maximum(ci, co)
        return jnp.minimum(
            1.0 / jnp.maximum(4.0 * ci * co, _TINY), nh / (2.0 * oh * jnp.maximum(cmax, _TINY))
        )
    if shadowing == "smith":
        mi = smith_mu(wi, alpha, dist)
        mo = smith_mu(wo, alpha, dist)
        # Cosines below 1e-9 (within 1e-9 rad of the horizon) are floored there, so that
        # 1 / den and its square (in the gradient) stay finite in float32 at alpha = 1e-4.
        ci = jnp.maximum(ci, _COS_FLOOR)
        co = jnp.maximum(co, _COS_FLOOR)
        return 1.0 / (4.0 * (ci * co + co * mi + ci * mo))
    check_shadowing(shadowing)
    raise AssertionError  # unreachable


def shadowing_g(wi: Array, wo: Array, alpha: Array, dist: str, shadowing: str) -> Array:
    """The shadowing-masking term ``G(wi, wo)`` itself (in [0, 1]), for tests and plots."""
    h = normalize(wi + wo)
    return visibility(wi, wo, h, alpha, dist, shadowing) * 4.0 * wi[..., 2] * wo[..., 2]


# -- sampling the distribution of normals ------------------------------------------------------
def _from_sin2_cos2(s2: Array, c2: Array, phi_turns: Array) -> Array:
    s = safe_sqrt(s2)
    cp, sp = cos_sin_turns(phi_turns)
    return jnp.stack([s * cp, s * sp, safe_sqrt(c2)], -1)


def sample_ndf(u: Array, alpha: Array, dist: str) -> Array:
    """Microfacet normal with density ``D(h) cos(theta_h)`` (see :func:`ndf_pdf`), ``(..., 3)``.

    ``u`` (..., 2) in [0, 1): ``u[..., 0]`` sets theta_h by inverting its marginal CDF,
    ``u[..., 1]`` sets phi_h.
    """
    alpha = jnp.asarray(alpha).astype(u.dtype)
    a2 = alpha * alpha
    u0 = jnp.minimum(u[..., 0], 1.0 - 1e-7)
    phi = u[..., 1]  # in turns
    if dist == "beckmann":
        t = -a2 * jnp.log1p(-u0)  # tan^2 theta_h
        s2, c2 = t / (1.0 + t), 1.0 / (1.0 + t)
    elif dist == "ggx":
        den = (1.0 - u0) + a2 * u0
        s2, c2 = a2 * u0 / den, (1.0 - u0) / den
    elif dist == "blinn":
        x = a2 * jnp.log1p(-u0)  # log cos^2 theta_h = 2 log(1 - u0) / (e + 2)
        s2, c2 = -jnp.expm1(x), jnp.exp(x)
    else:
        check_distribution(dist)
    return _from_sin2_cos2(s2, c2, phi)


def ndf_pdf(h: Array, alpha: Array, dist: str) -> Array:
    """Density of :func:`sample_ndf` per unit solid angle of ``h``: ``D(h) cos(theta_h)``."""
    return ndf(h, alpha, dist) * jnp.maximum(h[..., 2], 0.0)


def sample_visible_ggx(wo: Array, u: Array, alpha: Array) -> Array:
    """GGX visible normal (Heitz 2018, "Sampling the GGX distribution of visible normals").

    Density per solid angle of ``h``: ``G1(wo) max(0, wo.h) D(h) / cos(theta_o)``
    (see :func:`visible_pdf`). ``wo`` must be above the horizon.
    """
    alpha = jnp.asarray(alpha).astype(wo.dtype)
    # Written per component, and the unnormalized normal stored (optimization_barrier) before
    # it is normalized and reflected about: XLA:CPU otherwise splits the (..., 3)-shaped version
    # into 12 loops and recomputes the cheap part of the sampler in several of them; this way
    # reflect(wo, h) compiles to 3 loops. Same values up to rounding. Writing it per component
    # without the barrier is not enough: the recomputation remains.
    # Stretch to the configuration where the roughness is 1 (hemisphere of visible normals).
    vx, vy, vz = _normalized(alpha * wo[..., 0], alpha * wo[..., 1], wo[..., 2])
    lensq = vx * vx + vy * vy
    has = lensq > 0
    inv = jnp.where(has, 1.0 / jnp.sqrt(jnp.where(has, lensq, 1.0)), 0.0)
    t1x = jnp.where(has, -vy * inv, 1.0)
    t1y = jnp.where(has, vx * inv, 0.0)
    t2x, t2y, t2z = -vz * t1y, vz * t1x, vx * t1y - vy * t1x  # v x t1 (t1 has no z component)
    r = jnp.sqrt(u[..., 0])
    cp, sp = cos_sin_turns(u[..., 1])
    p1 = r * cp
    p2 = r * sp
    s = 0.5 * (1.0 + vz)
    p2 = (1.0 - s) * safe_sqrt(1.0 - p1 * p1) + s * p2
    pz = safe_sqrt(1.0 - p1 * p1 - p2 * p2)
    nx = p1 * t1x + p2 * t2x + pz * vx
    ny = p1 * t1y + p2 * t2y + pz * vy
    nz = p2 * t2z + pz * vz
    # Unstretch.
    h = jnp.stack([alpha * nx, alpha * ny, jnp.maximum(nz, 0.0)], -1)
    return normalize(jax.lax.optimization_barrier(h))


def _normalized(x: Array, y: Array, z: Array) -> tuple[Array, Array, Array]:
    """The components of :func:`~gonio.brdf.frames.normalize` of ``(x, y, z)``."""
    n2 = x * x + y * y + z * z
    ok = n2 > 0
    inv = jnp.where(ok, 1.0 / jnp.sqrt(jnp.where(ok, n2, 1.0)), 0.0)
    return jnp.where(ok, x * inv, 0.0), jnp.where(ok, y * inv, 0.0), jnp.where(ok, z * inv, 1.0)


def visible_pdf(wo: Array, h: Array, alpha: Array, dist: str) -> Array:
    """Density of visible normals ``G1(wo) max(0, wo.h) D(h) / cos(theta_o)`` over ``h``.

    Written as ``max(0, wo.h) D(h) / (cos_o + mu(wo))``, finite for grazing ``wo``.
    """
    co = jnp.maximum(wo[..., 2], 0.0)
    den = co + smith_mu(wo, alpha, dist)
    oh = jnp.maximum(dot(wo, h), 0.0)
    return jnp.where(den > 0, oh * ndf(h, alpha, dist) / jnp.where(den > 0, den, 1.0), 0.0)


def sample_visible(wo: Array, u: Array, alpha: Array, dist: str) -> Array:
    """Visible-normal sample for ``dist`` in :data:`VISIBLE_SAMPLING`."""
    if dist == "ggx":
        return sample_visible_ggx(wo, u, alpha)
    raise ParameterError(f"no visible-normal sampling for {dist!r}; use one of {VISIBLE_SAMPLING}")
