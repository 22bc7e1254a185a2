"""Workarounds for XLA's CPU fusion heuristics on hot lookup and sampling paths.

Used only on the two paths where XLA's fusion otherwise recomputes shared values as scalar code
inside gather loops: the table lookup's index arithmetic and the CDF binary search of
:func:`gonio.brdf.sampling.distributions.find_interval`. Their throughput is measured by
``benchmarks/bench_throughput.py``; any other use needs such a measurement to justify it.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp

Array = jnp.ndarray


def materialize(arrays: Sequence[Array], like: Array) -> list[Array]:
    """The same values, computed once: each array is divided by a runtime 1.0.

    XLA's CPU backend fuses cheap elementwise producers into every consumer. Fed to several
    gathers (or to every channel of an output), index arithmetic is then recomputed inside each
    gather loop, which XLA emits as scalar code. A division counts as expensive, so its result
    is computed once, in a vectorized loop, and stored. ``like * 0 + 1`` is 1.0 (NaN where
    ``like`` is NaN, where the result is meaningless anyway) and XLA cannot fold it away;
    dividing by 1.0 is exact, so the values are unchanged bit for bit. Integer arrays go
    through float64 or float32 (exact for indices below 2**24 in float32).

    Parameters
    ----------
    arrays : arrays of the batch shape, optionally with trailing axes (e.g. ``(..., 3)``).
    like : a float array of the batch shape.
    """
    one = like * 0.0 + 1.0
    out = []
    for x in arrays:
        o = one.reshape(one.shape + (1,) * (x.ndim - one.ndim))  # trailing axes of x broadcast
        if jnp.issubdtype(x.dtype, jnp.integer):
            f = jnp.float64 if like.dtype == jnp.float64 else jnp.float32
            out.append((x.astype(f) / o.astype(f)).astype(x.dtype))
        else:
            out.append(x / o.astype(x.dtype))
    return out
