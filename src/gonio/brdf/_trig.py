"""Cosine and sine of an angle given in turns, fast on XLA's CPU backend.

XLA:CPU evaluates float32 ``sin`` and ``cos`` more than an order of magnitude slower than
``exp`` or ``sqrt`` (they are not vectorized), so a sampling routine that calls them spends most
of its time there (``benchmarks/bench_throughput.py`` measures the samplers). The angles
sampling needs are fractions of a turn (``phi = 2 pi u``), so the range reduction is exact: ``t``
minus the nearest quarter turn is computed without rounding, and what remains is a polynomial on
``[-pi/4, pi/4]``.

For float32 the result is within 2 ulp of the exact value (1.7 ulp, 8.5e-8 measured over 2e6
random turns; XLA's own ``cos(2 pi t)`` is off by up to 4e-7, from rounding ``2 pi t`` alone):
Taylor polynomials to ``x^11`` and ``x^10`` truncate below 2e-9 relative, the rest is the
float32 rounding of the Horner steps. Other dtypes (float64) use ``jnp.cos``/``jnp.sin`` of
``2 pi t``.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

Array = jnp.ndarray

_TWO_PI = 2.0 * math.pi
# sin(2 pi r) = r (S0 + S1 r^2 + ...), cos(2 pi r) = 1 + C1 r^2 + ...: Taylor coefficients of
# the series in r (2 pi folded in, so that r is used as computed, exactly).
_S = tuple((-1) ** k * _TWO_PI ** (2 * k + 1) / math.factorial(2 * k + 1) for k in range(6))
_C = tuple((-1) ** k * _TWO_PI ** (2 * k) / math.factorial(2 * k) for k in range(1, 6))


def _horner(x2: Array, coeffs: tuple[float, ...]) -> Array:
    acc = jnp.full_like(x2, coeffs[-1])
    for c in coeffs[-2::-1]:
        acc = acc * x2 + c
    return acc


def cos_sin_turns(t: Array) -> tuple[Array, Array]:
    """``(cos(2 pi t), sin(2 pi t))`` for ``t`` in turns (any shape; exact range reduction for
    ``|t| < 2^21`` in float32)."""
    t = jnp.asarray(t)
    if t.dtype != jnp.float32:
        phi = _TWO_PI * t
        return jnp.cos(phi), jnp.sin(phi)
    q = jnp.round(4.0 * t)  # nearest quarter turn; 4 t and q / 4 are exact
    r = t - 0.25 * q  # in [-1/8, 1/8], exact (Sterbenz)
    r2 = r * r
    s = r * _horner(r2, _S)
    c = 1.0 + r2 * _horner(r2, _C)
    k = q.astype(jnp.int32) & 3
    cos = jnp.where(k == 0, c, jnp.where(k == 1, -s, jnp.where(k == 2, -c, s)))
    sin = jnp.where(k == 0, s, jnp.where(k == 1, c, jnp.where(k == 2, -s, -c)))
    return cos, sin
