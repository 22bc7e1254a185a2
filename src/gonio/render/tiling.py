"""Tiles of pixels for the render kernels, host arrays on the device, and lights stacked by kind.

Kernel shapes do not follow the request: pixels are cut into tiles of a few sizes (at most 17
per kernel) and lights of one kind are stacked to a padded capacity with a traced count, so that
a new light count reuses the compiled kernels and a new image size mostly does; a new tile size
compiles once per machine (the persistent cache, :mod:`gonio.compile_cache`). See
:mod:`gonio.render.integrator`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.render.lights import Environment, Light

Array = jnp.ndarray

#: Smallest pixel tile; tiles of delta lights are this times a power of 4 (up to the cap), so
#: that all image sizes share a handful of compiled kernels instead of one each.
MIN_PIXEL_TILE = 256

#: Tile sizes of sampled lights per cap: a tile is a multiple of ``cap / TILE_SIZES`` pixels.
TILE_SIZES = 16


def pixel_tile(n: int, cap: int) -> int:
    """Pixels per kernel call of the delta-light kernel for ``n`` pixels: ``MIN_PIXEL_TILE``
    times a power of 4, or ``cap`` (one evaluation per pixel: padding costs little)."""
    size = MIN_PIXEL_TILE
    while size < n and size < cap:
        size *= 4
    return max(1, min(size, cap))


def sample_tile(n: int, cap: int) -> int:
    """Pixels per kernel call of the sampled-light kernels for ``n`` pixels: the fewest tiles of
    at most ``cap`` pixels, of equal size rounded up to a multiple of ``cap / TILE_SIZES`` (at
    least ``MIN_PIXEL_TILE``).

    All image sizes share at most ``TILE_SIZES`` compiled kernels per ``cap`` (and one for
    images of ``MIN_PIXEL_TILE`` pixels or fewer), and the padding, whose samples cost what a
    real pixel's do, stays under one step per tile. For example, the 12 868 pixels of a 128²
    sphere fit in 2 x 6656 (3 % padding), where :func:`pixel_tile`'s powers of 4 would take
    2 x 8192 (21 %). Tiles split pixels only, so their size changes the work, not the image.
    """
    cap = max(1, cap)
    if n <= MIN_PIXEL_TILE or cap <= MIN_PIXEL_TILE:
        return min(MIN_PIXEL_TILE, cap)
    step = max(MIN_PIXEL_TILE, cap // TILE_SIZES)
    tiles = -(-n // cap)  # integer ceilings
    per_tile = -(-n // tiles)
    return min(cap, -(-per_tile // step) * step)


def device_array(a: np.ndarray) -> Array:
    """A host array on the default device: ``jax.device_put`` copies without compiling anything,
    where ``jnp.asarray`` compiles a small copy kernel per new shape (paid by every fresh
    process on its first image)."""
    a = np.asarray(a)
    if a.dtype == np.float64:
        a = a.astype(np.float32)
    return jax.device_put(a)


def tile_spans(n: int, size: int):
    for start in range(0, n, size):
        yield start, min(n, start + size)


def pad_rows(a: np.ndarray, n: int) -> np.ndarray:
    if a.shape[0] == n:
        return a
    pad = np.repeat(a[-1:], n - a.shape[0], axis=0)
    return np.concatenate([a, pad], 0)


def sampled_groups(lights: Sequence[Light], channels: int = 1) -> tuple:
    """Area and environment lights as the kernels take them: ``((light, count), ...)``, one
    light sample per group. An environment is its own group (``count`` None; environments of
    one image size are merged beforehand, :func:`gonio.render.lights.merge_environments`);
    other lights are stacked by kind as :func:`stack_by_kind` does, so that their number is a
    traced value, not part of the kernel's shape."""
    envs = tuple((lt, None) for lt in lights if isinstance(lt, Environment))
    others = [lt for lt in lights if not isinstance(lt, Environment)]
    return envs + stack_by_kind(others, channels)


def stack_by_kind(lights: Sequence[Light], channels: int = 1) -> tuple:
    """Lights grouped by kind (pytree structure and leaf shapes), each group's leaves stacked
    along a new first axis padded to a power of 2 (at least 8): ``((stacked, count), ...)``.
    The capacity, not the count, is part of the kernel's shape. Grey lights are first
    broadcast to ``channels`` (the image's), so that a mix of grey and coloured lights of one
    kind is one group, as a scene of either alone."""
    groups: dict[Any, list] = {}
    for light in lights:
        leaves, treedef = jax.tree_util.tree_flatten(light.broadcast_channels(channels))
        leaves = [np.asarray(x, np.float32) for x in leaves]
        groups.setdefault((treedef, tuple(x.shape for x in leaves)), []).append(leaves)
    out = []
    for (treedef, _), members in groups.items():
        cap = max(8, 1 << (len(members) - 1).bit_length())
        padded = members + [members[-1]] * (cap - len(members))
        stacked = [device_array(np.stack(col)) for col in zip(*padded, strict=True)]
        out.append((treedef.unflatten(stacked), device_array(np.int32(len(members)))))
    return tuple(out)
