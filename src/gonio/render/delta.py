"""Delta lights (directional, point) evaluated exactly: ``f E cos`` once per pixel, no samples.

Analytic models and tables (registered pytrees whose ``f`` is JAX code) run in one jitted kernel
per tile, and the tiles' results stay on the device until one transfer at the end; only a
material that is not a pytree is evaluated light by light outside ``jit``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf.models import BRDFModel
from gonio.render.scene import SphereHits
from gonio.render.tiling import device_array, pad_rows, pixel_tile, stack_by_kind, tile_spans


def traceable(material) -> bool:
    """``material`` can be a ``jax.jit`` argument: a model or a table registered as a pytree
    (an unregistered object is its own single leaf)."""
    if isinstance(material, BRDFModel):
        return True
    leaves = jax.tree_util.tree_leaves(material)
    return not (len(leaves) == 1 and leaves[0] is material)


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
    traced = traceable(material)
    groups = stack_by_kind(lights, channels) if traced else ()
    out = []
    for a, b in tile_spans(n, size):
        pos = device_array(pad_rows(hits.position[a:b], size))
        frame = device_array(pad_rows(hits.frame[a:b], size))
        wo = device_array(pad_rows(hits.wo[a:b], size))
        if traced:
            r = delta_kernel_model(material, groups, pos, frame, wo)
        else:
            r = 0.0
            for light in lights:
                ls = light.sample(pos, jnp.zeros((size, 2), jnp.float32))
                wi = np.asarray(jnp.einsum("pij,pj->pi", frame, ls.wi))
                f = np.asarray(material.f(wi, np.asarray(wo)), np.float32)
                r = r + f * np.asarray(ls.value) * np.maximum(wi[..., 2], 0.0)[..., None]
        stats.calls += 1
        out.append(r)
    # one transfer for all tiles (traced materials: every tile stays on the device until here)
    res = jax.device_get(out)
    spans = list(tile_spans(n, size))
    return np.concatenate(
        [np.asarray(x, np.float64)[: b - a] for x, (a, b) in zip(res, spans, strict=True)], 0
    )
