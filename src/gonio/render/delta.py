"""Delta lights (directional, point) evaluated exactly: ``f E cos`` once per pixel, no samples.

Every material is a registered pytree whose ``f`` is JAX code
(:class:`gonio.brdf.material.Material`): it runs in one jitted kernel per tile, and the tiles'
results stay on the device until one transfer at the end.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from gonio.render.scene import SphereHits
from gonio.render.tiling import device_array, pad_rows, pixel_tile, stack_by_kind, tile_spans


@jax.jit
def delta_kernel_model(model, groups, position, frame, wo):
    """Sum over delta lights of f E cos; ``groups`` from :func:`stack_by_kind`."""
    total = 0.0
    for stacked, count in groups:

        def term(i, stacked=stacked):
            light = jax.tree_util.tree_map(lambda leaf: leaf[i], stacked)
            ls = light.sample(position, jnp.zeros((*position.shape[:-1], 2), jnp.float32))
            wi = jnp.einsum("pij,pj->pi", frame, ls.wi)
            f = jnp.asarray(model.f(wi, wo), jnp.float32)
            return f * ls.value * jnp.maximum(wi[..., 2], 0.0)[..., None]

        # A traced trip count: renders with 1 .. capacity lights of a kind share this kernel,
        # and the padding costs nothing.
        total = total + jax.lax.fori_loop(1, count, lambda i, acc: acc + term(i), term(0))
    return total


def render_delta(
    material, lights, hits: SphereHits, tile_samples, stats, channels: int = 1
) -> np.ndarray:
    """Radiance ``(hits.count, C)`` from the delta ``lights``; counts kernel calls in ``stats``;
    ``channels``: the image's channel count C (grey lights are broadcast to it)."""
    n = hits.count
    size = pixel_tile(n, tile_samples)
    groups = stack_by_kind(lights, channels)
    out = []
    for a, b in tile_spans(n, size):
        pos = device_array(pad_rows(hits.position[a:b], size))
        frame = device_array(pad_rows(hits.frame[a:b], size))
        wo = device_array(pad_rows(hits.wo[a:b], size))
        r = delta_kernel_model(material, groups, pos, frame, wo)
        stats.calls += 1
        out.append(r)
    # one transfer for all tiles (every tile stays on the device until here)
    res = jax.device_get(out)
    spans = list(tile_spans(n, size))
    return np.concatenate(
        [np.asarray(x, np.float64)[: b - a] for x, (a, b) in zip(res, spans, strict=True)], 0
    )
