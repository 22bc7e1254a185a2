"""Sample points for the renderer: a rank-1 lattice sequence, rotated per pixel, built on the
radical inverse that Sobol' points start with.

The renderer needs a few hundred points in a handful of dimensions; building them is cheap, but
``scipy.stats.qmc`` costs the import of all of ``scipy.stats``, more than the rest of a
render's start (``benchmarks/bench_first_image.py`` times that start). So Sobol' points are
generated here from the Joe-Kuo direction numbers that SciPy ships
(``scipy/stats/_sobol_direction_numbers.npz``, read with NumPy, located without importing
``scipy.stats``); where that file is not found, ``scipy.stats.qmc.Sobol`` gives the same
integers. Points come in SciPy's order (Gray code, Antonov-Saleev): the first ``2^m`` points are
a (t, m, s)-net, and the first two dimensions a (0, m, 2)-net. :func:`to_unit` randomizes them
by a *digital shift* (XOR with uniform random 32-bit words per pixel), which keeps the net's
stratification in every elementary interval.

The renderer's pairs of numbers (:func:`padded_unit`) are a rank-1 lattice sequence instead
(Hickernell, Hong, L'Ecuyer and Lemieux 2000, "Extensible lattice sequences for quasi-Monte
Carlo quadrature"): point ``i`` is ``(phi(i), frac(phi(i) g))`` with ``phi`` the base-2 radical
inverse (the Sobol' sequence's first dimension) and ``g`` = :data:`LATTICE_GENERATOR`, so that
the first ``2^m`` points are the Korobov lattice ``{(j / 2^m, frac(j g / 2^m))}`` for every
``m`` and each aligned block of ``2^m`` is a shifted copy of it. Its randomization is the
lattice's own, a Cranley-Patterson rotation (the shift added modulo 1; integer addition wraps
modulo 2^32): each rotated point is uniform on [0, 1)^2, so every pixel is an unbiased estimate,
independent of the others, and the rotated set is still the lattice. The samplers map a pair
through a warp (concentric disk, visible normals, the environment's quadtree) onto an
environment whose bright regions have sharp edges; there the lattice gives less error than the
Sobol' net, for BRDF samples, environment samples and their MIS combination alike, and most
for glossy materials. The gap first showed against Mitsuba 3's ``multijitter`` sampler (a
correlated multi-jittered pattern, close to a rotated lattice), whose error the digitally
shifted net did not reach; ``benchmarks/bench_equal_time.py`` compares the two renderers'
error at equal time.
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

import jax.numpy as jnp
import numpy as np

BITS = 32

#: Generator ``g`` of the rank-1 lattice sequence of :func:`padded_unit`. Chosen by a search
#: over the odd numbers below 2^14 for the largest minimum, over ``N = 2^4 ... 2^11`` points, of
#: the lattice's Zaremba index over ``N`` (``min max(1, |h1|) max(1, |h2|)`` over the nonzero
#: dual vectors, ``h1 + g h2 = 0 mod N``; larger is a more even lattice): 0.113, where for
#: instance ``g = 7`` is as good at 16 points but falls to 0.003 at 2048.
#: ``tests/render/test_sobol.py`` checks it.
LATTICE_GENERATOR = 15577


@functools.cache
def _direction_file() -> Path | None:
    spec = importlib.util.find_spec("scipy")
    if spec is None or spec.origin is None:
        return None
    path = Path(spec.origin).parent / "stats" / "_sobol_direction_numbers.npz"
    return path if path.is_file() else None


@functools.lru_cache(maxsize=16)
def direction_numbers(dims: int, path: Path) -> np.ndarray:
    """Direction numbers ``v`` (dims, 32) uint32 from SciPy's table at ``path``: bit ``j`` of
    a point's index (Gray code) XORs ``v[:, j]`` into the point."""
    with np.load(path) as data:
        poly, vinit = data["poly"][:dims], data["vinit"][:dims]
    v = np.zeros((dims, BITS), dtype=np.uint64)
    v[0] = 1 << np.arange(BITS - 1, -1, -1, dtype=np.uint64)  # first dimension: van der Corput
    for d in range(1, dims):
        s = int(poly[d]).bit_length() - 1  # degree of the primitive polynomial
        m = [int(x) for x in vinit[d, :s]]
        for j in range(s, BITS):
            new = m[j - s] ^ (m[j - s] << s)
            for k in range(1, s):
                if (int(poly[d]) >> (s - k)) & 1:
                    new ^= m[j - k] << k
            m.append(new)
        v[d] = [m[j] << (BITS - 1 - j) for j in range(BITS)]
    return v.astype(np.uint32)


def sobol_ints(n: int, dims: int) -> np.ndarray:
    """The first ``n`` Sobol' points in ``dims`` dimensions as uint32 ``(n, dims)`` (the point
    is the integer times 2^-32), in SciPy's Gray-code order, unscrambled."""
    path = _direction_file()
    if path is None:
        from scipy.stats import qmc

        pts = qmc.Sobol(d=dims, scramble=False, bits=BITS).random(n)
        return (pts * 2.0**BITS).astype(np.uint64).astype(np.uint32)
    v = direction_numbers(dims, path)
    i = np.arange(n, dtype=np.uint64)
    gray = i ^ (i >> np.uint64(1))
    out = np.zeros((n, dims), np.uint32)
    for j in range(int(n - 1).bit_length() if n > 1 else 0):
        bit = ((gray >> np.uint64(j)) & np.uint64(1)).astype(bool)
        out[bit] ^= v[:, j]
    return out


def shifts(rng: np.random.Generator, n: int, dims: int) -> np.ndarray:
    """Uniform random digital shifts ``(n, dims)`` uint32, one row per pixel."""
    return rng.integers(0, 1 << BITS, size=(n, dims), dtype=np.uint32)


def to_unit(points: jnp.ndarray, shift: jnp.ndarray) -> jnp.ndarray:
    """Digitally shifted points in [0, 1) as float32: ``points`` (S, d) and ``shift`` (P, d)
    uint32 -> (P, S, d). The top 24 bits are kept, so every value is exact in float32 and
    below 1."""
    x = jnp.bitwise_xor(points[None, :, :], shift[:, None, :])
    return (x >> 8).astype(jnp.float32) * jnp.float32(2.0**-24)


def padded_unit(
    points: jnp.ndarray, shift: jnp.ndarray, *, samples_first: bool = False
) -> jnp.ndarray:
    """``d = shift.shape[1]`` uniforms per sample, as float32 (P, S, d): pairs of the rank-1
    lattice sequence (see the module's docstring), rotated per pixel. ``samples_first``: laid
    out (S, P, d) instead (the renderer's layout), the same numbers.

    ``points`` (S, k >= 1) uint32 hold in column 0 the radical inverses of the samples' indices
    (the first Sobol' dimension, :func:`sobol_ints`) in aligned blocks of a power of 2 up to 256
    points (each block then a shifted copy of one lattice); ``shift`` (P, d) uint32 one uniform
    random word per pixel and dimension, added modulo 2^32 (a rotation modulo 1).

    Dimensions 0-1 (the BRDF sample) take the lattice in the points' order; every further pair
    takes it in an order permuted per pixel and pair (sample ``i`` takes point ``i XOR r``,
    ``r`` from the shift's low 8 bits, which the conversion drops), with its own rotation:
    each pair is the whole lattice, while the pairing between pairs is random ("padding",
    Kollig and Keller 2002). This gives lower error than taking the second pair from the next
    dimensions of one sequence (see :mod:`gonio.render.integrator`).
    """
    s, d = points.shape[0], shift.shape[1]
    r = points[:, 0]  # radical inverse of the sample's index, 32 bits
    lattice = jnp.stack([r, r * jnp.uint32(LATTICE_GENERATOR)], -1)  # products wrap mod 2^32
    i = jnp.arange(s, dtype=jnp.uint32)
    mask = jnp.uint32(min(s, 256) - 1) if s & (s - 1) == 0 else jnp.uint32(0)

    def grid(per_sample: jnp.ndarray, per_pixel: jnp.ndarray):
        """Both with the axis of the other inserted, in the output's axis order."""
        if samples_first:
            return per_sample[:, None], per_pixel[None]
        return per_sample[None], per_pixel[:, None]

    shape = (s, shift.shape[0]) if samples_first else (shift.shape[0], s)
    cols = [jnp.broadcast_to(grid(lattice, shift)[0], (*shape, 2))]
    for k in range(1, (d + 1) // 2):
        i_k, r_k = grid(i, shift[:, 2 * k] & mask)
        cols.append(jnp.take(lattice, (i_k ^ r_k).astype(jnp.int32), axis=0))
    x = jnp.concatenate(cols, -1)[..., :d] + grid(i, shift)[1]  # wraps: a rotation modulo 1
    return (x >> 8).astype(jnp.float32) * jnp.float32(2.0**-24)


__all__ = [
    "BITS",
    "LATTICE_GENERATOR",
    "direction_numbers",
    "padded_unit",
    "shifts",
    "sobol_ints",
    "to_unit",
]
