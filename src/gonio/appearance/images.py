"""The appearance score's images of any material: point-light spheres and the studio sphere.

For each light angle ``a`` of :data:`~gonio.appearance.scene.LIGHT_ANGLES_DEG` the image is
exact (no sampling): a directional light of unit irradiance from ``(sin a, 0, cos a)``, so each
pixel is ``f(wi, wo) cos theta_i`` in sr^-1 (radiance per unit irradiance), 0 where the light is
below the local horizon or off the sphere. Under the studio environment
(:mod:`gonio.appearance.environment`) each pixel is the fixed estimate of ``integral L f cos
dwi`` (radiance, in the environment's units).

Any :class:`~gonio.brdf.material.Material` works: a table or an analytic model alike, since only
``f`` is called. Materials that are JAX pytrees are evaluated by one jitted kernel per material
structure (a fitted model family compiles once, whatever its parameters); others are called
as they are. Pixels are processed in chunks of fixed size (the last one padded) so that every
material of the same structure reuses the same compiled program.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from gonio.appearance import environment as env
from gonio.appearance.scene import (
    DEFAULT_RESOLUTION,
    LIGHT_ANGLES_DEG,
    SpherePixels,
    light_direction,
    sphere_pixels,
)
from gonio.errors import ParameterError

#: Pixels per kernel call.
_CHUNK = 1024

_JIT: dict[str, Any] = {}


@dataclass(frozen=True)
class SphereImages:
    """A material's appearance images.

    Attributes
    ----------
    images : ``{name: (H, W, C) float32}``; names ``"0"``, ``"30"``, ``"60"`` (the light's
        angle from the view in degrees) and ``"env"`` (the studio). Linear values, 0 off the
        sphere.
    pixels : the sphere's pixel geometry.
    env_samples : samples per pixel of the studio image (its estimator's seed is ``seed``).
    seed : seed of the studio image's uniforms.
    """

    images: dict[str, np.ndarray]
    pixels: SpherePixels
    env_samples: int
    seed: int

    @property
    def resolution(self) -> int:
        """Image side in pixels."""
        return self.pixels.resolution


def _point(material: Any, wi: Any, wo: Any) -> Any:
    import jax.numpy as jnp

    f = material.f(wi, wo)
    return f * jnp.maximum(wi[..., 2:3], 0.0)


def _studio(material: Any, wo: Any, frame: Any, u: Any) -> Any:
    import jax.numpy as jnp

    wi = env.directions(wo, u, jnp)  # (P, S, 3) local
    wo_b = jnp.broadcast_to(wo[:, None, :], wi.shape)
    up = wi[..., 2] > 0
    wi_safe = jnp.where(up[..., None], wi, jnp.array([0.0, 0.0, 1.0], wi.dtype))
    f = material.f(wi_safe, wo_b)
    pdf = env.mixture_pdf(wi_safe, wo_b, jnp)
    world = jnp.einsum("pji,psj->psi", frame, wi_safe)  # to_world with rows (t, b, n)
    radiance = env.studio_radiance(world, jnp).astype(wi.dtype)
    w = jnp.where(up, wi_safe[..., 2] / jnp.maximum(pdf, 1e-30), 0.0)
    if f.shape[-1] == 1:
        # a grey material under the coloured studio: its luminance-weighted radiance
        radiance = (radiance * jnp.array([0.2126, 0.7152, 0.0722], wi.dtype)).sum(-1, keepdims=True)
    return (f * radiance * w[..., None]).mean(1)


def _is_pytree(material: Any) -> bool:
    import jax

    leaves = jax.tree_util.tree_leaves(material)
    return bool(leaves) and all(hasattr(x, "dtype") for x in leaves) and leaves[0] is not material


def _kernel(name: str, material: Any):
    fn = {"point": _point, "studio": _studio}[name]
    if not _is_pytree(material):
        return fn
    if name not in _JIT:
        import jax

        _JIT[name] = jax.jit(fn)
    return _JIT[name]


def _chunks(n: int):
    for s in range(0, n, _CHUNK):
        yield s, min(n, s + _CHUNK)


def _pad(a: np.ndarray, m: int) -> np.ndarray:
    if a.shape[0] == _CHUNK:
        return a
    pad = np.repeat(a[-1:], _CHUNK - m, axis=0)
    return np.concatenate([a, pad])


def render_images(
    material: Any,
    resolution: int = DEFAULT_RESOLUTION,
    env_samples: int = env.DEFAULT_SAMPLES,
    seed: int = 0,
) -> SphereImages:
    """The point-light and studio images of ``material`` (anything with ``f(wi, wo)``).

    Parameters
    ----------
    material : a Material (1 or 3 channels).
    resolution : image side in pixels.
    env_samples : samples per pixel of the studio image, a positive multiple of
        :data:`~gonio.appearance.environment.N_PROPOSALS`.
    seed : seed of the studio image's uniforms (use the same seed for images to be compared).

    Raises
    ------
    ParameterError : bad resolution or sample count, a material with other than 1 or 3
        channels, or values that are not finite.
    """
    if env_samples < env.N_PROPOSALS or env_samples % env.N_PROPOSALS:
        raise ParameterError(
            f"env_samples must be a positive multiple of {env.N_PROPOSALS}, got {env_samples}"
        )
    channels = int(getattr(material, "n_channels", 0) or 0)
    if channels not in (0, 1, 3):
        raise ParameterError(
            f"the appearance score renders 1- or 3-channel materials, not {channels} channels"
        )
    px = sphere_pixels(resolution)
    p = px.index.size
    lights = np.stack([light_direction(a) for a in LIGHT_ANGLES_DEG])  # (L, 3) world
    wi_local = np.einsum("pij,lj->lpi", px.frame, lights).astype(np.float32)  # (L, P, 3)
    wo = px.wo.astype(np.float32)
    frame = px.frame.astype(np.float32)
    u = env.uniforms(p, env_samples, seed)
    point_k, studio_k = _kernel("point", material), _kernel("studio", material)
    point_out, studio_out = [], []
    for s, e in _chunks(p):
        m = e - s
        wi_c = np.stack([_pad(w[s:e], m) for w in wi_local])
        wo_c = _pad(wo[s:e], m)
        wo_l = np.broadcast_to(wo_c, wi_c.shape)
        point_out.append(np.asarray(point_k(material, wi_c, wo_l))[:, :m])
        studio_out.append(
            np.asarray(studio_k(material, wo_c, _pad(frame[s:e], m), _pad(u[s:e], m)))[:m]
        )
    point = np.concatenate(point_out, axis=1).astype(np.float32)
    studio = np.concatenate(studio_out, axis=0).astype(np.float32)
    if not (np.all(np.isfinite(point)) and np.all(np.isfinite(studio))):
        raise ParameterError("the material's values on the sphere are not finite")
    images = {f"{a:g}": px.scatter(point[i]) for i, a in enumerate(LIGHT_ANGLES_DEG)}
    images["env"] = px.scatter(studio)
    return SphereImages(images, px, int(env_samples), int(seed))
